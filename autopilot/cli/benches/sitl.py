"""``autopilot bench sitl``."""

from __future__ import annotations

import argparse
import asyncio
import json

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_config_options,
    add_json_option,
    progress_for,
)
from autopilot.config import load_config


def arguments(sitl: argparse.ArgumentParser) -> None:
    add_json_option(sitl)
    sitl.add_argument("--realtime", action="store_true",
                      help="run against the wall clock instead of lockstep")
    add_config_options(sitl)


def run(args: argparse.Namespace) -> int:
    from autopilot.bench.sitl import format_table, run_sitl_bench

    config = load_config(args.config, args.overrides)
    result = asyncio.run(run_sitl_bench(config.sim, lockstep=not args.realtime,
                                        log=progress_for(args)))
    print(json.dumps(result.to_dict()) if args.json else format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "sitl", "simulator speed and flight-stack accuracy: takeoff, 2 m step, hover, land",
    arguments, run),)
