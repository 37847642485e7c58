"""``autopilot status``: a run's status, from its goal API."""

from __future__ import annotations

import argparse
import time

from autopilot.cli.client import Client, NoApi, add_api_options, no_api, show
from autopilot.cli.common import Command


def arguments(status: argparse.ArgumentParser) -> None:
    status.add_argument("--watch", action="store_true",
                        help="print the status every second until interrupted")
    add_api_options(status)


def run(args: argparse.Namespace) -> int:
    client = Client(args)
    try:
        while True:
            code, body = client.call("GET", "/api/status")
            if not args.watch:
                return show(code, body)
            b = body if isinstance(body, dict) else {}
            pos = b.get("position_ned_m") or [float("nan")] * 3
            print(f"status {b.get('status_code')} {b.get('status')}  step={b.get('step')}  "
                  f"phase={b.get('phase')}  goal={b.get('goal_id')}  mode={b.get('mode')}  "
                  f"ned=({pos[0]:.1f}, {pos[1]:.1f}, {pos[2]:.1f})", flush=True)
            time.sleep(1.0)
    except NoApi as exc:
        return no_api(exc)


COMMAND = Command("status", "show a run's status (goal API)", arguments, run,
                  description="Show a run's status from its goal API: mission status code, "
                  "step, phase, goal, flight mode and position. Exit code 4 if no API answers.")
