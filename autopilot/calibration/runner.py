"""The whole run, as ``autopilot calibrate`` does it: frames in, the calibration out
(OpenCV and ROS YAML), with its summary."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable
from pathlib import Path

from autopilot.calibration.board import BoardSpec, parse_board_spec
from autopilot.calibration.common import CalibrationFailed, Log, no_log
from autopilot.calibration.detection import BoardDetector, BoardView
from autopilot.calibration.fit import CalibrationResult, calibrate
from autopilot.calibration.selection import DEFAULT_OPTIONS, CalibrationOptions, select_views
from autopilot.calibration.sources import FrameSource, SourceFrame
from autopilot.config import InputError


def calibrate_frames(frames: Iterable[SourceFrame], board: BoardSpec,
                     options: CalibrationOptions = DEFAULT_OPTIONS,
                     log: Log = no_log) -> CalibrationResult:
    """Detect the board in every frame, select the views, calibrate. :class:`InputError`
    for frames of different sizes, :class:`CalibrationFailed` for no board in any frame or
    too few usable views (the message says how many were found and are needed)."""
    detector = BoardDetector(board)
    found: list[BoardView] = []
    size: tuple[int, int] | None = None
    first = ""
    read = 0
    started = time.monotonic()
    last_report = started
    reading = iter(frames)
    try:
        for frame in reading:
            read += 1
            h, w = frame.image.shape[:2]
            if size is None:
                size, first = (w, h), frame.name
            elif (w, h) != size:
                raise InputError(f"{frame.name}: {w}x{h} pixels, but {first} is {size[0]}x"
                                 f"{size[1]}: calibrate one camera at one resolution at a time")
            view = detector.detect(frame.image, frame.name)
            if view is not None:
                found.append(view)
            now = time.monotonic()
            if now - last_report >= 2.0:
                last_report = now
                log(f"{read} frames, board in {len(found)}")
    except KeyboardInterrupt:
        if not getattr(frames, "live", False):
            raise
        log(f"Ctrl-C: stopped reading after {read} frames; calibrating with those")
    finally:
        close = getattr(reading, "close", None)
        if close is not None:
            close()  # a live source's receiver stops here
    skipped = tuple(getattr(frames, "skipped", ()))
    if read == 0 or size is None:
        raise InputError("no frames to calibrate with")
    log(f"{read} frames read in {time.monotonic() - started:.1f} s; board in {len(found)}")
    if not found:
        cols, rows = board.inner_corners
        raise CalibrationFailed(
            f"no {board.pattern} {board.columns}x{board.rows} found in any of the {read} "
            f"frames. COLSxROWS counts squares: this board has {cols}x{rows} inner corners"
            + (" and must be seen whole" if board.pattern == "chessboard" else
               f", {board.dictionary} markers")
            + "; check --board against the printed board, and the focus and lighting")
    selection = select_views(found, board, size, options)
    if len(selection.views) < options.min_views:
        counts = {r: sum(1 for x in selection.rejected if x.reason == r)
                  for r in ("blurry", "duplicate")}
        raise CalibrationFailed(
            f"the board was found in {len(found)} of {read} frames, {len(selection.views)} "
            f"of them usable ({counts['blurry']} blurry, {counts['duplicate']} "
            f"near-duplicates); need at least {options.min_views} views: show the board "
            "still and sharp at more places, distances and tilts"
            + ("" if options.min_views <= 3 else " (or lower --min-views)"))
    return calibrate(selection.views, board, size, options, rejected=selection.rejected,
                     frames_read=read, frames_with_board=len(found), skipped=skipped)


def ros_path_for(out: Path) -> Path:
    """Where the ROS camera_info YAML goes by default: next to ``out``, ``NAME_ros.yaml``."""
    return out.with_name(f"{out.stem}_ros.yaml")


def write_result(result: CalibrationResult, out: Path, ros_out: Path | None = None,
                 camera_name: str = "camera", source: str = "") -> tuple[Path, Path]:
    """The OpenCV calibration YAML at ``out`` (with the fit's figures as metadata) and ROS's
    camera_info YAML at ``ros_out`` (default :func:`ros_path_for`). :class:`InputError` if
    either cannot be written."""
    from datetime import UTC, datetime

    from drivers.calibration import CalibrationError, write_calibration, write_ros_calibration

    ros = ros_out if ros_out is not None else ros_path_for(out)
    if ros.resolve() == out.resolve():
        raise InputError(f"--ros-out {ros}: the same file as --out")
    c = result.coverage
    metadata: dict[str, int | float | str] = {
        "calibration_time": datetime.now(UTC).isoformat(timespec="seconds"),
        "board": result.board.text,
        "reprojection_rms_px": result.reprojection_rms_px,
        "views": len(result.views),
        "frames_with_board": result.frames_with_board,
        "frames_read": result.frames_read,
        "coverage_cells_fraction": c.cells_fraction,
        "coverage_border_cells_fraction": c.border_cells_fraction,
        "tilt_deg_max": c.tilt_deg_max,
    }
    if source:
        metadata["source"] = source
    try:
        write_calibration(out, result.intrinsics, metadata)
        write_ros_calibration(ros, result.intrinsics, camera_name)
    except CalibrationError as exc:
        raise InputError(str(exc)) from None
    return out, ros


def format_summary(result: CalibrationResult) -> str:
    """What ``autopilot calibrate`` prints."""
    intr = result.intrinsics
    c = result.coverage
    counts = result.rejected_counts()
    names = {"blurry": "blurry", "duplicate": "near-duplicates", "outlier": "outliers",
             "not_needed": "not needed"}
    why = ", ".join(f"{n} {names[r]}" for r, n in counts.items() if n)
    errors = [v.rms_px for v in result.views]
    worst = sorted(result.views, key=lambda v: -v.rms_px)[:3]
    d = intr.distortion
    labels = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
    lines = [
        f"board: {result.board.describe()}",
        f"views: {len(result.views)} used of {result.frames_with_board} with the board "
        f"({result.frames_read} frames read)" + (f"; not used: {why}" if why else ""),
        f"coverage: {c.cells_fraction:.0%} of the image's {c.grid[0]}x{c.grid[1]} cells, "
        f"{c.border_cells_fraction:.0%} of its border cells, {c.area_fraction:.0%} of its "
        f"area; tilted {c.tilt_deg_min:.0f}-{c.tilt_deg_max:.0f}° off the optical axis; board "
        f"{c.board_width_fraction_range[0]:.0%}-{c.board_width_fraction_range[1]:.0%} of the "
        "image's width",
        f"reprojection RMS {result.reprojection_rms_px:.3f} px (views {min(errors):.3f}-"
        f"{max(errors):.3f} px; worst: "
        + ", ".join(f"{v.name} {v.rms_px:.3f}" for v in worst) + ")",
        f"image {intr.width_px}x{intr.height_px}: fx {intr.fx:.2f} ± {result.std_px[0]:.2f}, "
        f"fy {intr.fy:.2f} ± {result.std_px[1]:.2f}, cx {intr.cx:.2f} ± {result.std_px[2]:.2f}"
        f", cy {intr.cy:.2f} ± {result.std_px[3]:.2f} px (hfov "
        f"{math.degrees(intr.hfov_rad):.1f}° as a pinhole)",
        "distortion: " + " ".join(f"{labels[i] if i < len(labels) else f'c{i}'} {v:+.5f}"
                                  for i, v in enumerate(d)),
    ]
    if result.skipped:
        lines.append(f"skipped {len(result.skipped)} unreadable files: "
                     + ", ".join(result.skipped[:5]) + (" ..." if len(result.skipped) > 5
                                                       else ""))
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def run(source: str, board_spec: str, out: str | os.PathLike, *,
        ros_out: str | os.PathLike | None = None, camera_name: str = "camera",
        max_frames: int | None = None, duration_s: float | None = None, every: int = 1,
        options: CalibrationOptions = DEFAULT_OPTIONS,
        log: Log = no_log) -> tuple[CalibrationResult, Path, Path]:
    """``autopilot calibrate``: parse the board, read the source, calibrate, write both
    files. Returns the result and the two paths written."""
    board = parse_board_spec(board_spec)
    out_path = Path(out)
    if not out_path.parent.is_dir():
        raise InputError(f"--out {out}: no such folder {out_path.parent}")
    ros_path = Path(ros_out) if ros_out is not None else None
    if ros_path is not None and not ros_path.parent.is_dir():
        raise InputError(f"--ros-out {ros_out}: no such folder {ros_path.parent}")
    frames = FrameSource(source, max_frames=max_frames, duration_s=duration_s, every=every,
                         log=log)
    log(f"reading {frames.describe()}; board: {board.describe()}")
    result = calibrate_frames(frames, board, options, log)
    written = write_result(result, out_path, ros_path, camera_name, source)
    return result, *written
