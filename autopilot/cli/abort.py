"""``autopilot abort``: abort a run's mission: hold, land, disarm."""

from __future__ import annotations

import argparse

from autopilot.cli.client import Client, NoApi, add_api_options, no_api, show
from autopilot.cli.common import Command


def arguments(abort: argparse.ArgumentParser) -> None:
    add_api_options(abort)


def run(args: argparse.Namespace) -> int:
    try:
        return show(*Client(args).call("POST", "/api/abort"))
    except NoApi as exc:
        return no_api(exc)


COMMAND = Command("abort", "abort the mission: hold, land, disarm", arguments, run,
                  description="Abort a run's mission through its goal API: hold, land, "
                  "disarm. The run then ends with exit code 1.")
