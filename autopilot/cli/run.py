"""``autopilot run``: fly a mission."""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path

from autopilot.cli.common import (
    EXIT_ABORTED,
    EXIT_FAILED,
    EXIT_OK,
    Command,
    add_config_options,
    add_fault_option,
    fmt,
)
from autopilot.config import ConfigError, InputError, Problem
from autopilot.vehicle_kinds import DRIVER_KINDS, DRIVER_NAMES

#: what a run writes into its folder (``--overwrite`` removes them first)
RUN_OUTPUTS = ("flight.mcap", "summary.json", "report.html", "onboard.mp4", "autopilot.log",
               "photos")


def arguments(run: argparse.ArgumentParser) -> None:
    run.add_argument("--mission", required=True, metavar="NAME|FILE",
                     help="a shipped mission's name (see 'autopilot missions') or a YAML file")
    run.add_argument("--out", metavar="DIR", help="where flight.mcap and summary.json go "
                     "(default: a new folder under runs/); a folder holding a flight is "
                     "refused unless --overwrite")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the flight already in --out DIR (its log, summary, report, "
                     "video and photos are removed first)")
    run.add_argument("--realtime", action="store_true",
                     help="run against the wall clock instead of lockstep (implied by --api)")
    run.add_argument("--lockstep", action="store_true",
                     help="with --api: keep the lockstep clock (simulated time then runs as "
                     "fast as the CPU allows while it waits for goals)")
    run.add_argument("--api", metavar="HOST:PORT",
                     help="serve the goal API (HTTP + WebSocket; docs at /docs) on HOST:PORT, "
                     "e.g. 127.0.0.1:8080; an address other than loopback needs a token")
    run.add_argument("--console", metavar="HOST:PORT",
                     help="serve the operator console (a page: live video with overlays, "
                     "values, map, keyboard flying, goals) and the goal API on HOST:PORT, e.g. "
                     "127.0.0.1:8090; an address other than loopback needs a token")
    run.add_argument("--api-token-file", metavar="FILE",
                     help="the goal API's bearer token (else the AUTOPILOT_API_TOKEN "
                     "environment variable); required off loopback")
    run.add_argument("--api-tls-cert", metavar="FILE",
                     help="serve the goal API and the console over HTTPS with this PEM "
                     "certificate (chain); use it on any network others share: the token then "
                     "never crosses it in clear text (with --api-tls-key)")
    run.add_argument("--api-tls-key", metavar="FILE", help="the certificate's PEM private key")
    run.add_argument("--report", action="store_true",
                     help="write DIR/report.html (plots of the flight) at the end")
    run.add_argument("--record-video", nargs="?", const="", metavar="CAMERA",
                     help="log every frame of a camera (default: the followed one) and write "
                     "DIR/onboard.mp4 with what the autopilot saw and decided drawn over it")
    run.add_argument("--driver", choices=DRIVER_NAMES,
                     help="the vehicle driver (default: the configuration's 'driver'): "
                     + "; ".join(f"{k.name}: {k.summary}" for k in DRIVER_KINDS.values()))
    run.add_argument("--connect", metavar="URL",
                     help="the vehicle's address: for MAVLink drivers udpin://HOST:PORT, "
                     "udpout://HOST:PORT, tcpout://HOST:PORT, tcpin://HOST:PORT or "
                     "serial:///dev/DEVICE[:BAUD] (default link.connect, "
                     "udpin://127.0.0.1:14540); for the AR.Drone ardrone://HOST[:PORT] "
                     "(default ardrone://192.168.1.1)")
    run.add_argument("--video", action="append", metavar="[CAMERA=]URL",
                     help="a camera's video stream for MAVLink drivers (repeatable; a bare URL "
                     "is the mission's first camera's; default vehicle.cameras.NAME.video: "
                     "front udp://127.0.0.1:5600, down udp://127.0.0.1:5601)")
    run.add_argument("--signing-key", metavar="FILE",
                     help="sign MAVLink 2 with this key and accept only signed messages "
                     "(64 hex digits, 32 raw bytes or a passphrase)")
    run.add_argument("--insecure", action="store_true",
                     help="allow an unsigned MAVLink link to another machine (without it, a "
                     "non-loopback --connect needs --signing-key)")
    run.add_argument("--verbose", action="store_true",
                     help="show every log message (MAVSDK's and FFmpeg's too) on the terminal; "
                     "they always go to DIR/autopilot.log")
    run.add_argument("--calibration", action="append", metavar="[CAMERA=]FILE",
                     help="a camera's intrinsics and distortion (OpenCV or ROS calibration "
                     "YAML, e.g. from 'autopilot calibrate'; repeatable; a bare FILE is the "
                     "mission's first camera's); default vehicle.cameras.NAME.calibration, "
                     "else the nominal pinhole (with a warning). With the simulator: what "
                     "the simulated camera reports with its frames")
    run.add_argument("--stages", action="store_true",
                     help="count where the CPU time goes, stage by stage (physics, flight "
                     "stack, rendering, camera model, codec, detection, estimation, control, "
                     "logging, metrics): shown per simulated second, and in summary.json")
    add_config_options(run)
    add_fault_option(run)


