"""``autopilot doctor``: a companion computer's preflight check."""

from __future__ import annotations

import argparse
import asyncio
import json
from pathlib import Path

from autopilot.cli.common import EXIT_FAILED, EXIT_OK, Command, add_set_option
from autopilot.vehicle_kinds import DRIVER_KINDS


def arguments(doctor: argparse.ArgumentParser) -> None:
    doctor.add_argument("--mission", default="follow_ball", metavar="NAME|FILE",
                        help="the mission whose cameras and settings to check (default "
                        "follow_ball)")
    doctor.add_argument("--driver", choices=[k.name for k in DRIVER_KINDS.values()
                                             if k.doctor is not None],
                        help="the vehicle's driver (default: the configuration's, else "
                        "pymavlink); ardrone: a Parrot AR.Drone 2.0")
    doctor.add_argument("--connect", metavar="URL",
                        help="the vehicle's address (as for run: MAVLink, or ardrone://HOST)")
    doctor.add_argument("--video", action="append", metavar="[CAMERA=]URL",
                        help="a camera's stream (as for run)")
    doctor.add_argument("--calibration", action="append", metavar="[CAMERA=]FILE",
                        help="a camera's intrinsics (as for run)")
    doctor.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key")
    doctor.add_argument("--duration-s", type=float, default=5.0, metavar="S",
                        help="how long to measure rates (default 5)")
    doctor.add_argument("--json", action="store_true", help="print one JSON object")
    add_set_option(doctor, "override a mission or configuration key")


def run(args: argparse.Namespace) -> int:
    from autopilot.doctor import as_dicts, run_doctor, summary_line
    from autopilot.logs import setup_logging
    from autopilot.mission import load_mission

    setup_logging(None)
    plan = load_mission(args.mission, args.overrides)
    driver = args.driver or (plan.config.driver if plan.config.driver != "sim" else "pymavlink")
    plan = load_mission(args.mission, [*args.overrides, f"driver={driver}"])
    report = (lambda check: None) if args.json else (lambda check: print(check.line(),
                                                                         flush=True))
    checks = asyncio.run(run_doctor(
        plan, connect=args.connect, video=args.video, calibration=args.calibration,
        signing_key=Path(args.signing_key) if args.signing_key else None,
        duration_s=args.duration_s, report=report))
    if args.json:
        print(json.dumps({"checks": as_dicts(checks), "ok": not any(
            c.status == "FAIL" for c in checks)}))
    else:
        print(summary_line(checks))
    return EXIT_FAILED if any(c.status == "FAIL" for c in checks) else EXIT_OK


COMMAND = Command(
    "doctor", "preflight check of a companion computer: MAVLink link (heartbeat, rates, time "
    "sync) or an AR.Drone's (navdata, firmware, battery), cameras (frames, rate, "
    "calibration), clock, disk", arguments, run, flight=True,
    description="Preflight check of a companion computer against its vehicle: the MAVLink "
    "link (heartbeat, message rates, time sync), each camera the mission uses (frames, rate, "
    "calibration), the clock and the disk. Exit code 1 if any check fails.")
