"""``autopilot bench mavlink``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command, add_json_option, check_choices, progress_for


def arguments(bench: argparse.ArgumentParser) -> None:
    add_json_option(bench)
    bench.add_argument("--mission", dest="missions", action="append", default=None,
                       metavar="NAME", help="only this mission (repeatable; default: every "
                       "shipped mission but standby)")
    bench.add_argument("--firmware", dest="firmwares", action="append", default=None,
                       metavar="NAME", help="px4 or ardupilot (repeatable; default both)")
    bench.add_argument("--driver", dest="drivers", action="append", default=None,
                       metavar="NAME", help="pymavlink or mavsdk (repeatable; default both)")
    bench.add_argument("--instance", type=int, default=6, metavar="N",
                       help="the simulator's SITL instance (its ports; default 6)")
    bench.add_argument("--set", dest="overrides", action="append", default=[],
                       metavar="KEY=VALUE", help="a key of the world or the mission, for both "
                       "processes (e.g. scenario.seed=5, sim.wind.gust_mps=1.5)")
    bench.add_argument("--out", type=Path, default=None, metavar="DIR",
                       help="keep each flight's logs, truth and summary here")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import mavlink

    check_choices("--mission", args.missions, mavlink.MISSIONS, "no such mission")
    check_choices("--firmware", args.firmwares, mavlink.FACES, "no such firmware")
    check_choices("--driver", args.drivers, mavlink.DRIVERS, "no such driver")
    result = mavlink.run_bench(args.missions or mavlink.MISSIONS,
                               args.firmwares or tuple(mavlink.FACES),
                               args.drivers or mavlink.DRIVERS, out_dir=args.out,
                               instance=args.instance, overrides=args.overrides,
                               log=progress_for(args))
    print(json.dumps(result) if args.json else mavlink.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "mavlink", "every shipped mission through each MAVLink driver (pymavlink, MAVSDK) against "
    "'autopilot sim --firmware px4|ardupilot' in real time, each part its own process as a "
    "user runs it, scored against truth (about 45 min for the full matrix; --mission, "
    "--firmware, --driver narrow it)", arguments, run),)
