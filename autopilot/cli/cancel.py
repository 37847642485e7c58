"""``autopilot cancel``: cancel a goal; the vehicle hovers."""

from __future__ import annotations

import argparse
import sys

from autopilot.cli.client import Client, NoApi, add_api_options, no_api, show
from autopilot.cli.common import EXIT_USAGE, Command


def arguments(cancel: argparse.ArgumentParser) -> None:
    cancel.add_argument("goal_id", nargs="?", help="default: the running goal")
    add_api_options(cancel)


def run(args: argparse.Namespace) -> int:
    client = Client(args)
    try:
        goal_id = args.goal_id
        if goal_id is None:
            body = client.call("GET", "/api/status")[1]
            goal_id = body.get("goal_id") if isinstance(body, dict) else None
            if goal_id is None:
                print("no goal is running", file=sys.stderr)
                return EXIT_USAGE
        return show(*client.call("POST", f"/api/goals/{goal_id}/cancel"))
    except NoApi as exc:
        return no_api(exc)


COMMAND = Command("cancel", "cancel a goal (default: the running one); the vehicle hovers",
                  arguments, run)
