"""``autopilot goal``: send a goal (one mission step) to a run's goal API."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from autopilot.cli.client import Client, NoApi, add_api_options, no_api, show
from autopilot.cli.common import EXIT_FAILED, EXIT_OK, Command
from autopilot.config import InputError


def arguments(goal: argparse.ArgumentParser) -> None:
    goal.add_argument("goal", metavar="JSON|FILE",
                      help="the step as JSON, e.g. '{\"goto\": {\"position_m\": [5, 0, 3]}}', "
                      "or a YAML/JSON file holding it")
    goal.add_argument("--wait", action="store_true",
                      help="follow the goal until it ends (feedback on stderr)")
    add_api_options(goal)


def read_goal(text: str):
    """The goal's body from JSON text or a YAML/JSON file."""
    if not text.lstrip().startswith("{") and Path(text).is_file():
        import yaml

        try:
            return yaml.safe_load(Path(text).read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            raise InputError(f"{text}: not a YAML or JSON goal ({exc})") from None
    try:
        return json.loads(text)
    except ValueError as exc:
        raise InputError(f"the goal is not JSON ({exc}) nor a file; e.g. "
                         "'{\"goto\": {\"position_m\": [5, 0, 3]}}'") from None


def run(args: argparse.Namespace) -> int:
    body = read_goal(args.goal)
    client = Client(args)
    try:
        code, answer = client.call("POST", "/api/goals", body)
    except NoApi as exc:
        return no_api(exc)
    for text in (answer.get("warnings") or []) if isinstance(answer, dict) else []:
        print(f"warning: {text}", file=sys.stderr)
    if code >= 400 or not args.wait:
        return show(code, answer)
    goal_id = answer["goal_id"]
    print(f"goal {goal_id} accepted", file=sys.stderr)
    last = None
    while True:
        try:
            code, goal = client.call("GET", f"/api/goals/{goal_id}")
        except NoApi:
            print("the run has ended (its goal API is gone)", file=sys.stderr)
            return EXIT_OK if last is not None and last.startswith("succeeded") \
                else EXIT_FAILED
        feedback = goal.get("feedback", {})
        progress = feedback.get("progress")
        line = (f"{goal.get('state')} {feedback.get('phase') or ''} "
                f"{f'{round(100 * progress)}%' if progress else ''} "
                f"photos={feedback.get('photos', 0)}")
        if line != last:
            print(line, file=sys.stderr, flush=True)
            last = line
        if goal.get("state") not in ("queued", "running"):
            print(json.dumps(goal, indent=2))
            return EXIT_OK if goal.get("state") == "succeeded" else EXIT_FAILED
        time.sleep(0.5)


COMMAND = Command("goal", "send a goal (one mission step) to a run's goal API", arguments, run,
                  description="Send a goal (one mission step, e.g. a goto, orbit or land) to "
                  "a run's goal API ('autopilot run --api' or --console). Exit codes: 0 "
                  "accepted (with --wait: succeeded), 1 it failed or was cancelled, 2 refused "
                  "(the answer says why), 4 no API answers there.")
