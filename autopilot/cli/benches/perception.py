"""``autopilot bench perception``."""

from __future__ import annotations

import argparse
import json

from autopilot.cli.common import (
    EXIT_OK,
    Command,
    add_config_options,
    add_json_option,
    check_choices,
    progress_for,
)
from autopilot.config import load_config


def arguments(perception: argparse.ArgumentParser) -> None:
    add_json_option(perception)
    perception.add_argument("--quick", action="store_true",
                            help="a few frames per cell (what the test suite runs)")
    perception.add_argument("--detector", dest="detectors", action="append", default=None,
                            metavar="NAME",
                            help="only this detector (repeatable: ball, marker, image, pad)")
    add_config_options(perception)


def run(args: argparse.Namespace) -> int:
    from autopilot.bench import perception as perception_bench

    check_choices("--detector", args.detectors, perception_bench.BENCHES, "no such detector")
    config = load_config(args.config, args.overrides)
    result = perception_bench.run_bench(progress_for(args), quick=args.quick,
                                        detectors=args.detectors, config=config)
    print(json.dumps(result) if args.json else perception_bench.format_table(result))
    return EXIT_OK


BENCHES = (Command(
    "perception", "each detector on frames rendered from known poses, against truth: ball "
    "(centre, range) and marker at 1, 3, 5 m and 0-60 degrees obliquity (position, "
    "orientation, detection rate, time per frame); down camera: image and pad at 1, 3, 8 m, "
    "ours against seed 000's and seed 001's detectors", arguments, run),)
