"""``autopilot missions``: the shipped missions."""

from __future__ import annotations

import argparse

from autopilot.cli.common import EXIT_OK, Command
from autopilot.config import ConfigError


def arguments(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    from autopilot.mission import load_mission, shipped_missions

    for path in shipped_missions():
        try:
            plan = load_mission(str(path))
            print(f"{path.stem:<20} {plan.mission.description}")
        except ConfigError as exc:
            print(f"{path.stem:<20} INVALID: {exc.problems[0]}")
    return EXIT_OK


COMMAND = Command("missions", "list the shipped missions", arguments, run,
                  description="List the shipped missions, each with what it does: give a "
                  "name to 'autopilot run --mission NAME' (or copy its file from the "
                  "missions/ folder and change it).")
