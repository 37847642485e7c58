"""``autopilot bench``: the benchmarks. Each bench is a :class:`Command` in a module of
:mod:`autopilot.cli.benches` (its ``BENCHES``); a new module there is a new bench."""

from __future__ import annotations

import argparse
import importlib
import pkgutil

from autopilot.cli.common import Command


def benches() -> list[Command]:
    """Every bench, in name order."""
    from autopilot.cli import benches as package

    found = []
    for module in pkgutil.iter_modules(package.__path__):
        found += importlib.import_module(f"{package.__name__}.{module.name}").BENCHES
    return sorted(found, key=lambda bench: bench.name)


def arguments(bench: argparse.ArgumentParser) -> None:
    subparsers = bench.add_subparsers(dest="bench", required=True, metavar="BENCH",
                                      parser_class=type(bench))
    for each in benches():
        each.attach(subparsers).set_defaults(flight=True)


def run(args: argparse.Namespace) -> int:  # (each bench's parser sets its own handler)
    raise AssertionError("a bench's parser sets its handler")


COMMAND = Command("bench", "run a benchmark", arguments, run, flight=True,
                  description="Run a benchmark: speed and accuracy figures the project "
                  "publishes (docs/benchmarks.md is generated from their JSON). "
                  "'autopilot bench BENCH --help' says what each measures and how long it "
                  "takes.")