def prepare_out_dir(out: Path, given: bool, overwrite: bool,
                    outputs: tuple[str, ...] = RUN_OUTPUTS, what: str = "a flight") -> None:
    """The run's folder, made (or emptied of a previous run's ``outputs`` with ``overwrite``);
    an :class:`InputError` naming ``--out`` if it cannot be used."""
    import shutil

    option = f"--out {out}" if given else f"the run folder {out}"
    if out.exists() and not out.is_dir():
        raise InputError(f"{option}: is a file, not a folder (give a folder for the flight's "
                         "log, summary and report)")
    previous = [name for name in outputs if (out / name).exists()] if out.is_dir() else []
    if previous and not overwrite:
        raise InputError(f"{option}: already holds {what} ({', '.join(previous)}): give a "
                         "new folder" + (", or --overwrite to replace it" if what == "a flight"
                                         else ""))
    try:
        for name in previous:
            path = out / name
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".autopilot-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{option}: cannot write there ({exc.strerror or exc})") from None


def check_network_exposure(option: str, url: str, key: str | None, insecure: bool) -> None:
    """A MAVLink link to or from another machine needs a signing key (or an explicit
    --insecure): anyone on that network could otherwise fly the vehicle."""
    from autopilot.api import is_loopback
    from drivers.mavlink.link import Endpoint, UrlError

    try:
        endpoint = Endpoint.parse(url)
    except UrlError as exc:
        raise ConfigError([Problem("command line", None, option, str(exc))]) from None
    if endpoint.kind == "serial" or key or insecure or is_loopback(endpoint.host):
        return
    raise ConfigError([Problem("command line", None, option, f"{url}: a MAVLink link on a "
                               "network address needs "
                               "--signing-key FILE (MAVLink 2 signing), or --insecure to "
                               "accept unsigned traffic from that network")])


def listen_token(option: str, address: str, token_file: str | None) -> str | None:
    """A served address (the goal API's, a console's) checked before anything starts: it
    parses, can be listened on, and has a token if other machines can reach it. Its token."""
    from autopilot.api import ApiSetupError, check_listen, is_loopback, parse_address
    from autopilot.api_server import read_token

    try:
        host, port = parse_address(address)
        token = read_token(token_file)
        if not is_loopback(host) and not token:
            raise ApiSetupError(f"{option} {address} is reachable from other machines: give "
                                "a token (--api-token-file FILE, or AUTOPILOT_API_TOKEN)")
        check_listen(host, port)
    except ApiSetupError as exc:
        raise InputError(str(exc)) from None
    return token


def check_api(args: argparse.Namespace) -> str | None:
    """The goal API's and console's options checked before anything flies; the token."""
    from autopilot.api import ApiSetupError, parse_address
    from autopilot.api_server import check_tls

    if args.console:
        try:
            console = parse_address(args.console)
            same = not args.api or parse_address(args.api) == console
        except ApiSetupError as exc:
            raise InputError(str(exc).replace("--api", "--console")) from None
        if not same:
            raise InputError(f"--api {args.api} and --console {args.console}: the console is "
                             "served with the goal API, on one address (give one of them)")
        args.api = args.console
    if not args.api:
        if args.api_tls_cert or args.api_tls_key:
            raise InputError("--api-tls-cert/--api-tls-key serve the goal API or the console: "
                             "give --api HOST:PORT or --console HOST:PORT")
        return None
    token = listen_token("--console" if args.console else "--api", args.api,
                         args.api_token_file)
    try:
        if bool(args.api_tls_cert) != bool(args.api_tls_key):
            raise ApiSetupError("--api-tls-cert and --api-tls-key go together")
        if args.api_tls_cert:
            check_tls(args.api_tls_cert, args.api_tls_key)
    except ApiSetupError as exc:
        raise InputError(str(exc)) from None
    return token


