"""``autopilot validate``: check a mission or configuration file without flying."""

from __future__ import annotations

import argparse

from autopilot.cli.common import EXIT_OK, Command, add_set_option
from autopilot.config import load_config


def arguments(validate: argparse.ArgumentParser) -> None:
    validate.add_argument("file", metavar="NAME|FILE",
                          help="a mission (a shipped mission's name or a YAML file) or a "
                          "configuration file")
    add_set_option(validate, "check with this key overridden, as 'run --set' would fly it "
                   "(repeatable)")


def run(args: argparse.Namespace) -> int:
    from autopilot.mission import find_mission, is_mission_file, load_mission

    if is_mission_file(find_mission(args.file)):
        plan = load_mission(args.file, args.overrides)
        print(f"{args.file}: ok (mission {plan.mission.name}, {len(plan.steps)} steps, from "
              f"{plan.source})")
        for text in plan.warnings:
            print(f"warning: {text}")
    else:
        load_config(args.file, args.overrides)
        print(f"{args.file}: ok (configuration)")
    return EXIT_OK


COMMAND = Command("validate", "check a mission or configuration file", arguments, run,
                  description="Check a mission (a shipped mission's name or a YAML file) or a "
                  "configuration file as 'run' would, without flying: every problem at once, "
                  "each naming its file, line and key. Exit code 2 if any.")
