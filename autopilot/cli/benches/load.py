"""``autopilot bench load``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_json_option,
    add_set_option,
    stderr_progress,
)
from autopilot.config import InputError


def arguments(load_bench: argparse.ArgumentParser) -> None:
    add_json_option(load_bench)
    load_bench.add_argument("--hogs", default="0,2,4,6", metavar="N|N,N,...",
                            help="busy processes: one load, or a list (default 0,2,4,6)")
    load_bench.add_argument("--follow-s", type=float, default=20.0, metavar="S",
                            help="how long each flight follows the ball (default 20)")
    load_bench.add_argument("--repeat", type=int, default=1, metavar="K",
                            help="fly each load K times, a row per flight (default 1): one "
                            "real-time flight on a busy CPU is one draw of many")
    load_bench.add_argument("--driver", choices=("mavsdk", "pymavlink"), default="mavsdk")
    load_bench.add_argument("--out", metavar="DIR",
                            help="keep each load's logs (vehicle, run, viewer) in DIR/hogsN "
                            "(DIR/hogsN-K when repeated)")
    add_set_option(load_bench, "override a mission or configuration key (the vehicle's and "
                   "the autopilot's)")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import load as load_bench
    from autopilot.bench.load_figures import format_table

    hogs = load_bench.parse_hogs(args.hogs)
    if not 0 < args.follow_s <= 600:
        raise InputError(f"--follow-s {args.follow_s}: between 0 and 600 s")
    if not 1 <= args.repeat <= 50:
        raise InputError(f"--repeat {args.repeat}: between 1 and 50 flights per load")
    cores = load_bench.pick_cores()
    result = load_bench.run_bench(hogs, args.follow_s, args.driver, args.overrides,
                                  stderr_progress, Path(args.out) if args.out else None,
                                  cores=cores, repeat=args.repeat)
    print(json.dumps(result) if args.json else format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "load", "flight on a busy CPU: the vehicle (autopilot sim) on a core of its own, the "
    "autopilot (MAVLink driver, H.264 video, a console viewer) sharing the other with N busy "
    "processes; per N: completed, control tick, latency, frames shed by perception and by "
    "the console, range RMS (about 1 min per N)", arguments, run),)
