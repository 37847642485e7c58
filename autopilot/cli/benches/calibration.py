"""``autopilot bench calibration``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autopilot.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    Command,
    add_config_options,
    add_json_option,
    progress_for,
)
from autopilot.config import load_config


def arguments(calibration: argparse.ArgumentParser) -> None:
    add_json_option(calibration)
    calibration.add_argument("--quick", action="store_true",
                             help="the ChArUco board only, fewer views (what the test suite "
                             "runs)")
    calibration.add_argument("--save-views", metavar="DIR",
                             help="also write the rendered views as PNG files, a folder per "
                             "board (DIR/charuco, DIR/chessboard), for 'autopilot calibrate'")
    add_config_options(calibration)


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import calibration as calibration_bench

    config = load_config(args.config, args.overrides)
    result = calibration_bench.run_bench(
        progress_for(args), quick=args.quick, config=config,
        save_dir=Path(args.save_views) if args.save_views else None)
    print(json.dumps(result) if args.json else calibration_bench.format_table(result))
    return EXIT_OK if all(r["met"] for r in result["required"].values()) else EXIT_FAILED


BENCHES = (Command(
    "calibration", "'autopilot calibrate' on views of a ChArUco board and a chessboard "
    "rendered by the simulated front camera (distortion, noise, motion blur) from known poses: "
    "focal length, principal point and distortion against the truth, reprojection error",
    arguments, run),)
