"""``autopilot bench logging``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    at_least,
    progress_for,
)


def arguments(logging_bench: argparse.ArgumentParser) -> None:
    add_json_option(logging_bench)
    logging_bench.add_argument("--pairs", type=int, default=3, metavar="N",
                               help="runs with and without the log (default 3 of each)")
    logging_bench.add_argument("--mission", default="follow_ball", metavar="NAME|FILE")
    add_set_option(logging_bench, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import logging as logging_bench

    at_least("--pairs", args.pairs, 1)
    result = logging_bench.run_bench(args.mission, args.overrides, args.pairs,
                                     progress_for(args))
    print(json.dumps(result) if args.json else logging_bench.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "logging", "what writing flight.mcap (camera frames included) costs a lockstep follow_ball "
    "run: alternate runs with and without the log", arguments, run),)
