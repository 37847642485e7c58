"""``autopilot bench landing``."""

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
    stderr_progress,
)
from autopilot.config import InputError


def arguments(landing: argparse.ArgumentParser) -> None:
    add_json_option(landing)
    landing.add_argument("--trials", type=int, default=20, metavar="N",
                         help="seeds per strategy (default 20)")
    landing.add_argument("--rover-speed", type=float, default=1.5, metavar="M_S",
                         help="the rover's speed (default 1.5 m/s)")
    landing.add_argument("--strategy", dest="strategies", action="append", default=None,
                         choices=("ours", "seed004", "ours_uwb_only"),
                         help="only this strategy (repeatable)")
    landing.add_argument("--workers", type=int, default=None, metavar="N",
                         help="parallel runs (default: one per core)")
    landing.add_argument("--cluster", metavar="ADDRESS",
                         help="run the trials on this Ray cluster ('local': start one here)")
    add_set_option(landing, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import landing

    at_least("--trials", args.trials, 1)
    if not 0.0 <= args.rover_speed <= 5.0:
        raise InputError(f"--rover-speed {args.rover_speed}: between 0 and 5 m/s")
    if args.workers is not None:
        at_least("--workers", args.workers, 1)
    result = landing.run_bench(args.trials, args.rover_speed, args.overrides, progress_for(args),
                               workers=args.workers, cluster=args.cluster,
                               strategies=args.strategies, announce=stderr_progress)
    print(json.dumps(result) if args.json else landing.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "landing", "land_on_rover over many seeds: ours against seed 004's (its fused filter and "
    "gain-scheduled PID) and ours without the tag, in the same trials: success rate, median "
    "and p95 touchdown error (--rover-speed 0: a static rover)", arguments, run),)
