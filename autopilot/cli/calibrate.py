"""``autopilot calibrate``: a camera's intrinsics and distortion from views of a board."""

from __future__ import annotations

import argparse
import json
import sys

from autopilot.cli.common import EXIT_OK, Command
from autopilot.config import InputError


def arguments(calibrate: argparse.ArgumentParser) -> None:
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


def run(args: argparse.Namespace) -> int:
    from autopilot.calibration import CalibrationOptions, format_summary
    from autopilot.calibration import run as calibrate

    if args.max_views < 3 or args.min_views < 3 or args.min_views > args.max_views:
        raise InputError(f"--min-views {args.min_views} / --max-views {args.max_views}: both "
                         "at least 3, and --min-views not above --max-views")
    options = CalibrationOptions(max_views=args.max_views, min_views=args.min_views,
                                 fix_k3=args.fix_k3, rational=args.rational)

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    result, out, ros = calibrate(args.source, args.board, args.out, ros_out=args.ros_out,
                                 camera_name=args.camera_name, max_frames=args.frames,
                                 duration_s=args.duration_s, every=args.every,
                                 options=options, log=log)
    if args.json:
        print(json.dumps({**result.as_dict(), "source": args.source, "out": str(out),
                          "ros_out": str(ros)}))
    else:
        print(format_summary(result))
        print(f"wrote {out} (OpenCV) and {ros} (ROS camera_info)")
    return EXIT_OK


COMMAND = Command(
    "calibrate", "estimate a camera's intrinsics and lens distortion from views of a "
    "chessboard or ChArUco board; writes OpenCV and ROS calibration YAML", arguments, run,
    description="Find the board in every frame, keep sharp, varied views (no "
    "near-duplicates), calibrate (dropping views that do not fit the others), report "
    "the reprojection error and how much of the image and of the tilts the views "
    "covered, and write the calibration.")
