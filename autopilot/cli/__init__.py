"""The ``autopilot`` command. Each command is a module of this package exporting ``COMMAND``
(a :class:`~autopilot.cli.common.Command`: its arguments and what runs it), listed once in
:data:`COMMANDS`; the benches are modules of :mod:`autopilot.cli.benches`, found there."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from autopilot import __version__
from autopilot.cli.common import (
    EXIT_ABORTED,
    EXIT_FAILED,
    EXIT_LINK,
    EXIT_NO_VEHICLE,
    EXIT_NO_VIDEO,
    EXIT_OK,
    EXIT_RENDERING,
    EXIT_USAGE,
)
from autopilot.config import ConfigError, InputError
from autopilot.suggest import did_you_mean

__all__ = ["COMMANDS", "EXIT_ABORTED", "EXIT_FAILED", "EXIT_LINK", "EXIT_NO_VEHICLE",
           "EXIT_NO_VIDEO", "EXIT_OK", "EXIT_RENDERING", "EXIT_USAGE", "build_parser", "main"]

#: the commands, in the order ``autopilot --help`` lists them (module names in this package)
COMMANDS = ("run", "sim", "doctor", "report", "replay", "video", "score", "calibrate",
            "missions", "validate", "trials", "bench", "goal", "status", "cancel", "abort")


class Parser(argparse.ArgumentParser):
    """argparse with "did you mean" for a mistyped command, bench or choice."""

    def error(self, message: str):
        import re

        match = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if match:
            choices = re.findall(r"'([^']*)'", match.group(2))
            message += did_you_mean(match.group(1), choices)
        super().error(message)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="autopilot", description="Camera-guided quadrotor missions for PX4 / "
                    "MAVLink vehicles, with a built-in MuJoCo simulator.",
                    epilog="'autopilot COMMAND --help' says more about each command.")
    parser.add_argument("--version", action="version", version=f"autopilot {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     parser_class=Parser)
    for name in COMMANDS:
        importlib.import_module(f"autopilot.cli.{name}").COMMAND.attach(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version (0) and argument errors (2)
        return int(exc.code or 0)
    if args.flight:
        from autopilot.process import configure_for_flight

        configure_for_flight()
    try:
        if getattr(args, "faults", None):
            from drivers.sim.faults import FaultError, fault_override

            try:
                args.overrides = [*args.overrides, fault_override(args.faults)]
            except FaultError as exc:
                raise InputError(str(exc)) from None
        return args.handler(args)
    except ConfigError as exc:
        print(f"error: invalid configuration:\n{exc}", file=sys.stderr)
        return EXIT_USAGE
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_ABORTED
    except Exception as exc:
        code = failure_exit_code(exc)
        if code is None:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return code


def failure_exit_code(exc: BaseException) -> int | None:
    """The exit code for a failure that is the world's, not a bug: one line, no traceback."""
    from drivers.base import CameraUnavailable, ConnectionLost, VehicleNotFound

    if isinstance(exc, VehicleNotFound):
        exc.args = (f"{exc}: is the vehicle on and sending there? (PX4 SITL and 'autopilot "
                    "sim' send to udp 14540; a flight controller on a serial port: --connect "
                    "serial:///dev/ttyAMA0:921600; a vehicle elsewhere: --connect "
                    "udpin://0.0.0.0:14540 --signing-key FILE)",)
        return EXIT_NO_VEHICLE
    if isinstance(exc, CameraUnavailable):
        return EXIT_RENDERING if exc.cause == "rendering" else EXIT_NO_VIDEO
    if isinstance(exc, ConnectionLost):  # lost before the flight could start
        return EXIT_NO_VEHICLE
    if isinstance(exc, ConnectionError | OSError) and _is_link_error(exc):
        return EXIT_LINK
    if isinstance(exc, RuntimeError) and "MUJOCO_GL" in str(exc):
        # MuJoCo refuses the backend as it loads: say what to do instead
        exc.args = (f"{exc}; use MUJOCO_GL=egl (headless, Mesa's EGL), MUJOCO_GL=osmesa, or "
                    "unset it",)
        return EXIT_RENDERING
    return None


def _is_link_error(exc: BaseException) -> bool:
    from drivers.mavlink.link import LinkError

    return isinstance(exc, LinkError) or "cannot bind" in str(exc)
