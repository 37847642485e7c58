"""``autopilot report``: a flight's plots as one HTML page."""

from __future__ import annotations

import argparse
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command
from autopilot.config import InputError


def arguments(report: argparse.ArgumentParser) -> None:
    report.add_argument("run_dir", metavar="DIR", help="a run's folder (holding flight.mcap)")


def run_folder_log(run_dir: str) -> Path:
    """``DIR/flight.mcap``, or an :class:`InputError` saying what DIR lacks."""
    folder = Path(run_dir)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder (give a run's folder: the --out of "
                         "'autopilot run', or one under runs/)")
    log = folder / "flight.mcap"
    if not log.is_file():
        raise InputError(f"{log}: no such file ({folder} is not a run's folder)")
    return log


def run(args: argparse.Namespace) -> int:
    from autopilot.report.html import write_report

    run_folder_log(args.run_dir)
    print(f"wrote {write_report(Path(args.run_dir))}")
    return EXIT_OK


COMMAND = Command("report", "write DIR/report.html (plots of the flight) from DIR/flight.mcap",
                  arguments, run)