def run(args: argparse.Namespace) -> int:
    from autopilot.logs import setup_logging
    from autopilot.mission import load_mission
    from autopilot.run import default_out_dir, fly
    from autopilot.steps import step_kind

    overrides = [*args.overrides, *([f"driver={args.driver}"] if args.driver else [])]
    plan = load_mission(args.mission, overrides, args.config)
    waits = [(i, step.name) for i, step in enumerate(plan.steps)
             if (kind := step_kind(step.name)).waits_for_goals and kind.endless(step.params)]
    token = check_api(args)
    if waits and not args.api:
        index, name = waits[0]
        raise InputError(f"{plan.source}: step {index} ({name}) waits for goals from the "
                         "goal API: run with --api HOST:PORT (e.g. --api 127.0.0.1:8080), or "
                         f"give the {name} step an end of its own (its timeout_s)")
    if args.faults and plan.config.driver != "sim":
        raise InputError(f"--fault acts on the simulated vehicle, not on a vehicle flown through "
                         f"--driver {plan.config.driver}: give it to 'autopilot sim --fault ...' "
                         "(the MAVLink vehicle it simulates), or fly --driver sim")
    kind = DRIVER_KINDS[plan.config.driver]
    if kind.check_connect is not None:
        kind.check_connect("--connect", args.connect or kind.default_connect(plan.config),
                           args.signing_key or plan.config.link.signing_key, args.insecure)
    if plan.config.driver == "sim" and args.calibration:
        from autopilot.run import with_calibrations

        with_calibrations(plan, args.calibration)  # (checked before the run's folder is made)
    out = Path(args.out) if args.out else default_out_dir(plan)
    prepare_out_dir(out, bool(args.out), args.overwrite)
    setup_logging(out, verbose=args.verbose)

    def progress(line: str) -> None:
        if sys.stderr.isatty():
            sys.stderr.write("\r" + " " * 100 + "\r")
        print(line, file=sys.stderr, flush=True)

    print(f"mission {plan.mission.name} ({plan.source}); log in {out}", file=sys.stderr)
    realtime = args.realtime or (bool(args.api) and not args.lockstep)
    summary = asyncio.run(fly(plan, out, realtime=realtime, progress=progress,
                              handle_signals=True, connect=args.connect, video=args.video,
                              calibration=args.calibration,
                              record_video=args.record_video,
                              signing_key=Path(args.signing_key) if args.signing_key else None,
                              api=args.api, api_token=token, console=bool(args.console),
                              api_tls=(args.api_tls_cert, args.api_tls_key)
                              if args.api_tls_cert else None, stages=args.stages))
    if sys.stderr.isatty():
        sys.stderr.write("\n")
    lines = summary_lines(summary, out)
    if args.record_video is not None:
        from autopilot.report.video import VideoError, write_video

        try:
            path, frames = write_video(out, args.record_video or None)
            lines.append(f"wrote {path} ({frames} frames)")
        except VideoError as exc:
            lines.append(f"no video: {exc}")
    if args.report:
        from autopilot.report.html import write_report

        lines.append(f"wrote {write_report(out)}")
    print("\n".join(lines))
    return exit_code(summary)


def exit_code(summary: dict) -> int:
    """0 for a completed mission; 130 only when Ctrl-C or SIGTERM stopped it; 1 otherwise (a
    failed step, a failsafe, an abort from the console or the goal API)."""
    if summary["status"] == "completed":
        return EXIT_OK
    return EXIT_ABORTED if summary.get("signal") else EXIT_FAILED


def summary_lines(summary: dict, out: Path) -> list[str]:
    """What the terminal shows of a flight: its status, and each step's main figures (the
    step kinds say which, :attr:`StepKind.summary_lines`)."""
    from autopilot.steps.registry import summary_lines as step_lines

    metrics = summary["metrics"]
    rtf = metrics["sim"].get("real_time_factor")
    if not summary.get("flown", True):
        timing = f"nothing flown (stopped after {summary['wall_time_s']:.1f} s)"
    elif rtf:
        timing = f"simulated {summary['sim_time_s']:.1f} s in {summary['wall_time_s']:.1f} s " \
                 f"(× {rtf:.1f})"
    else:
        timing = f"flew for {summary['wall_time_s']:.1f} s"
    profile = (summary.get("sim") or {}).get("profile")
    steal = metrics["sim"].get("cpu_steal_pct")
    lines = [f"status: {summary['status']}" + (f" ({summary['reason']})" if summary["reason"]
                                                else ""),
             timing + (f", {profile} world" if profile else "")
             + ("" if steal is None else f"; hypervisor steal {steal:.1f} % of CPU time")]
    lines += step_lines(metrics)
    if summary.get("photos") and summary["photos"].get("taken"):
        lines.append(f"photos: {summary['photos']['taken']} in {out / 'photos'} "
                     "(JPEG + EXIF GPS, photos.geojson)")
    if summary.get("stages", {}).get("ms_per_sim_s"):
        ranked = sorted(summary["stages"]["ms_per_sim_s"].items(), key=lambda kv: -kv[1])
        lines.append("CPU per simulated second: " + ", ".join(f"{name} {ms:.0f} ms"
                                                                 for name, ms in ranked))
    lat = metrics["latency_ms"]
    if lat.get("samples"):
        lines.append(f"latency (frame capture to setpoint): p50 {lat['p50']:.1f} ms, "
                     f"p95 {lat['p95']:.1f} ms")
    reckoned = summary.get("dead_reckoning")
    if reckoned:
        lines.append(f"position dead-reckoned over {reckoned['path_m']:.1f} m: it may be off by "
                     f"{reckoned['drift_m']:.2f} m by the end (no GNSS)")
    lines.append(f"wrote {out / 'summary.json'} and {out / 'flight.mcap'}")
    return lines


COMMAND = Command("run", "fly a mission (in the simulator unless configured otherwise)",
                  arguments, run, flight=True,
                  description="Fly a mission, in the simulator unless configured otherwise. "
                  "Exit codes: 0 completed, 1 failed or aborted (by a failsafe, the console or "
                  "the goal API), 2 invalid input, 3 no vehicle, 4 link cannot be opened, 5 no "
                  "video, 6 cannot render, 130 Ctrl-C or SIGTERM.")

__all__ = ["COMMAND", "exit_code", "fmt", "prepare_out_dir", "summary_lines"]
