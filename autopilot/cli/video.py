"""``autopilot video``: a camera's logged frames with overlays, as DIR/onboard.mp4."""

from __future__ import annotations

import argparse
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command
from autopilot.cli.report import run_folder_log


def arguments(video: argparse.ArgumentParser) -> None:
    video.add_argument("run_dir", metavar="DIR", help="a run's folder (holding flight.mcap)")
    video.add_argument("--camera", metavar="NAME",
                       help="whose frames (default: the followed camera)")


def run(args: argparse.Namespace) -> int:
    from autopilot.report.video import write_video

    run_folder_log(args.run_dir)
    path, frames = write_video(Path(args.run_dir), args.camera)
    print(f"wrote {path} ({frames} frames)")
    return EXIT_OK


COMMAND = Command("video", "write DIR/onboard.mp4: a camera's logged frames with overlays",
                  arguments, run)
