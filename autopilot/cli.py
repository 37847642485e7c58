"""The ``autopilot`` command."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from collections.abc import Sequence

from autopilot import __version__
from autopilot.config import ConfigError, InputError, load_config
from autopilot.process import configure_for_flight

EXIT_OK = 0
EXIT_FAILED = 1  # the mission failed (the summary says why)
EXIT_USAGE = 2  # invalid input: configuration, mission, URL, key file
EXIT_NO_VEHICLE = 3  # no vehicle answered within the timeout
EXIT_LINK = 4  # the link cannot be opened: port in use, no such device, connection refused
EXIT_NO_VIDEO = 5  # the camera delivered no frame
EXIT_RENDERING = 6  # the simulator cannot render (MUJOCO_GL, OpenGL libraries)
EXIT_ABORTED = 130


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE",
                        help="configuration file (default: the project's config.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a configuration key "
                        "(dotted path, e.g. sim.wind.gust_mps=2); repeatable")


def _add_fault_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--fault", dest="faults", action="append", default=[], metavar="KIND[:KEY=VALUE,...]",
        help="inject a fault in the simulated vehicle (replaces the mission's scenario.faults; "
        "repeatable), e.g. camera_dropout:start_s=12,duration_s=3 or link_loss:fraction=0.3; "
        "kinds and parameters: drivers/sim/faults.py and the README")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="autopilot", description="Camera-guided quadrotor missions for PX4 / MAVLink "
        "vehicles, with a built-in MuJoCo simulator.")
    parser.add_argument("--version", action="version", version=f"autopilot {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="fly a mission (in the simulator unless configured "
                              "otherwise)")
    run.add_argument("--mission", required=True, metavar="NAME|FILE",
                     help="a shipped mission's name (see 'autopilot missions') or a YAML file")
    run.add_argument("--out", metavar="DIR", help="where flight.mcap and summary.json go "
                     "(default: a new folder under runs/)")
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
    run.add_argument("--driver", choices=("sim", "mavsdk", "pymavlink"),
                     help="the vehicle driver (default: the configuration's 'driver')")
    run.add_argument("--connect", metavar="URL",
                     help="MAVLink connection for MAVLink drivers: udpin://HOST:PORT, "
                     "udpout://HOST:PORT, tcpout://HOST:PORT, tcpin://HOST:PORT or "
                     "serial:///dev/DEVICE[:BAUD] (default link.connect, "
                     "udpin://127.0.0.1:14540)")
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
                     "else the nominal pinhole (with a warning)")
    _add_config_options(run)
    _add_fault_option(run)

    sim = commands.add_parser(
        "sim", help="run the simulator in real time as a MAVLink vehicle (like PX4 SITL)")
    sim.add_argument("--mission", metavar="NAME|FILE",
                     help="put this mission's scenario (e.g. the moving ball) in the world")
    sim.add_argument("--instance", type=int, default=0, metavar="N",
                     help="PX4 SITL instance number: ports 14580+N, 18570+N (default 0)")
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

    doctor = commands.add_parser(
        "doctor", help="preflight check of a companion computer: MAVLink link (heartbeat, "
        "rates, time sync), cameras (frames, rate, calibration), clock, disk")
    doctor.add_argument("--mission", default="follow_ball", metavar="NAME|FILE",
                        help="the mission whose cameras and settings to check (default "
                        "follow_ball)")
    doctor.add_argument("--driver", choices=("mavsdk", "pymavlink"),
                        help="the MAVLink driver (default: the configuration's, else pymavlink)")
    doctor.add_argument("--connect", metavar="URL", help="MAVLink connection (as for run)")
    doctor.add_argument("--video", action="append", metavar="[CAMERA=]URL",
                        help="a camera's stream (as for run)")
    doctor.add_argument("--calibration", action="append", metavar="[CAMERA=]FILE",
                        help="a camera's intrinsics (as for run)")
    doctor.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key")
    doctor.add_argument("--duration-s", type=float, default=5.0, metavar="S",
                        help="how long to measure rates (default 5)")
    doctor.add_argument("--json", action="store_true", help="print one JSON object")
    doctor.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a mission or configuration key")

    report = commands.add_parser(
        "report", help="write DIR/report.html (plots of the flight) from DIR/flight.mcap")
    report.add_argument("run_dir", metavar="DIR")

    replay = commands.add_parser(
        "replay", help="re-run detection and estimation over a logged flight's frames and "
        "telemetry (optionally with changed settings) and report their metrics")
    replay.add_argument("run_dir", metavar="DIR")
    replay.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="change a setting of the flight's "
                        "configuration (e.g. perception.ball.min_circularity=0.7, "
                        "estimation.target.accel_noise_m_s2=2); repeatable")
    replay.add_argument("--json", action="store_true",
                        help="print one JSON object on stdout (shaped like summary.json)")

    video = commands.add_parser(
        "video", help="write DIR/onboard.mp4: a camera's logged frames with overlays")
    video.add_argument("run_dir", metavar="DIR")
    video.add_argument("--camera", metavar="NAME",
                       help="whose frames (default: the followed camera)")

    scorer = commands.add_parser(
        "score", help="score a run flown through a MAVLink driver against the ground truth "
        "'autopilot sim --out' recorded")
    scorer.add_argument("run_dir", metavar="RUN_DIR")
    scorer.add_argument("--truth", required=True, metavar="FILE",
                        help="the simulator's truth.mcap")
    _add_config_options(sim)
    _add_fault_option(sim)

    calibrate = commands.add_parser(
        "calibrate", help="estimate a camera's intrinsics and lens distortion from views of a "
        "chessboard or ChArUco board; writes OpenCV and ROS calibration YAML",
        description="Find the board in every frame, keep sharp, varied views (no "
        "near-duplicates), calibrate (dropping views that do not fit the others), report "
        "the reprojection error and how much of the image and of the tilts the views "
        "covered, and write the calibration.")
    calibrate.add_argument(
        "source", metavar="SOURCE", help="an image folder, a video file, or a live video: "
        "udp://HOST:PORT (RTP H.264, as PX4 cameras and 'autopilot sim' send it), or "
        "anything else OpenCV opens (rtsp://..., /dev/video0, a device number)")
    calibrate.add_argument(
        "--board", required=True, metavar="SPEC",
        help="chessboard:COLSxROWS:SQUARE_M or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT. "
        "COLS and ROWS count squares, not inner corners (for both: a chessboard with 9x6 "
        "inner corners is 10x7); sizes in metres; DICT is OpenCV's (DICT_5X5_100, ...). "
        "E.g. chessboard:10x7:0.025, charuco:11x8:0.03:0.022:DICT_5X5_100")
    calibrate.add_argument(
        "--out", required=True, metavar="FILE",
        help="the OpenCV calibration YAML to write (what --calibration and "
        "vehicle.cameras.NAME.calibration take); ROS's camera_info YAML is written next to "
        "it as NAME_ros.yaml (cam.yaml: cam_ros.yaml) unless --ros-out says otherwise")
    calibrate.add_argument("--ros-out", metavar="FILE",
                           help="where the ROS camera_info YAML goes instead")
    calibrate.add_argument("--camera-name", default="camera", metavar="NAME",
                           help="camera_name in the ROS file (default camera)")
    calibrate.add_argument(
        "--frames", type=int, metavar="N",
        help="read at most N frames (a live source: default 900, then it stops)")
    calibrate.add_argument(
        "--duration-s", type=float, metavar="S",
        help="read for at most S seconds (a live source: default 60; Ctrl-C stops early and "
        "calibrates with what was seen)")
    calibrate.add_argument("--every", type=int, default=1, metavar="N",
                           help="use every N-th frame or image only (default 1: all)")
    calibrate.add_argument("--max-views", type=int, default=40, metavar="N",
                           help="calibrate with at most N views, the most varied (default 40)")
    calibrate.add_argument("--min-views", type=int, default=10, metavar="N",
                           help="fail with fewer usable views than N (default 10)")
    calibrate.add_argument("--fix-k3", action="store_true",
                           help="fit k1 k2 p1 p2 only (k3 = 0: narrow lenses, few views)")
    calibrate.add_argument("--rational", action="store_true",
                           help="OpenCV's rational model, 8 coefficients (wide-angle lenses)")
    calibrate.add_argument("--json", action="store_true",
                           help="print one JSON object on stdout (progress still on stderr)")

    commands.add_parser("missions", help="list the shipped missions")

    trials = commands.add_parser(
        "trials", help="many seeded lockstep runs of a mission in parallel: each metric's "
        "median, p95 and worst seed, and the failing seeds to replay")
    trials.add_argument("mission", metavar="NAME|FILE")
    trials.add_argument("--trials", type=int, default=10, metavar="N",
                        help="runs (seeds SEED_START .. SEED_START+N-1; default 10)")
    trials.add_argument("--seed-start", type=int, default=0, metavar="S",
                        help="the first scenario seed (default 0)")
    trials.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a mission or configuration key "
                        "(every run)")
    _add_fault_option(trials)
    trials.add_argument("--vary", dest="varies", action="append", default=[],
                        metavar="KEY=LOW:HIGH|KEY=A,B,C",
                        help="draw a key's value per seed: uniformly in [LOW, HIGH], or one "
                        "of the values (repeatable)")
    trials.add_argument("--success", dest="criteria", action="append", default=None,
                        metavar="KEY[OP NUMBER]",
                        help="what a successful run shows, e.g. landing.on_deck or "
                        "'landing.error_m<=0.1' (repeatable; default: completed, and on the "
                        "deck or pad for a landing)")
    trials.add_argument("--workers", type=int, default=None, metavar="N",
                        help="parallel runs (default: one per core)")
    trials.add_argument("--cluster", metavar="ADDRESS",
                        help="run each trial as a task on this Ray cluster ('local': start "
                        "a Ray instance here; needs pip install 'autopilot[cluster]')")
    trials.add_argument("--out", metavar="DIR",
                        help="keep each run's flight log and summary in DIR/seed<N>")
    trials.add_argument("--json", action="store_true", help="print one JSON object on stdout")

    bench = commands.add_parser("bench", help="run a benchmark")
    benches = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    sitl = benches.add_parser(
        "sitl", help="simulator speed and flight-stack accuracy: takeoff, 2 m step, hover, land")
    sitl.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    sitl.add_argument("--realtime", action="store_true",
                      help="run against the wall clock instead of lockstep")
    _add_config_options(sitl)
    for name, baselines in (("follow_ball", "the seed 001 and 003 rules"),
                            ("follow_marker", "the seed 002 rule")):
        follow = benches.add_parser(
            name, help=f"{name}: default, hard (figure eight in gusts) and stress (random walk "
            f"at 2.5 m/s, 3 m/s gusts) scenarios, our controller against {baselines}")
        follow.add_argument("--json", action="store_true",
                            help="print one JSON object on stdout")
        follow.add_argument("--mission", default=name, metavar="NAME|FILE")
        follow.add_argument("--scenario", dest="scenarios", action="append", default=None,
                            metavar="NAME", help="only this scenario (repeatable)")
        follow.add_argument("--quick", action="store_true",
                            help="one seed of the default scenario, the step shortened to 10 s "
                            "(CI)")
        follow.add_argument("--seeds", type=int, default=3, metavar="N",
                            help="scenario seeds per scenario and controller (default 3)")
        follow.add_argument("--seed-start", type=int, default=1, metavar="S",
                            help="the first scenario seed (default 1)")
        follow.add_argument("--row", dest="rows", action="append", default=None,
                            metavar="NAME", help="only this controller (ours or a seed rule; "
                            "repeatable)")
        follow.add_argument("--set", dest="overrides", action="append", default=[],
                            metavar="KEY=VALUE", help="override a mission or configuration key")

    for name, seed in (("hover_image", "seed 000's ORB 300 + FLANN + solvePnPRansac, flown "
                                       "with our controller"),
                       ("land_pad", "seed 001's multi-scale TM_CCOEFF template matching, "
                                    "flown with our lander and with seed 001's own")):
        down = benches.add_parser(
            name, help=f"{name}: default and hard (gusts, target offset and turned"
            f"{', decoys' if name == 'land_pad' else ''}) scenarios over a few seeds, ours "
            f"against {seed}; a run without its figure counts as a failure")
        down.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        down.add_argument("--seeds", type=int, default=3, metavar="N",
                          help="scenario seeds per scenario and detector (default 3)")
        down.add_argument("--scenario", dest="scenarios", action="append", default=None,
                          metavar="NAME", help="only this scenario (repeatable)")
        down.add_argument("--quick", action="store_true",
                          help="one seed of a shortened default scenario (what CI flies)")
        down.add_argument("--row", dest="rows", action="append", default=None, metavar="NAME",
                          help="only this row (ours or a baseline; repeatable)")
        down.add_argument("--seed-start", type=int, default=1, metavar="S",
                          help="the first scenario seed (default 1)")
        down.add_argument("--set", dest="overrides", action="append", default=[],
                          metavar="KEY=VALUE", help="override a mission or configuration key")

    offboard = benches.add_parser(
        "offboard", help="orbit and survey (seed 004): our trajectory tracking against seed "
        "004's PID, over the shipped, concave and gusty scenarios: cross-track error, "
        "coverage, photos, real-time factor (about 8 min)")
    offboard.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    offboard.add_argument("--seeds", type=int, default=2, metavar="N",
                          help="seeds per scenario and tracker (default 2)")
    offboard.add_argument("--scenario", dest="scenarios", action="append", default=None,
                          metavar="NAME", help="only this scenario (repeatable)")
    offboard.add_argument("--set", dest="overrides", action="append", default=[],
                          metavar="KEY=VALUE", help="override a mission or configuration key")

    landing = benches.add_parser(
        "landing", help="land_on_rover over many seeds: ours against seed 004's (its fused "
        "filter and gain-scheduled PID) and ours without the tag, in the same trials: success "
        "rate, median and p95 touchdown error (--rover-speed 0: a static rover)")
    landing.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    landing.add_argument("--trials", type=int, default=20, metavar="N",
                         help="seeds per strategy (default 20)")
    landing.add_argument("--rover-speed", type=float, default=1.5, metavar="M_S",
                         help="the rover's speed (default 1.5 m/s)")
    landing.add_argument("--strategy", dest="strategies", action="append", default=None,
                         choices=("ours", "seed004", "ours_uwb_only"),
                         help="only this strategy (repeatable)")
    landing.add_argument("--workers", type=int, default=None, metavar="N",
                         help="parallel runs (default: one per core)")
    landing.add_argument("--cluster", metavar="ADDRESS",
                         help="run the trials on this Ray cluster ('local': start one here)")
    landing.add_argument("--set", dest="overrides", action="append", default=[],
                         metavar="KEY=VALUE", help="override a mission or configuration key")

    faults_bench = benches.add_parser(
        "faults", help="every shipped mission × every fault that applies (camera, telemetry, "
        "link, EKF, GPS, rangefinder, motor, battery, wind, rover, decoy), several seeds each: "
        "completed / ended safe / unsafe counts per cell and the worst seeds to replay (about "
        "an hour for the full matrix at 2 seeds on 2 cores; --mission/--kind narrow it)")
    faults_bench.add_argument("--json", action="store_true",
                              help="print one JSON object on stdout")
    faults_bench.add_argument("--seeds", type=int, default=2, metavar="N",
                              help="seeds per cell (default 2)")
    faults_bench.add_argument("--seed-start", type=int, default=0, metavar="S")
    faults_bench.add_argument("--mission", dest="missions", action="append", default=None,
                              metavar="NAME", help="only this mission (repeatable)")
    faults_bench.add_argument("--kind", dest="kinds", action="append", default=None,
                              metavar="KIND", help="only this fault kind or case, e.g. "
                              "gps_loss or battery_sag/critical (repeatable)")
    faults_bench.add_argument("--workers", type=int, default=None, metavar="N",
                              help="parallel runs (default: one per core)")
    faults_bench.add_argument("--set", dest="overrides", action="append", default=[],
                              metavar="KEY=VALUE", help="override a mission or configuration key")

    soak_bench = benches.add_parser(
        "soak", help="an hour of simulated flight (lockstep), the shipped missions back to back "
        "in one process: memory, tasks, threads, file descriptors and event-loop lag sampled; "
        "fails on growth over 5 %% or any leak (about 25 min on 2 cores)")
    soak_bench.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    soak_bench.add_argument("--duration-s", type=float, default=3600.0, metavar="S",
                            help="simulated seconds of flight (default 3600)")
    soak_bench.add_argument("--mission", dest="missions", action="append", default=None,
                            metavar="NAME", help="fly only these missions, in turn (repeatable)")
    soak_bench.add_argument("--set", dest="overrides", action="append", default=[],
                            metavar="KEY=VALUE", help="override a mission or configuration key")

    console_bench = benches.add_parser(
        "console", help="what the operator console costs the autopilot (a real-time "
        "follow_ball, windows with and without a viewer of the front camera's MJPEG) and the "
        "video's capture-to-viewer latency (about 1 min)")
    console_bench.add_argument("--json", action="store_true",
                               help="print one JSON object on stdout")
    console_bench.add_argument("--window", type=float, default=8.0, metavar="S",
                               help="each window's wall time (default 8)")
    console_bench.add_argument("--windows", type=int, default=2, metavar="N",
                               help="windows each way, alternating (default 2)")
    console_bench.add_argument("--fps", type=float, default=15.0,
                               help="the viewer's frame rate (default 15)")
    console_bench.add_argument("--browser", action="store_true",
                               help="the viewer is the console's page in headless chromium "
                               "(Playwright): latency to the frame drawn")
    console_bench.add_argument("--bare", action="store_true",
                               help="watch the bare frames (?overlay=0): the newest, without "
                               "waiting for the frame's detections")

    load_bench = benches.add_parser(
        "load", help="flight on a busy CPU: the vehicle (autopilot sim) on a core of its own, "
        "the autopilot (MAVLink driver, H.264 video, a console viewer) sharing the other with "
        "N busy processes; per N: completed, control tick, latency, frames shed by perception "
        "and by the console, range RMS (about 1 min per N)")
    load_bench.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    load_bench.add_argument("--hogs", default=",".join(map(str, (0, 2, 4, 6))),
                            metavar="N|N,N,...", help="busy processes: one load, or a list "
                            "(default 0,2,4,6)")
    load_bench.add_argument("--follow-s", type=float, default=20.0, metavar="S",
                            help="how long each flight follows the ball (default 20)")
    load_bench.add_argument("--driver", choices=("mavsdk", "pymavlink"), default="mavsdk")
    load_bench.add_argument("--out", metavar="DIR",
                            help="keep each load's logs (vehicle, run, viewer) in DIR/hogsN")
    load_bench.add_argument("--set", dest="overrides", action="append", default=[],
                            metavar="KEY=VALUE", help="override a mission or configuration key "
                            "(the vehicle's and the autopilot's)")

    api_bench = benches.add_parser(
        "api", help="what the goal API costs the process: a real-time standby hover with the "
        "API idle, then busy (status polled, the status stream followed) (about 1 min)")
    api_bench.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    api_bench.add_argument("--seconds", type=float, default=20.0, metavar="S",
                           help="hover this long in each flight (default 20)")
    api_bench.add_argument("--poll-hz", type=float, default=10.0, metavar="HZ",
                           help="GET /api/status rate while busy (default 10)")
    api_bench.add_argument("--abuse", action="store_true",
                           help="instead: one real-time standby with the console and a token, "
                           "attacked from another process (idle sockets, slow headers, 8 MB and "
                           "deep bodies, no token), then the largest accepted orbit, survey and "
                           "goto and a goal flood: the loop's lag per phase and whether the "
                           "flight went on (about 3 min)")
    api_bench.add_argument("--idle", type=int, default=2000, metavar="N",
                           help="--abuse: idle sockets opened at once (default 2000)")
    api_bench.add_argument("--flood", type=int, default=500, metavar="N",
                           help="--abuse: goals posted back to back (default 500)")

    perception = benches.add_parser(
        "perception", help="each detector on frames rendered from known poses, against truth: "
        "ball (centre, range) and marker at 1, 3, 5 m and 0-60 degrees obliquity (position, "
        "orientation, detection rate, time per frame); down camera: image and pad at 1, 3, "
        "8 m, ours against seed 000's and seed 001's detectors")
    perception.add_argument("--json", action="store_true",
                            help="print one JSON object on stdout")
    perception.add_argument("--quick", action="store_true",
                            help="a few frames per cell (what the test suite runs)")
    perception.add_argument("--detector", dest="detectors", action="append", default=None,
                            metavar="NAME",
                            help="only this detector (repeatable: ball, marker, image, pad)")
    _add_config_options(perception)

    calibration = benches.add_parser(
        "calibration", help="'autopilot calibrate' on views of a ChArUco board and a "
        "chessboard rendered by the simulated front camera (distortion, noise, motion blur) "
        "from known poses: focal length, principal point and distortion against the truth, "
        "reprojection error")
    calibration.add_argument("--json", action="store_true",
                             help="print one JSON object on stdout")
    calibration.add_argument("--quick", action="store_true",
                             help="the ChArUco board only, fewer views (what the test suite "
                             "runs)")
    calibration.add_argument("--save-views", metavar="DIR",
                             help="also write the rendered views as PNG files, a folder per "
                             "board (DIR/charuco, DIR/chessboard), for 'autopilot calibrate'")
    _add_config_options(calibration)

    logging_bench = benches.add_parser(
        "logging", help="what writing flight.mcap (camera frames included) costs a lockstep "
        "follow_ball run: alternate runs with and without the log")
    logging_bench.add_argument("--json", action="store_true",
                               help="print one JSON object on stdout")
    logging_bench.add_argument("--pairs", type=int, default=3, metavar="N",
                               help="runs with and without the log (default 3 of each)")
    logging_bench.add_argument("--mission", default="follow_ball", metavar="NAME|FILE")
    logging_bench.add_argument("--set", dest="overrides", action="append", default=[],
                               metavar="KEY=VALUE", help="override a mission or configuration "
                               "key")

    for name, text in (("goal", "send a goal (one mission step) to a run's goal API"),
                       ("status", "show a run's status (goal API)"),
                       ("cancel", "cancel a goal (default: the running one); the vehicle "
                                  "hovers"),
                       ("abort", "abort the mission: hold, land, disarm")):
        client = commands.add_parser(name, help=text)
        if name == "goal":
            client.add_argument("goal", metavar="JSON|FILE",
                                help="the step as JSON, e.g. '{\"goto\": {\"position_m\": "
                                "[5, 0, 3]}}', or a YAML/JSON file holding it")
            client.add_argument("--wait", action="store_true",
                                help="follow the goal until it ends (feedback on stderr)")
        if name == "cancel":
            client.add_argument("goal_id", nargs="?", help="default: the running goal")
        if name == "status":
            client.add_argument("--watch", action="store_true",
                                help="print the status every second until interrupted")
        client.add_argument("--api", default="127.0.0.1:8080", metavar="HOST:PORT",
                            help="where the run serves its goal API (default 127.0.0.1:8080)")
        client.add_argument("--api-token-file", metavar="FILE",
                            help="bearer token (else AUTOPILOT_API_TOKEN)")

    validate = commands.add_parser("validate", help="check a mission or configuration file")
    validate.add_argument("file")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command in ("run", "bench", "sim", "doctor", "trials"):
        configure_for_flight()
    try:
        if getattr(args, "faults", None):
            from drivers.sim.faults import FaultError, fault_override

            try:
                args.overrides = [*args.overrides, fault_override(args.faults)]
            except FaultError as exc:
                raise InputError(str(exc)) from None
        return _dispatch(args)
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
        code = _failure_exit_code(exc)
        if code is None:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return code


def _dispatch(args: argparse.Namespace) -> int:
    handlers = {"run": _run, "sim": _sim, "doctor": _doctor, "report": _report, "video": _video,
                "replay": _replay, "score": _score, "bench": _bench, "calibrate": _calibrate,
                "missions": lambda _args: _missions(), "validate": lambda a: _validate(a.file),
                "trials": _trials,
                "goal": _api_client, "status": _api_client, "cancel": _api_client,
                "abort": _api_client}
    return handlers[args.command](args)


def _trials(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.trials import (
        TrialsError,
        parse_criterion,
        parse_vary,
        print_result,
        run_trials,
    )

    log = (lambda message: None) if args.json else \
        (lambda message: print(f"  {message}", file=sys.stderr, flush=True))
    try:
        varies = [parse_vary(v) for v in args.varies]
        criteria = [parse_criterion(c) for c in args.criteria] if args.criteria else None
        if args.workers is not None and args.workers < 1:
            raise TrialsError("--workers must be at least 1")
        result = run_trials(args.mission, args.trials, seed_start=args.seed_start,
                            overrides=args.overrides, varies=varies, criteria=criteria,
                            workers=args.workers, cluster=args.cluster,
                            out_dir=Path(args.out) if args.out else None, progress=log)
    except TrialsError as exc:
        raise InputError(str(exc)) from None
    print_result(result, args.json)
    return EXIT_OK if not result.failing else EXIT_FAILED


def _api_client(args: argparse.Namespace) -> int:
    """``autopilot goal | status | cancel | abort``: thin clients of a run's goal API."""
    import json
    import time
    import urllib.error
    import urllib.request

    from autopilot.api import ApiSetupError, parse_address, read_token

    try:
        host, port = parse_address(args.api)
        token = read_token(args.api_token_file)
    except ApiSetupError as exc:
        raise InputError(str(exc)) from None
    base = f"http://{host}:{port}"

    def call(method: str, path: str, body=None) -> tuple[int, object]:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(base + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        try:
            with urllib.request.urlopen(req, timeout=10) as resp:
                return resp.status, json.loads(resp.read() or b"null")
        except urllib.error.HTTPError as err:
            try:
                return err.code, json.loads(err.read() or b"null")
            except ValueError:
                return err.code, {"error": err.reason}
        except (urllib.error.URLError, OSError) as exc:
            raise InputError(f"no goal API at {base} ({getattr(exc, 'reason', exc)}): is "
                             "'autopilot run --api' running there?") from None

    def show(code: int, body) -> int:
        print(json.dumps(body, indent=2))
        return 0 if code < 400 else EXIT_USAGE

    if args.command == "status":
        while True:
            code, body = call("GET", "/api/status")
            if not args.watch:
                return show(code, body)
            b = body if isinstance(body, dict) else {}
            pos = b.get("position_ned_m") or [float("nan")] * 3
            print(f"status {b.get('status_code')} {b.get('status')}  step={b.get('step')}  "
                  f"phase={b.get('phase')}  goal={b.get('goal_id')}  mode={b.get('mode')}  "
                  f"ned=({pos[0]:.1f}, {pos[1]:.1f}, {pos[2]:.1f})", flush=True)
            time.sleep(1.0)
    if args.command == "abort":
        return show(*call("POST", "/api/abort"))
    if args.command == "cancel":
        goal_id = args.goal_id
        if goal_id is None:
            goal_id = call("GET", "/api/status")[1].get("goal_id")
            if goal_id is None:
                print("no goal is running", file=sys.stderr)
                return EXIT_USAGE
        return show(*call("POST", f"/api/goals/{goal_id}/cancel"))
    text = args.goal
    from pathlib import Path

    if not text.lstrip().startswith("{") and Path(text).is_file():
        import yaml

        body = yaml.safe_load(Path(text).read_text())
    else:
        try:
            body = json.loads(text)
        except ValueError as exc:
            raise InputError(f"the goal is not JSON ({exc}); e.g. "
                             "'{\"goto\": {\"position_m\": [5, 0, 3]}}'") from None
    code, answer = call("POST", "/api/goals", body)
    if code >= 400 or not args.wait:
        return show(code, answer)
    goal_id = answer["goal_id"]
    print(f"goal {goal_id} accepted", file=sys.stderr)
    last = None
    while True:
        try:
            code, goal = call("GET", f"/api/goals/{goal_id}")
        except InputError:
            print("the run has ended (its goal API is gone)", file=sys.stderr)
            return 0 if last is not None and last.startswith("succeeded") else 1
        feedback = goal.get("feedback", {})
        line = (f"{goal.get('state')} {feedback.get('phase') or ''} "
                f"{round(100 * feedback['progress']) if feedback.get('progress') else ''}"
                f"{'%' if feedback.get('progress') else ''} photos={feedback.get('photos', 0)}")
        if line != last:
            print(line, file=sys.stderr, flush=True)
            last = line
        if goal.get("state") not in ("queued", "running"):
            print(json.dumps(goal, indent=2))
            return 0 if goal.get("state") == "succeeded" else 1
        time.sleep(0.5)


def _failure_exit_code(exc: BaseException) -> int | None:
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


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.api import ApiSetupError, parse_address, read_token
    from autopilot.logs import setup_logging
    from autopilot.mission import load_mission
    from autopilot.run import default_out_dir, fly

    overrides = [*args.overrides, *([f"driver={args.driver}"] if args.driver else [])]
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
    plan = load_mission(args.mission, overrides, args.config)
    token = None
    waits = [i for i, step in enumerate(plan.steps)
             if step.name == "standby" and step.params.timeout_s is None]
    if waits and not args.api:
        raise InputError(f"{plan.source}: step {waits[0]} (standby) waits for goals from the "
                         "goal API: run with --api HOST:PORT (e.g. --api 127.0.0.1:8080), or "
                         "give the standby a timeout_s")
    if args.api:
        from autopilot.api import check_listen, check_tls, is_loopback

        try:
            host, port = parse_address(args.api)
            token = read_token(args.api_token_file)
            if not is_loopback(host) and not token:
                raise ApiSetupError(f"--api {args.api} is reachable from other machines: give "
                                    "a token (--api-token-file FILE, or AUTOPILOT_API_TOKEN)")
            check_listen(host, port)
            if bool(args.api_tls_cert) != bool(args.api_tls_key):
                raise ApiSetupError("--api-tls-cert and --api-tls-key go together")
            if args.api_tls_cert:
                check_tls(args.api_tls_cert, args.api_tls_key)
        except ApiSetupError as exc:
            raise InputError(str(exc)) from None
    elif args.api_tls_cert or args.api_tls_key:
        raise InputError("--api-tls-cert/--api-tls-key serve the goal API or the console: "
                         "give --api HOST:PORT or --console HOST:PORT")
    if args.faults and plan.config.driver != "sim":
        raise InputError(f"--fault acts on the simulated vehicle, not on a vehicle flown through "
                         f"--driver {plan.config.driver}: give it to 'autopilot sim --fault ...' "
                         "(the MAVLink vehicle it simulates), or fly --driver sim")
    out = Path(args.out) if args.out else default_out_dir(plan)
    if plan.config.driver != "sim":
        _check_network_exposure("--connect", args.connect or plan.config.link.connect,
                                args.signing_key or plan.config.link.signing_key, args.insecure)
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
                              if args.api_tls_cert else None))
    if sys.stderr.isatty():
        sys.stderr.write("\n")
    follow = summary["metrics"].get("follow") or {}
    rtf = summary["metrics"]["sim"].get("real_time_factor")
    timing = (f"simulated {summary['sim_time_s']:.1f} s in {summary['wall_time_s']:.1f} s "
              f"(× {rtf:.1f})" if rtf else f"flew for {summary['wall_time_s']:.1f} s")
    profile = (summary.get("sim") or {}).get("profile")
    lines = [f"status: {summary['status']}" + (f" ({summary['reason']})" if summary["reason"]
                                                else ""),
             timing + (f", {profile} world" if profile else "") + _steal(summary)]
    if follow:
        lines.append("follow: " + ", ".join(
            f"{k}={_fmt(follow.get(k))}" for k in ("detection_rate", "rms_range_error_m",
                                                   "rms_image_error_px", "max_lost_s")))
    estimation = summary["metrics"].get("estimation") or {}
    if estimation:
        lines.append("estimate (as flown on): " + ", ".join(
            f"{k}={_fmt(estimation.get(k))}" for k in (
                "rms_position_error_m", "rms_relative_position_error_m",
                "rms_velocity_error_m_s", "within_2sigma", "relative_within_2sigma",
                "coasting_share", "lost_share")))
    for group, keys in (
            ("orbit", ("rms_cross_track_m", "max_cross_track_m", "rms_cross_track_nav_m",
                       "rms_navigation_error_m", "photos", "images_planned", "centre_in_frame")),
            ("survey", ("rms_cross_track_m", "max_cross_track_m", "rms_cross_track_nav_m",
                        "rms_navigation_error_m", "coverage", "photos", "photos_planned")),
            ("goto", ("rms_cross_track_m", "rms_cross_track_nav_m", "final_error_m")),
            ("landing", ("on_deck", "on_pad", "error_m", "relative_horizontal_speed_m_s",
                         "touchdown_speed_m_s", "time_to_land_s", "retries")),
            ("relative", ("rms_horizontal_error_m", "within_2sigma", "lost_share"))):
        values = summary["metrics"].get(group) or {}
        if values:
            lines.append(f"{group}: " + ", ".join(f"{k}={_fmt(values.get(k))}" for k in keys
                                                   if k in values))
    if summary.get("photos") and summary["photos"].get("taken"):
        lines.append(f"photos: {summary['photos']['taken']} in {out / 'photos'} "
                     "(JPEG + EXIF GPS, photos.geojson)")
    lat = summary["metrics"]["latency_ms"]
    if lat["samples"]:
        lines.append(f"latency: p50 {lat['p50']:.1f} ms, p95 {lat['p95']:.1f} ms")
    lines.append(f"wrote {out / 'summary.json'} and {out / 'flight.mcap'}")
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
    return {"completed": EXIT_OK, "aborted": EXIT_ABORTED}.get(summary["status"], EXIT_FAILED)


