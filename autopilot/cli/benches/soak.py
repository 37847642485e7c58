"""``autopilot bench soak``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    stderr_progress,
)
from autopilot.config import InputError


def arguments(soak_bench: argparse.ArgumentParser) -> None:
    add_json_option(soak_bench)
    soak_bench.add_argument("--duration-s", type=float, default=3600.0, metavar="S",
                            help="simulated seconds of flight (default 3600)")
    soak_bench.add_argument("--mission", dest="missions", action="append", default=None,
                            metavar="NAME", help="fly only these missions, in turn (repeatable)")
    add_set_option(soak_bench, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import soak
    from autopilot.mission import load_mission

    if not args.duration_s > 0:
        raise InputError(f"--duration-s {args.duration_s}: must be positive")
    missions = args.missions or soak.MISSIONS
    for name in missions:
        load_mission(name, args.overrides)  # nothing flies on an invalid mission
    result = soak.run_bench(args.duration_s, missions, args.overrides, stderr_progress)
    print(json.dumps(result) if args.json else soak.format_table(result))
    return EXIT_OK if result["ok"] else EXIT_FAILED


BENCHES = (Command(
    "soak", "an hour of simulated flight (lockstep), the shipped missions back to back in one "
    "process: memory, tasks, threads, file descriptors and event-loop lag sampled; fails on "
    "growth over 5 %% or any leak (about 25 min on 2 cores)", arguments, run),)
