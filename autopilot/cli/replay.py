"""``autopilot replay``: detection and estimation again over a logged flight."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command, add_set_option
from autopilot.cli.report import run_folder_log


def arguments(replay: argparse.ArgumentParser) -> None:
    replay.add_argument("run_dir", metavar="DIR", help="a run's folder (holding flight.mcap)")
    add_set_option(replay, "change a setting of the flight's configuration (e.g. "
                   "perception.ball.min_circularity=0.7, "
                   "estimation.target.accel_noise_m_s2=2); repeatable")
    replay.add_argument("--json", action="store_true",
                        help="print one JSON object on stdout (shaped like summary.json)")


def run(args: argparse.Namespace) -> int:
    from autopilot.flightlog.records import clean
    from autopilot.replay import format_replay, replay

    run_folder_log(args.run_dir)
    result = replay(Path(args.run_dir), args.overrides)
    print(json.dumps(clean(result)) if args.json else format_replay(result))
    return EXIT_OK


COMMAND = Command(
    "replay", "re-run detection and estimation over a logged flight's frames and telemetry "
    "(optionally with changed settings) and report their metrics", arguments, run)
