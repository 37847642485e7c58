"""``autopilot bench offboard``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    at_least,
    check_choices,
    progress_for,
)


def arguments(offboard: argparse.ArgumentParser) -> None:
    add_json_option(offboard)
    offboard.add_argument("--seeds", type=int, default=2, metavar="N",
                          help="seeds per scenario and tracker (default 2)")
    offboard.add_argument("--scenario", dest="scenarios", action="append", default=None,
                          metavar="NAME", help="only this scenario (repeatable)")
    add_set_option(offboard, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import offboard

    check_choices("--scenario", args.scenarios, offboard.SCENARIOS, "no such scenario")
    at_least("--seeds", args.seeds, 1)
    result = offboard.run_bench(args.seeds, args.overrides, progress_for(args), args.scenarios)
    print(json.dumps(result) if args.json else offboard.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "offboard", "orbit and survey (seed 004): our trajectory tracking against seed 004's PID, "
    "over the shipped, concave and gusty scenarios: cross-track error, coverage, photos, "
    "real-time factor (about 8 min)", arguments, run),)
