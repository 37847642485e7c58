"""``autopilot trials``: many seeded lockstep runs of a mission, in parallel."""

from __future__ import annotations

import argparse
from pathlib import Path

from autopilot.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    Command,
    add_fault_option,
    add_set_option,
    progress_for,
    stderr_progress,
)
from autopilot.config import InputError


def arguments(trials: argparse.ArgumentParser) -> None:
    trials.add_argument("mission", metavar="NAME|FILE")
    trials.add_argument("--trials", type=int, default=10, metavar="N",
                        help="runs (seeds SEED_START .. SEED_START+N-1; default 10)")
    trials.add_argument("--seed-start", type=int, default=0, metavar="S",
                        help="the first scenario seed (default 0)")
    add_set_option(trials, "override a mission or configuration key (every run)")
    add_fault_option(trials)
    trials.add_argument("--vary", dest="varies", action="append", default=[],
                        metavar="KEY=LOW:HIGH|KEY=A,B,C",
                        help="draw a key's value per seed: uniformly in [LOW, HIGH], or one "
                        "of the values (repeatable)")
    trials.add_argument("--success", dest="criteria", action="append", default=None,
                        metavar="KEY[OP NUMBER]",
                        help="what a successful run shows, e.g. landing.on_deck or "
                        "'landing.error_m<=0.1' (repeatable; default: completed, and on the "
                        "deck or pad for a landing)")
    trials.add_argument("--workers", type=int, default=None, metavar="N",
                        help="parallel runs (default: one per core)")
    trials.add_argument("--cluster", metavar="ADDRESS",
                        help="run each trial as a task on this Ray cluster ('local': start "
                        "a Ray instance here; needs pip install 'autopilot[cluster]')")
    trials.add_argument("--out", metavar="DIR",
                        help="keep each run's flight log and summary in DIR/seed<N>")
    trials.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def run(args: argparse.Namespace) -> int:
    from autopilot.trials import (
        TrialsError,
        parse_criterion,
        parse_vary,
        print_result,
        run_trials,
    )

    try:
        varies = [parse_vary(v) for v in args.varies]
        criteria = [parse_criterion(c) for c in args.criteria] if args.criteria else None
        if args.workers is not None and args.workers < 1:
            raise TrialsError("--workers must be at least 1")
        if args.trials < 1:
            raise TrialsError(f"--trials {args.trials}: at least 1")
        result = run_trials(args.mission, args.trials, seed_start=args.seed_start,
                            overrides=args.overrides, varies=varies, criteria=criteria,
                            workers=args.workers, cluster=args.cluster,
                            out_dir=Path(args.out) if args.out else None,
                            progress=progress_for(args), announce=stderr_progress)
    except TrialsError as exc:
        raise InputError(str(exc)) from None
    print_result(result, args.json)
    return EXIT_OK if not result.failing else EXIT_FAILED


COMMAND = Command(
    "trials", "many seeded lockstep runs of a mission in parallel: each metric's median, p95 "
    "and worst seed, and the failing seeds to replay", arguments, run, flight=True,
    description="Many seeded lockstep runs of a mission in parallel: each metric's median, "
    "p95 and worst seed, and the failing seeds with the command that replays each. Exit "
    "code 1 if any run failed its success criteria.")