def _check_network_exposure(option: str, url: str, key: str | None, insecure: bool) -> None:
    """A MAVLink link to or from another machine needs a signing key (or an explicit
    --insecure): anyone on that network could otherwise fly the vehicle."""
    from autopilot.config import Problem
    from drivers.mavlink.link import Endpoint, UrlError

    try:
        endpoint = Endpoint.parse(url)
    except UrlError as exc:
        raise ConfigError([Problem("command line", None, option, str(exc))]) from None
    if endpoint.kind == "serial" or key or insecure or _loopback(endpoint.host):
        return
    raise ConfigError([Problem("command line", None, option, f"{url}: a MAVLink link on a "
                               "network address needs "
                               "--signing-key FILE (MAVLink 2 signing), or --insecure to "
                               "accept unsigned traffic from that network")])


def _loopback(host: str) -> bool:
    import ipaddress

    if host in ("localhost", ""):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _sim(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.sim_server import serve

    if args.mission:
        from autopilot.mission import load_mission

        plan = load_mission(args.mission, args.overrides, args.config)
        config, scenario = plan.config, plan.mission.scenario
    else:
        config, scenario = load_config(args.config, args.overrides), None
    signing = None
    if args.signing_key:
        from autopilot.config import Problem
        from drivers.mavlink.signing import Signing, SigningKeyError

        try:
            signing = Signing.load(args.signing_key)
        except SigningKeyError as exc:
            raise ConfigError([Problem("command line", None, "--signing-key",
                                       str(exc))]) from None
    _check_network_exposure("--bind", f"udpin://{args.bind}:14580", args.signing_key,
                            args.insecure)
    from autopilot.logs import route_library_logs

    route_library_logs()
    from autopilot.cameras import parse_camera_options
    from autopilot.sim_server import FROM_CONFIG

    videos = None if args.no_video else (
        parse_camera_options(args.video, "--video", "front") if args.video else FROM_CONFIG)
    token = None
    if args.console:
        from autopilot.api import (
            ApiSetupError,
            check_listen,
            is_loopback,
            parse_address,
            read_token,
        )

        try:
            host, port = parse_address(args.console)
            token = read_token(args.api_token_file)
            if not is_loopback(host) and not token:
                raise ApiSetupError(f"--console {args.console} is reachable from other "
                                    "machines: give a token (--api-token-file FILE, or "
                                    "AUTOPILOT_API_TOKEN)")
            check_listen(host, port)
        except ApiSetupError as exc:
            raise InputError(str(exc)) from None
    asyncio.run(serve(config, scenario, instance=args.instance, videos=videos,
                      out_dir=Path(args.out) if args.out else None,
                      log=lambda line: print(line, file=sys.stderr, flush=True),
                      host=args.bind, signing=signing, console=args.console,
                      console_token=token,
                      title=plan.mission.name if args.mission else "empty world"))
    return EXIT_OK


def _doctor(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.doctor import as_dicts, run_doctor, summary_line
    from autopilot.logs import setup_logging
    from autopilot.mission import load_mission

    setup_logging(None)
    plan = load_mission(args.mission, args.overrides)
    driver = args.driver or (plan.config.driver if plan.config.driver != "sim" else "pymavlink")
    plan = load_mission(args.mission, [*args.overrides, f"driver={driver}"])
    report = (lambda check: None) if args.json else (lambda check: print(check.line(),
                                                                         flush=True))
    checks = asyncio.run(run_doctor(
        plan, connect=args.connect, video=args.video, calibration=args.calibration,
        signing_key=Path(args.signing_key) if args.signing_key else None,
        duration_s=args.duration_s, report=report))
    if args.json:
        print(json.dumps({"checks": as_dicts(checks), "ok": not any(
            c.status == "FAIL" for c in checks)}))
    else:
        print(summary_line(checks))
    return EXIT_FAILED if any(c.status == "FAIL" for c in checks) else EXIT_OK


def _report(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.report.html import write_report

    log = Path(args.run_dir) / "flight.mcap"
    if not log.is_file():
        print(f"error: {log}: no such file", file=sys.stderr)
        return EXIT_USAGE
    print(f"wrote {write_report(Path(args.run_dir))}")
    return EXIT_OK


def _video(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.report.video import write_video

    path, frames = write_video(Path(args.run_dir), args.camera)
    print(f"wrote {path} ({frames} frames)")
    return EXIT_OK


def _replay(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.flightlog.records import clean
    from autopilot.replay import format_replay, replay

    result = replay(Path(args.run_dir), args.overrides)
    print(json.dumps(clean(result)) if args.json else format_replay(result))
    return EXIT_OK


def _score(args: argparse.Namespace) -> int:
    from pathlib import Path

    from autopilot.score import score

    metrics = score(Path(args.run_dir), Path(args.truth))
    groups = {name: group for name, group in metrics.items()
              if name != "steps" and isinstance(group, dict) and group}
    if not groups:
        print("no scored step in this run (follow_ball, follow_marker, …), or no truth "
              "overlapping it", file=sys.stderr)
        return EXIT_FAILED
    for name, group in groups.items():
        print(f"{name}: " + ", ".join(f"{k}={_fmt(v)}" for k, v in group.items()
                                     if not isinstance(v, (dict, list))))
    print(f"updated {Path(args.run_dir) / 'summary.json'}")
    return EXIT_OK


def _steal(summary: dict) -> str:
    steal = summary["metrics"]["sim"].get("cpu_steal_pct")
    return "" if steal is None else f"; hypervisor steal {steal:.1f} % of CPU time"


def _fmt(value) -> str:
    return "n/a" if value is None else f"{value:.3f}" if isinstance(value, float) else str(value)


def _missions() -> int:
    from autopilot.mission import load_mission, shipped_missions

    for path in shipped_missions():
        try:
            plan = load_mission(str(path))
            print(f"{path.stem:<20} {plan.mission.description}")
        except ConfigError as exc:
            print(f"{path.stem:<20} INVALID: {exc.problems[0]}")
    return EXIT_OK


def _validate(file: str) -> int:
    from autopilot.mission import is_mission_file, load_mission

    if is_mission_file(file):
        plan = load_mission(file)
        print(f"{file}: ok (mission {plan.mission.name}, {len(plan.steps)} steps)")
    else:
        load_config(file)
        print(f"{file}: ok (configuration)")
    return EXIT_OK


def _calibrate(args: argparse.Namespace) -> int:
    from autopilot.calibrate import CalibrationOptions, format_summary, run

    if args.max_views < 3 or args.min_views < 3 or args.min_views > args.max_views:
        raise InputError(f"--min-views {args.min_views} / --max-views {args.max_views}: both "
                         "at least 3, and --min-views not above --max-views")
    options = CalibrationOptions(max_views=args.max_views, min_views=args.min_views,
                                 fix_k3=args.fix_k3, rational=args.rational)

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    result, out, ros = run(args.source, args.board, args.out, ros_out=args.ros_out,
                           camera_name=args.camera_name, max_frames=args.frames,
                           duration_s=args.duration_s, every=args.every, options=options,
                           log=log)
    if args.json:
        print(json.dumps({**result.as_dict(), "source": args.source, "out": str(out),
                          "ros_out": str(ros)}))
    else:
        print(format_summary(result))
        print(f"wrote {out} (OpenCV) and {ros} (ROS camera_info)")
    return EXIT_OK


def _stderr_progress(message: str) -> None:
    print(f"  {message}", file=sys.stderr, flush=True)


def _bench(args: argparse.Namespace) -> int:
    log = (lambda message: None) if args.json else \
        (lambda message: print(f"  {message}", file=sys.stderr, flush=True))
    if args.bench in ("follow_ball", "follow_marker"):
        from autopilot.bench import follow

        known = follow.BENCHES[args.bench].scenarios
        unknown = [s for s in args.scenarios or () if s not in known]
        if unknown:
            raise InputError(f"--scenario {unknown[0]}: no such scenario (known: "
                             f"{', '.join(known)})")
        if args.seeds < 1:
            raise InputError(f"--seeds {args.seeds}: at least 1")
        controllers = follow.BENCHES[args.bench].controllers
        unknown = [r for r in args.rows or () if r not in controllers]
        if unknown:
            raise InputError(f"--row {unknown[0]}: no such controller (known: "
                             f"{', '.join(controllers)})")
        result = follow.run_bench(args.bench, args.mission, args.overrides, log,
                                  args.scenarios, quick=args.quick, seeds=args.seeds,
                                  seed_start=args.seed_start, controllers=args.rows)
        print(json.dumps(result) if args.json else follow.format_table(result))
        return EXIT_OK

    if args.bench in ("hover_image", "land_pad"):
        from autopilot.bench import down

        known = down.BENCHES[args.bench].scenarios
        unknown = [s for s in args.scenarios or () if s not in known]
        if unknown:
            raise InputError(f"--scenario {unknown[0]}: no such scenario (known: "
                             f"{', '.join(known)})")
        if args.seeds < 1:
            raise InputError(f"--seeds {args.seeds}: at least 1")
        rows = down.BENCHES[args.bench].rows
        unknown = [r for r in args.rows or () if r not in rows]
        if unknown:
            raise InputError(f"--row {unknown[0]}: no such row (known: {', '.join(rows)})")
        result = down.run_bench(args.bench, args.seeds, args.overrides, log, args.scenarios,
                                quick=args.quick, rows=args.rows, seed_start=args.seed_start)
        print(json.dumps(result) if args.json else down.format_table(result))
        return EXIT_OK

    if args.bench == "soak":
        from autopilot.bench import soak
        from autopilot.mission import load_mission

        log = _stderr_progress  # (stdout keeps the table or the JSON)
        if not args.duration_s > 0:
            raise InputError(f"--duration-s {args.duration_s}: must be positive")
        missions = args.missions or soak.MISSIONS
        for name in missions:
            load_mission(name, args.overrides)  # nothing flies on an invalid mission
        result = soak.run_bench(args.duration_s, missions, args.overrides, log)
        print(json.dumps(result) if args.json else soak.format_table(result))
        return EXIT_OK if result["ok"] else EXIT_FAILED

    if args.bench == "faults":
        from autopilot.bench import faults

        log = _stderr_progress
        if args.seeds < 1:
            raise InputError(f"--seeds {args.seeds}: at least 1")
        for name in args.missions or ():
            if name not in faults.MISSIONS:
                raise InputError(f"--mission {name}: not in the fault bench (its missions: "
                                 f"{', '.join(faults.MISSIONS)})")
        known = {c.kind for c in faults.CASES} | {c.name for c in faults.CASES}
        for kind in args.kinds or ():
            if kind not in known:
                raise InputError(f"--kind {kind}: no such fault case (known: "
                                 f"{', '.join(c.name for c in faults.CASES)})")
        if not faults.cells(args.missions, args.kinds):
            raise InputError("no cell applies to those missions and kinds")
        result = faults.run_bench(args.seeds, args.missions, args.kinds, args.overrides, log,
                                  workers=args.workers, seed_start=args.seed_start)
        print(json.dumps(result) if args.json else faults.format_table(result))
        return EXIT_OK if result["total"]["unsafe"] == 0 else EXIT_FAILED

    if args.bench == "landing":
        from autopilot.bench import landing

        if args.trials < 1:
            raise InputError(f"--trials {args.trials}: at least 1")
        if not 0.0 <= args.rover_speed <= 5.0:
            raise InputError(f"--rover-speed {args.rover_speed}: between 0 and 5 m/s")
        result = landing.run_bench(args.trials, args.rover_speed, args.overrides, log,
                                   workers=args.workers, cluster=args.cluster,
                                   strategies=args.strategies)
        print(json.dumps(result) if args.json else landing.format_table(result))
        return EXIT_OK

    if args.bench == "console":
        from autopilot.bench import console as console_bench

        if args.window <= 0 or args.windows < 1 or not 0 < args.fps <= 30:
            raise InputError("--window must be positive, --windows at least 1, --fps in "
                             "(0, 30]")
        result = console_bench.run_bench(args.window, args.windows, args.fps, args.browser,
                                         log, overlay=not args.bare)
        print(json.dumps(result) if args.json else console_bench.format_table(result))
        return EXIT_OK

    if args.bench == "load":
        from pathlib import Path

        from autopilot.bench import load as load_bench

        hogs = load_bench.parse_hogs(args.hogs)
        if not 0 < args.follow_s <= 600:
            raise InputError(f"--follow-s {args.follow_s}: between 0 and 600 s")
        cores = load_bench.pick_cores()
        result = load_bench.run_bench(hogs, args.follow_s, args.driver, args.overrides,
                                      _stderr_progress, Path(args.out) if args.out else None,
                                      cores=cores)
        print(json.dumps(result) if args.json else load_bench.format_table(result))
        return EXIT_OK

    if args.bench == "api":
        from autopilot.bench import api as api_bench

        if args.seconds <= 0 or args.poll_hz <= 0:
            raise InputError("--seconds and --poll-hz must be positive")
        if args.abuse:
            if not 0 < args.idle <= 20_000 or not 0 < args.flood <= 100_000:
                raise InputError("--idle must be 1-20000 and --flood 1-100000")
            result = api_bench.run_abuse(args.idle, max(args.seconds, 12.0), args.flood, log)
            print(json.dumps(result) if args.json else api_bench.format_abuse(result))
            return EXIT_OK if result["status"] == "completed" and not result["aborted"] \
                else EXIT_FAILED
        result = api_bench.run_bench(args.seconds, args.poll_hz, log)
        print(json.dumps(result) if args.json else api_bench.format_table(result))
        return EXIT_OK

    if args.bench == "offboard":
        from autopilot.bench import offboard

        unknown = [s for s in args.scenarios or () if s not in offboard.SCENARIOS]
        if unknown:
            raise InputError(f"--scenario {unknown[0]}: no such scenario (known: "
                             f"{', '.join(offboard.SCENARIOS)})")
        if args.seeds < 1:
            raise InputError(f"--seeds {args.seeds}: at least 1")
        result = offboard.run_bench(args.seeds, args.overrides, log, args.scenarios)
        print(json.dumps(result) if args.json else offboard.format_table(result))
        return EXIT_OK

    if args.bench == "perception":
        from autopilot.bench import perception as perception_bench

        unknown = [d for d in args.detectors or () if d not in perception_bench.BENCHES]
        if unknown:
            raise InputError(f"--detector {unknown[0]}: no such detector (known: "
                             f"{', '.join(perception_bench.BENCHES)})")
        config = load_config(args.config, args.overrides)
        result = perception_bench.run_bench(log, quick=args.quick, detectors=args.detectors,
                                            config=config)
        print(json.dumps(result) if args.json else perception_bench.format_table(result))
        return EXIT_OK

    if args.bench == "calibration":
        from pathlib import Path

        from autopilot.bench import calibration as calibration_bench

        config = load_config(args.config, args.overrides)
        result = calibration_bench.run_bench(
            log, quick=args.quick, config=config,
            save_dir=Path(args.save_views) if args.save_views else None)
        print(json.dumps(result) if args.json else calibration_bench.format_table(result))
        return EXIT_OK if all(r["met"] for r in result["required"].values()) else EXIT_FAILED

    if args.bench == "logging":
        from autopilot.bench import logging as logging_bench

        result = logging_bench.run_bench(args.mission, args.overrides, args.pairs, log)
        print(json.dumps(result) if args.json else logging_bench.format_table(result))
        return EXIT_OK

    from autopilot.bench.sitl import format_table, run_sitl_bench

    config = load_config(args.config, args.overrides)
    result = asyncio.run(run_sitl_bench(config.sim, lockstep=not args.realtime, log=log))
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(format_table(result))
    return EXIT_OK
