"""The ``autopilot`` command."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from collections.abc import Sequence

from autopilot import __version__
from autopilot.config import ConfigError, load_config

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE",
                        help="configuration file (default: the project's config.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a configuration key "
                        "(dotted path, e.g. sim.wind.gust_mps=2); repeatable")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="autopilot", description="Camera-guided quadrotor missions for PX4 / MAVLink "
        "vehicles, with a built-in MuJoCo simulator.")
    parser.add_argument("--version", action="version", version=f"autopilot {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    bench = commands.add_parser("bench", help="run a benchmark")
    benches = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    sitl = benches.add_parser(
        "sitl", help="simulator speed and flight-stack accuracy: takeoff, 2 m step, hover, land")
    sitl.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    sitl.add_argument("--realtime", action="store_true",
                      help="run against the wall clock instead of lockstep")
    _add_config_options(sitl)

    validate = commands.add_parser("validate", help="check a configuration file")
    validate.add_argument("file")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "bench":
            return _bench(args)
        if args.command == "validate":
            load_config(args.file)
            print(f"{args.file}: ok")
            return EXIT_OK
    except ConfigError as exc:
        print(f"error: invalid configuration:\n{exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    raise AssertionError(f"unhandled command {args.command}")


def _bench(args: argparse.Namespace) -> int:
    from autopilot.bench.sitl import format_table, run_sitl_bench

    config = load_config(args.config, args.overrides)
    log = (lambda message: None) if args.json else \
        (lambda message: print(f"  {message}", file=sys.stderr, flush=True))
    result = asyncio.run(run_sitl_bench(config.sim, lockstep=not args.realtime, log=log))
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(format_table(result))
    return EXIT_OK
