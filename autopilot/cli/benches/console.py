"""``autopilot bench console``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import EXIT_OK, Command, add_json_option, progress_for
from autopilot.config import InputError


def arguments(console_bench: argparse.ArgumentParser) -> None:
    add_json_option(console_bench)
    console_bench.add_argument("--window", type=float, default=8.0, metavar="S",
                               help="each window's wall time (default 8)")
    console_bench.add_argument("--windows", type=int, default=2, metavar="N",
                               help="windows each way, alternating (default 2)")
    console_bench.add_argument("--fps", type=float, default=15.0,
                               help="the viewer's frame rate (default 15)")
    console_bench.add_argument("--browser", action="store_true",
                               help="the viewer is the console's page in headless chromium "
                               "(Playwright): latency to the frame drawn")
    console_bench.add_argument("--bare", action="store_true",
                               help="watch the bare frames (?overlay=0): the newest, without "
                               "waiting for the frame's detections")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import console as console_bench

    if args.window <= 0 or args.windows < 1 or not 0 < args.fps <= 30:
        raise InputError("--window must be positive, --windows at least 1, --fps in "
                         "(0, 30]")
    result = console_bench.run_bench(args.window, args.windows, args.fps, args.browser,
                                     progress_for(args), overlay=not args.bare)
    print(json.dumps(result) if args.json else console_bench.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "console", "what the operator console costs the autopilot (a real-time follow_ball, "
    "windows with and without a viewer of the front camera's MJPEG) and the video's "
    "capture-to-viewer latency (about 1 min)", arguments, run),)
