"""``autopilot bench speed``."""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command, add_json_option, add_set_option, stderr_progress


def arguments(speed: argparse.ArgumentParser) -> None:
    from autopilot.bench.speed import DEFAULT_MISSIONS, PROFILES

    add_json_option(speed)
    speed.add_argument("--mission", action="append", metavar="NAME",
                       help="only this mission (repeatable; default: "
                       f"{', '.join(DEFAULT_MISSIONS)})")
    speed.add_argument("--profile", action="append", choices=PROFILES,
                       help="only this sensor profile (repeatable; default both)")
    speed.add_argument("--out", metavar="DIR", help="keep each flight's log and summary here")
    add_set_option(speed, "override a mission or configuration key (every flight)")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench.speed import DEFAULT_MISSIONS, PROFILES, format_table, run_bench
    from autopilot.mission import load_mission

    missions = tuple(dict.fromkeys(args.mission or DEFAULT_MISSIONS))
    profiles = tuple(dict.fromkeys(args.profile or PROFILES))
    for name in missions:  # each checked with the overrides before anything flies
        for profile in profiles:
            load_mission(name, [f"sim.profile={profile}", *args.overrides])
    profiles = tuple(dict.fromkeys(args.profile or PROFILES))
    with tempfile.TemporaryDirectory(prefix="bench-speed-") as scratch:
        out = Path(args.out) if args.out else Path(scratch)
        result = run_bench(missions, profiles, args.overrides, out, stderr_progress)
    print(json.dumps(result) if args.json else format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "speed", "where a simulated second goes: each mission in lockstep on each sensor profile, "
    "its real-time factor and the CPU ms per simulated second of each stage (physics, flight "
    "stack, rendering, camera model, codec, detection, estimation, control, logging, metrics), "
    "and what bounds it (about 1 min per mission and profile)", arguments, run),)
