"""``autopilot bench hover_image | land_pad``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    add_workers_option,
    at_least,
    check_choices,
    progress_for,
    stderr_progress,
)

BASELINES = {
    "hover_image": ("", "seed 000's ORB 300 + FLANN + solvePnPRansac, flown with our "
                    "controller"),
    "land_pad": (", decoys", "seed 001's multi-scale TM_CCOEFF template matching, flown with "
                 "our lander and with seed 001's own"),
}


def arguments(down: argparse.ArgumentParser) -> None:
    add_json_option(down)
    down.add_argument("--seeds", type=int, default=3, metavar="N",
                      help="scenario seeds per scenario and detector (default 3)")
    down.add_argument("--scenario", dest="scenarios", action="append", default=None,
                      metavar="NAME", help="only this scenario (repeatable)")
    down.add_argument("--quick", action="store_true",
                      help="one seed of a shortened default scenario (what CI flies)")
    down.add_argument("--row", dest="rows", action="append", default=None, metavar="NAME",
                      help="only this row (ours or a baseline; repeatable)")
    down.add_argument("--seed-start", type=int, default=1, metavar="S",
                      help="the first scenario seed (default 1)")
    add_workers_option(down)
    add_set_option(down, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import down

    bench = down.BENCHES[args.bench]
    check_choices("--scenario", args.scenarios, bench.scenarios, "no such scenario")
    at_least("--seeds", args.seeds, 1)
    check_choices("--row", args.rows, bench.rows, "no such row")
    if args.workers is not None:
        at_least("--workers", args.workers, 1)
    result = down.run_bench(args.bench, args.seeds, args.overrides, progress_for(args),
                            args.scenarios, quick=args.quick, rows=args.rows,
                            seed_start=args.seed_start, workers=args.workers,
                            announce=stderr_progress)
    print(json.dumps(result) if args.json else down.format_table(result))
    return EXIT_OK


BENCHES = tuple(
    Command(name, f"{name}: default and hard (gusts, target offset and turned{extra}) "
            f"scenarios over a few seeds, ours against {seed}; a run without its figure "
            "counts as a failure", arguments, run)
    for name, (extra, seed) in BASELINES.items())
