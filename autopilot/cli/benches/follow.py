"""``autopilot bench follow_ball | follow_marker``."""

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

BASELINES = {"follow_ball": "the seed 001 and 003 rules", "follow_marker": "the seed 002 rule"}


def arguments_for(name: str):
    def arguments(follow: argparse.ArgumentParser) -> None:
        add_json_option(follow)
        follow.add_argument("--mission", default=name, metavar="NAME|FILE")
        follow.add_argument("--scenario", dest="scenarios", action="append", default=None,
                            metavar="NAME", help="only this scenario (repeatable)")
        follow.add_argument("--quick", action="store_true",
                            help="one seed of the default scenario, the step shortened to 10 s "
                            "(CI)")
        follow.add_argument("--seeds", type=int, default=3, metavar="N",
                            help="scenario seeds per scenario and controller (default 3)")
        follow.add_argument("--seed-start", type=int, default=1, metavar="S",
                            help="the first scenario seed (default 1)")
        follow.add_argument("--row", dest="rows", action="append", default=None,
                            metavar="NAME", help="only this controller (ours or a seed rule; "
                            "repeatable)")
        add_workers_option(follow)
        add_set_option(follow, "override a mission or configuration key")
    return arguments


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import follow

    bench = follow.BENCHES[args.bench]
    check_choices("--scenario", args.scenarios, bench.scenarios, "no such scenario")
    at_least("--seeds", args.seeds, 1)
    check_choices("--row", args.rows, bench.controllers, "no such controller")
    if args.workers is not None:
        at_least("--workers", args.workers, 1)
    result = follow.run_bench(args.bench, args.mission, args.overrides, progress_for(args),
                              args.scenarios, quick=args.quick, seeds=args.seeds,
                              seed_start=args.seed_start, controllers=args.rows,
                              workers=args.workers, announce=stderr_progress)
    print(json.dumps(result) if args.json else follow.format_table(result))
    return EXIT_OK


BENCHES = tuple(
    Command(name, f"{name}: default, hard (figure eight in gusts) and stress (random walk at "
            f"2.5 m/s, 3 m/s gusts) scenarios, our controller against {baselines}",
            arguments_for(name), run)
    for name, baselines in BASELINES.items())
