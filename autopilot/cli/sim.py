"""``autopilot sim``: the simulator in real time as a MAVLink vehicle (like PX4 SITL)."""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path

from autopilot.cli.common import EXIT_OK, Command, add_config_options, add_fault_option
from autopilot.cli.run import check_network_exposure, listen_token, prepare_out_dir
from autopilot.config import ConfigError, InputError, Problem, load_config
from drivers.sim.config import FIRMWARE_NAMES


def arguments(sim: argparse.ArgumentParser) -> None:
    sim.add_argument("--mission", metavar="NAME|FILE",
                     help="put this mission's scenario (e.g. the moving ball) in the world")
    sim.add_argument("--firmware", choices=FIRMWARE_NAMES, default=None,
                     help="the vehicle it is: px4 (default: a PX4 SITL vehicle over MAVLink), "
                     "ardupilot (ArduCopter SITL as a ground station finds it: MAVLink on tcp "
                     "5760, 5762, 5763 and udp out to 14550) or ardrone (a Parrot AR.Drone "
                     "2.0 over its SDK protocol: AT commands udp 5556, navdata udp 5554, "
                     "video tcp 5555, configuration tcp 5559); as --set sim.firmware=…")
    sim.add_argument("--instance", type=int, default=0, metavar="N",
                     help="instance number: PX4 SITL's ports 14580+N, 18570+N; ArduCopter's "
                     "and an AR.Drone's moved by 10×N, as sim_vehicle.py -I N (default 0)")
    sim.add_argument("--video", action="append", metavar="[CAMERA=]URL",
                     help="where a camera streams (RTP H.264; repeatable; default: every "
                     "camera to the address its vehicle.cameras.NAME.video names — front "
                     "udp://127.0.0.1:5600, down udp://127.0.0.1:5601); a bare URL is the "
                     "front camera's, and only the cameras given stream")
    sim.add_argument("--no-video", action="store_true", help="do not stream any camera")
    sim.add_argument("--console", metavar="HOST:PORT",
                     help="serve a console that watches the simulated vehicle (its cameras, "
                     "telemetry, track and messages) on HOST:PORT, e.g. 127.0.0.1:8091; an "
                     "address other than loopback needs a token")
    sim.add_argument("--api-token-file", metavar="FILE",
                     help="the console's bearer token (else AUTOPILOT_API_TOKEN); required "
                     "off loopback")
    sim.add_argument("--out", metavar="DIR", help="record ground truth into DIR/truth.mcap "
                     "(for 'autopilot score') and photos into DIR/photos/")
    sim.add_argument("--bind", default="127.0.0.1", metavar="HOST",
                     help="address the MAVLink ports listen on (default 127.0.0.1; another "
                     "needs --signing-key or --insecure)")
    sim.add_argument("--signing-key", metavar="FILE",
                     help="MAVLink 2 signing: sign everything sent, drop unsigned messages")
    sim.add_argument("--insecure", action="store_true",
                     help="allow --bind on a network address without --signing-key")
    add_config_options(sim)
    add_fault_option(sim)


def run(args: argparse.Namespace) -> int:
    if args.firmware is not None:
        args.overrides = [*(args.overrides or []), f"sim.firmware={args.firmware}"]
    if args.mission:
        from autopilot.mission import load_mission

        plan = load_mission(args.mission, args.overrides, args.config)
        config, scenario = plan.config, plan.mission.scenario
    else:
        config, scenario = load_config(args.config, args.overrides), None
    if not 0 <= args.instance <= 999:
        raise InputError(f"--instance {args.instance}: between 0 and 999 (ports 14580+N)")
    signing = None
    if args.signing_key:
        from drivers.mavlink.signing import Signing, SigningKeyError

        try:
            signing = Signing.load(args.signing_key)
        except SigningKeyError as exc:
            raise ConfigError([Problem("command line", None, "--signing-key",
                                       str(exc))]) from None
    check_network_exposure("--bind", f"udpin://{args.bind}:14580", args.signing_key,
                           args.insecure)
    title = plan.mission.name if args.mission else "empty world"
    return FACES[config.sim.firmware](args, config, scenario, signing, title)


def _serve_px4(args: argparse.Namespace, config, scenario, signing, title: str) -> int:
    """PX4 SITL's face: MAVLink on its ports, RTP video, the console."""
    from drivers.mavlink.face import MavlinkFace

    return _serve_mavlink(args, config, scenario, signing, title, MavlinkFace)


def _serve_ardupilot(args: argparse.Namespace, config, scenario, signing, title: str) -> int:
    """ArduCopter SITL's face: MAVLink on TCP 5760/5762/5763 and UDP out to 14550, RTP video,
    the console."""
    from drivers.mavlink.face_ardupilot import ArduPilotFace

    return _serve_mavlink(args, config, scenario, signing, title, ArduPilotFace)


def _serve_mavlink(args: argparse.Namespace, config, scenario, signing, title: str,
                   face_class: type) -> int:
    from autopilot.sim_server import serve

    if args.out:
        prepare_out_dir(Path(args.out), True, False, ("truth.mcap", "photos"), "a recording")
    from autopilot.logs import route_library_logs

    route_library_logs()
    from autopilot.cameras import parse_camera_options
    from autopilot.sim_server import FROM_CONFIG

    videos = None if args.no_video else (
        parse_camera_options(args.video, "--video", "front") if args.video else FROM_CONFIG)
    token = listen_token("--console", args.console, args.api_token_file) if args.console \
        else None
    asyncio.run(serve(config, scenario, instance=args.instance, videos=videos,
                      out_dir=Path(args.out) if args.out else None,
                      log=lambda line: print(line, file=sys.stderr, flush=True),
                      host=args.bind, signing=signing, console=args.console,
                      console_token=token, title=title, face_class=face_class))
    return EXIT_OK


def _serve_ardrone(args: argparse.Namespace, config, scenario, signing, title: str) -> int:
    """The AR.Drone 2.0's: its SDK protocol's four ports."""
    from autopilot.ardrone_server import ArdronePorts, serve
    from autopilot.logs import route_library_logs

    for option, given in (("--signing-key", args.signing_key), ("--console", args.console),
                          ("--video", args.video)):
        if given:
            raise InputError(f"{option}: not available with --firmware ardrone (the AR.Drone "
                             "protocol has no signing; its one video stream is TCP 5555)")
    route_library_logs()
    asyncio.run(serve(config, scenario, host=args.bind,
                      ports=ArdronePorts().offset(10 * args.instance),
                      log=lambda line: print(line, file=sys.stderr, flush=True),
                      video=not args.no_video, out_dir=Path(args.out) if args.out else None))
    return EXIT_OK


#: ``autopilot sim``'s server for each firmware (``sim.firmware``)
FACES = {"px4": _serve_px4, "ardupilot": _serve_ardupilot, "ardrone": _serve_ardrone}


COMMAND = Command("sim", "run the simulator in real time as a MAVLink vehicle (like PX4 SITL)",
                  arguments, run, flight=True,
                  description="Run the simulator in real time as a MAVLink vehicle, as PX4 "
                  "SITL does: MAVSDK, MAVProxy, QGroundControl and 'autopilot run --driver "
                  "mavsdk|pymavlink' connect to it on udp 14540 (offboard API) and 14550 "
                  "(ground station), cameras stream RTP H.264. Ctrl-C stops it.")
