"""What the commands share: exit codes, the ``Command`` record every command module exports,
common options, and the progress printers."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from autopilot.config import InputError
from autopilot.suggest import did_you_mean

EXIT_OK = 0
EXIT_FAILED = 1  # the mission failed (the summary says why; a failsafe's abort too)
EXIT_USAGE = 2  # invalid input: configuration, mission, URL, key file, argument
EXIT_NO_VEHICLE = 3  # no vehicle answered within the timeout
EXIT_LINK = 4  # the link cannot be opened: port in use, no such device, connection refused
#               (and for the goal API's clients: no API answers at that address)
EXIT_NO_VIDEO = 5  # the camera delivered no frame
EXIT_RENDERING = 6  # the simulator cannot render (MUJOCO_GL, OpenGL libraries)
EXIT_ABORTED = 130  # Ctrl-C or SIGTERM (after the safe stop), nothing else


@dataclass(frozen=True)
class Command:
    """One ``autopilot`` command (or one ``autopilot bench`` bench): its name, its one-line
    help, its arguments and what runs it. ``flight``: the process is set up for flying
    (:func:`autopilot.process.configure_for_flight`) before it runs."""

    name: str
    help: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    description: str | None = None
    flight: bool = False

    def attach(self, subparsers) -> argparse.ArgumentParser:
        parser = subparsers.add_parser(
            self.name, help=self.help,
            description=self.description
            or (self.help[:1].upper() + self.help[1:]).replace("%%", "%") + ".")
        self.arguments(parser)
        parser.set_defaults(handler=self.run, flight=self.flight)
        return parser


def add_config_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE",
                        help="configuration file (default: the project's config.yaml)")
    add_set_option(parser)


def add_set_option(parser: argparse.ArgumentParser,
                   text: str = "override a configuration key (dotted path, e.g. "
                   "sim.wind.gust_mps=2); repeatable") -> None:
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help=text)


def add_fault_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--fault", dest="faults", action="append", default=[], metavar="KIND[:KEY=VALUE,...]",
        help="inject a fault in the simulated vehicle (replaces the mission's scenario.faults; "
        "repeatable), e.g. camera_dropout:start_s=12,duration_s=3 or link_loss:fraction=0.3; "
        "kinds and parameters: drivers/sim/faults.py and the docs")


def add_json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def check_choices(option: str, given: Iterable[str] | None, known: Iterable[str],
                  what: str = "no such name") -> None:
    """An :class:`InputError` for the first of ``given`` not in ``known``, naming the option,
    the known names and the nearest one."""
    known = list(known)
    for value in given or ():
        if value not in known:
            raise InputError(f"{option} {value}: {what}{did_you_mean(value, known)} (known: "
                             f"{', '.join(known)})")


def at_least(option: str, value: int | float, low: int | float) -> None:
    if value < low:
        raise InputError(f"{option} {value}: at least {low}")


def stderr_progress(message: str) -> None:
    """Progress of a long command on stderr (stdout keeps its table or JSON)."""
    print(f"  {message}", file=sys.stderr, flush=True)


def add_workers_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="flights at once, each in a process of its own (default: one per "
                        "core; 1: one after the other in this process)")


def quiet(message: str) -> None:
    """Progress nobody reads (``--json``)."""


def progress_for(args: argparse.Namespace) -> Callable[[str], None]:
    return quiet if getattr(args, "json", False) else stderr_progress


def fmt(value) -> str:
    return "n/a" if value is None else f"{value:.3f}" if isinstance(value, float) else str(value)
