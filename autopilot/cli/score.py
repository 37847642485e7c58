"""``autopilot score``: a MAVLink run scored against the simulator's recorded truth."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from autopilot.cli.common import EXIT_FAILED, EXIT_OK, Command, fmt
from autopilot.cli.report import run_folder_log
from autopilot.config import InputError


def arguments(scorer: argparse.ArgumentParser) -> None:
    scorer.add_argument("run_dir", metavar="RUN_DIR", help="the run's folder")
    scorer.add_argument("--truth", required=True, metavar="FILE",
                        help="the simulator's truth.mcap ('autopilot sim --out DIR')")


def run(args: argparse.Namespace) -> int:
    from autopilot.score import score

    run_folder_log(args.run_dir)
    if not Path(args.truth).is_file():
        raise InputError(f"--truth {args.truth}: no such file (the truth.mcap 'autopilot sim "
                         "--out DIR' wrote)")
    metrics = score(Path(args.run_dir), Path(args.truth))
    groups = {name: group for name, group in metrics.items()
              if name != "steps" and isinstance(group, dict) and group}
    if not groups:
        print("no step of this run is scored by its metrics, or no truth "
              "overlapping it", file=sys.stderr)
        return EXIT_FAILED
    for name, group in groups.items():
        print(f"{name}: " + ", ".join(f"{k}={fmt(v)}" for k, v in group.items()
                                     if not isinstance(v, (dict, list))))
    print(f"updated {Path(args.run_dir) / 'summary.json'}")
    return EXIT_OK


COMMAND = Command("score", "score a run flown through a MAVLink driver against the ground "
                  "truth 'autopilot sim --out' recorded", arguments, run)
