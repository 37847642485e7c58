"""``autopilot bench faults``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    at_least,
    check_choices,
    stderr_progress,
)
from autopilot.config import InputError


def arguments(faults_bench: argparse.ArgumentParser) -> None:
    add_json_option(faults_bench)
    faults_bench.add_argument("--seeds", type=int, default=2, metavar="N",
                              help="seeds per cell (default 2)")
    faults_bench.add_argument("--seed-start", type=int, default=0, metavar="S")
    faults_bench.add_argument("--mission", dest="missions", action="append", default=None,
                              metavar="NAME", help="only this mission (repeatable)")
    faults_bench.add_argument("--kind", dest="kinds", action="append", default=None,
                              metavar="KIND", help="only this fault kind or case, e.g. "
                              "gps_loss or battery_sag/critical (repeatable)")
    faults_bench.add_argument("--workers", type=int, default=None, metavar="N",
                              help="parallel runs (default: one per core)")
    add_set_option(faults_bench, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import faults

    at_least("--seeds", args.seeds, 1)
    check_choices("--mission", args.missions, faults.MISSIONS, "not in the fault bench")
    known = [*dict.fromkeys([c.kind for c in faults.CASES] + [c.name for c in faults.CASES])]
    check_choices("--kind", args.kinds, known, "no such fault case")
    if not faults.cells(args.missions, args.kinds):
        raise InputError("no cell applies to those missions and kinds")
    result = faults.run_bench(args.seeds, args.missions, args.kinds, args.overrides,
                              stderr_progress, workers=args.workers, seed_start=args.seed_start)
    print(json.dumps(result) if args.json else faults.format_table(result))
    return EXIT_OK if result["total"]["unsafe"] == 0 else EXIT_FAILED


BENCHES = (Command(
    "faults", "every shipped mission × every fault that applies (camera, telemetry, link, EKF, "
    "GPS, rangefinder, motor, battery, wind, rover, decoy), several seeds each: completed / "
    "ended safe / unsafe counts per cell and the worst seeds to replay (about an hour for the "
    "full matrix at 2 seeds on 2 cores; --mission/--kind narrow it)", arguments, run),)
