"""``autopilot bench api``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import EXIT_FAILED, EXIT_OK, Command, add_json_option, progress_for
from autopilot.config import InputError


def arguments(api_bench: argparse.ArgumentParser) -> None:
    add_json_option(api_bench)
    api_bench.add_argument("--seconds", type=float, default=20.0, metavar="S",
                           help="hover this long in each flight (default 20)")
    api_bench.add_argument("--poll-hz", type=float, default=10.0, metavar="HZ",
                           help="GET /api/status rate while busy (default 10)")
    api_bench.add_argument("--abuse", action="store_true",
                           help="instead: one real-time standby with the console and a token, "
                           "attacked from another process (idle sockets, slow headers, 8 MB and "
                           "deep bodies, no token), then the largest accepted orbit, survey and "
                           "goto and a goal flood: the loop's lag per phase and whether the "
                           "flight went on (about 3 min)")
    api_bench.add_argument("--idle", type=int, default=2000, metavar="N",
                           help="--abuse: idle sockets opened at once (default 2000)")
    api_bench.add_argument("--flood", type=int, default=500, metavar="N",
                           help="--abuse: goals posted back to back (default 500)")


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import api as api_bench

    log = progress_for(args)
    if args.seconds <= 0 or args.poll_hz <= 0:
        raise InputError("--seconds and --poll-hz must be positive")
    if args.abuse:
        if not 0 < args.idle <= 20_000 or not 0 < args.flood <= 100_000:
            raise InputError("--idle must be 1-20000 and --flood 1-100000")
        result = api_bench.run_abuse(args.idle, max(args.seconds, 12.0), args.flood, log)
        print(json.dumps(result) if args.json else api_bench.format_abuse(result))
        return EXIT_OK if result["status"] == "completed" and not result["aborted"] \
            else EXIT_FAILED
    result = api_bench.run_bench(args.seconds, args.poll_hz, log)
    print(json.dumps(result) if args.json else api_bench.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "api", "what the goal API costs the process: a real-time standby hover with the API idle, "
    "then busy (status polled, the status stream followed) (about 1 min); --abuse: the API "
    "under attack", arguments, run),)
