"""The calibration itself: OpenCV's fit, dropping views that do not fit the others, with
the reprojection errors and the coverage of the image and of the tilts."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from autopilot.calibration.board import BoardSpec
from autopilot.calibration.common import CalibrationFailed
from autopilot.calibration.detection import BoardView
from autopilot.calibration.selection import (
    DEFAULT_OPTIONS,
    BoardPose,
    CalibrationOptions,
    Rejection,
    board_pose,
)
from drivers.base import CameraIntrinsics
from drivers.camera_model import distortion_problem


@dataclass(frozen=True, slots=True)
class ViewError:
    name: str
    rms_px: float
    corners: int
    tilt_deg: float
    board_width_fraction: float  # the whole board's width over the image's


@dataclass(frozen=True, slots=True)
class Coverage:
    """How much of the image and of the possible poses the views used covered."""

    #: Of the image divided into ``grid`` cells: the share with a corner in any view.
    cells_fraction: float
    #: Of the cells on the image's border (where the lens distorts most): the share covered.
    border_cells_fraction: float
    #: Of the image's area: the share inside some view's detected corners' outline.
    area_fraction: float
    grid: tuple[int, int]
    tilt_deg_min: float
    tilt_deg_max: float
    #: The range of tilt about the camera's x axis (board top towards or away) and y axis.
    tilt_x_deg_range: tuple[float, float]
    tilt_y_deg_range: tuple[float, float]
    board_width_fraction_range: tuple[float, float]


@dataclass(frozen=True, slots=True, eq=False)
class CalibrationResult:
    board: BoardSpec
    intrinsics: CameraIntrinsics
    #: Over every corner of every view used: sqrt(mean squared reprojection error), px.
    reprojection_rms_px: float
    #: The views used, with their own RMS error.
    views: tuple[ViewError, ...]
    #: Views found but not used, and why.
    rejected: tuple[Rejection, ...]
    coverage: Coverage
    #: One standard deviation of fx, fy, cx, cy (px) as the fit estimates it.
    std_px: tuple[float, float, float, float]
    frames_read: int
    frames_with_board: int
    warnings: tuple[str, ...] = ()
    #: Files of a folder that could not be read.
    skipped: tuple[str, ...] = field(default=())

    def rejected_counts(self) -> dict[str, int]:
        counts = {"blurry": 0, "duplicate": 0, "not_needed": 0, "outlier": 0}
        for r in self.rejected:
            counts[r.reason] += 1
        return counts

    def as_dict(self) -> dict:
        intr = self.intrinsics
        c = self.coverage
        return {
            "board": self.board.text,
            "image_width_px": intr.width_px, "image_height_px": intr.height_px,
            "fx_px": intr.fx, "fy_px": intr.fy, "cx_px": intr.cx, "cy_px": intr.cy,
            "distortion": list(intr.distortion),
            "std_px": dict(zip(("fx", "fy", "cx", "cy"), self.std_px, strict=True)),
            "reprojection_rms_px": self.reprojection_rms_px,
            "frames_read": self.frames_read,
            "frames_with_board": self.frames_with_board,
            "views_used": len(self.views),
            "rejected": self.rejected_counts(),
            "coverage": {
                "cells_fraction": c.cells_fraction, "grid": list(c.grid),
                "border_cells_fraction": c.border_cells_fraction,
                "area_fraction": c.area_fraction,
                "tilt_deg_min": c.tilt_deg_min, "tilt_deg_max": c.tilt_deg_max,
                "tilt_x_deg_range": list(c.tilt_x_deg_range),
                "tilt_y_deg_range": list(c.tilt_y_deg_range),
                "board_width_fraction_range": list(c.board_width_fraction_range)},
            "views": [{"name": v.name, "rms_px": v.rms_px, "corners": v.corners,
                       "tilt_deg": v.tilt_deg,
                       "board_width_fraction": v.board_width_fraction} for v in self.views],
            "rejected_views": [{"name": r.name, "reason": r.reason, "detail": r.detail}
                               for r in self.rejected],
            "skipped_files": list(self.skipped),
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True, slots=True, eq=False)
class Fit:
    rms_px: float
    k: np.ndarray
    dist: np.ndarray
    rvecs: tuple
    tvecs: tuple
    per_view_px: np.ndarray
    std: np.ndarray


def fit_views(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
         options: CalibrationOptions) -> Fit:
    obj = board.object_points_m()
    object_points = [obj[v.corner_ids].reshape(-1, 1, 3) for v in views]
    image_points = [v.image_points_px.astype(np.float32).reshape(-1, 1, 2) for v in views]
    flags = (cv2.CALIB_FIX_K3 if options.fix_k3 else 0) | \
        (cv2.CALIB_RATIONAL_MODEL if options.rational else 0)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        rms, k, dist, rvecs, tvecs, std, _, per_view = cv2.calibrateCameraExtended(
            object_points, image_points, image_size, None, None, flags=flags,
            criteria=criteria)
    except cv2.error as exc:
        raise CalibrationFailed(f"OpenCV cannot fit a camera to these {len(views)} views "
                                f"({(exc.err or str(exc)).strip()}): show the board at more "
                                "distances and tilts") from None
    return Fit(float(rms), k, dist.ravel(), tuple(rvecs), tuple(tvecs),
                np.asarray(per_view, dtype=float).ravel(), np.asarray(std, dtype=float).ravel())


def calibrate(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
              options: CalibrationOptions = DEFAULT_OPTIONS, *,
              rejected: Sequence[Rejection] = (), frames_read: int | None = None,
              frames_with_board: int | None = None,
              skipped: Sequence[str] = ()) -> CalibrationResult:
    """Fit the camera to ``views`` (already selected: see :func:`select_views`), drop the
    views that fit much worse than the others and fit again (see
    :class:`CalibrationOptions`). :class:`CalibrationFailed` with fewer than
    ``options.min_views`` views."""
    if len(views) < options.min_views:
        raise CalibrationFailed(f"{len(views)} usable views of the board; need at least "
                                f"{options.min_views}")
    used = list(views)
    dropped: list[Rejection] = []
    fit = fit_views(used, board, image_size, options)
    for _ in range(3):
        median = float(np.median(fit.per_view_px))
        limit = max(options.outlier_factor * median, options.outlier_floor_px)
        bad = [i for i, e in enumerate(fit.per_view_px) if e > limit]
        if not bad or len(used) - len(bad) < options.min_views:
            break
        dropped += [Rejection(used[i].name, "outlier", f"RMS {fit.per_view_px[i]:.2f} px "
                              f"(limit {limit:.2f} px)") for i in bad]
        used = [v for i, v in enumerate(used) if i not in set(bad)]
        fit = fit_views(used, board, image_size, options)

    w, h = image_size
    dist = [float(d) for d in fit.dist]
    if len(dist) > 5 and not options.rational:
        dist = dist[:5]
    intr = CameraIntrinsics(int(w), int(h), float(fit.k[0, 0]), float(fit.k[1, 1]),
                            float(fit.k[0, 2]), float(fit.k[1, 2]), tuple(dist))
    poses = [board_pose(v, board, fit.k, fit.dist, image_size, r, t)
             for v, r, t in zip(used, fit.rvecs, fit.tvecs, strict=True)]
    errors = [ViewError(v.name, float(e), len(v.corner_ids), p.tilt_deg, p.scale)
              for v, e, p in zip(used, fit.per_view_px, poses, strict=True)]
    coverage = coverage_of(used, poses, image_size)
    std = tuple(float(s) for s in fit.std[:4])
    widths = [v.edge_width_px for v in used if math.isfinite(v.edge_width_px)]
    result_warnings = warnings_of(intr, fit.rms_px, coverage, len(used), options,
                                float(np.median(widths)) if widths else math.nan)
    found = len(views) + len(rejected) if frames_with_board is None else frames_with_board
    return CalibrationResult(
        board=board, intrinsics=intr, reprojection_rms_px=fit.rms_px, views=tuple(errors),
        rejected=tuple(rejected) + tuple(dropped), coverage=coverage, std_px=std,
        frames_read=found if frames_read is None else frames_read,
        frames_with_board=found, warnings=result_warnings, skipped=tuple(skipped))


def coverage_of(views: Sequence[BoardView], poses: Sequence[BoardPose],
              image_size: tuple[int, int]) -> Coverage:
    w, h = image_size
    gx, gy = (8, 6) if w >= h else (6, 8)
    cells = np.zeros((gy, gx), bool)
    scale = 4  # the area mask at a quarter of the resolution
    mask = np.zeros((max(1, h // scale), max(1, w // scale)), np.uint8)
    for v in views:
        p = v.image_points_px
        ix = np.clip((p[:, 0] + 0.5) * gx / w, 0, gx - 1).astype(int)
        iy = np.clip((p[:, 1] + 0.5) * gy / h, 0, gy - 1).astype(int)
        cells[iy, ix] = True
        hull = cv2.convexHull((p / scale).astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
    border = np.ones_like(cells)
    border[1:-1, 1:-1] = False
    tilts = [p.tilt_deg for p in poses]
    tx = [p.tilt_xy_deg[0] for p in poses]
    ty = [p.tilt_xy_deg[1] for p in poses]
    widths = [p.scale for p in poses]
    return Coverage(
        cells_fraction=float(cells.mean()),
        border_cells_fraction=float(cells[border].mean()),
        area_fraction=float(mask.mean()), grid=(gx, gy),
        tilt_deg_min=float(min(tilts)), tilt_deg_max=float(max(tilts)),
        tilt_x_deg_range=(float(min(tx)), float(max(tx))),
        tilt_y_deg_range=(float(min(ty)), float(max(ty))),
        board_width_fraction_range=(float(min(widths)), float(max(widths))))


def warnings_of(intr: CameraIntrinsics, rms_px: float, coverage: Coverage, used: int,
              options: CalibrationOptions, edge_width_px: float) -> tuple[str, ...]:
    out = []
    if edge_width_px > 3.0:
        out.append(f"the views are blurred (edges {edge_width_px:.1f} px wide; a focused, "
                   "still camera gives 1-2 px): focus the lens, light the board better "
                   "(shorter exposure), move it slower")
    if rms_px > 1.0:
        out.append(f"reprojection RMS {rms_px:.2f} px is high (below 0.5 px is usual): is the "
                   "board flat, are --board's sizes right, was the camera in focus?")
    if coverage.border_cells_fraction < 0.5:
        out.append(f"the board reached only {coverage.border_cells_fraction:.0%} of the "
                   "image's border cells: the distortion near the edges and corners is "
                   "extrapolated; hold the board there too")
    elif coverage.cells_fraction < 0.6:
        out.append(f"the board covered only {coverage.cells_fraction:.0%} of the image: "
                   "move it all over the image, into the corners")
    if coverage.tilt_deg_max < 25.0:
        out.append(f"no view tilted more than {coverage.tilt_deg_max:.0f}°: tilt the board "
                   "30-50° in different directions; the focal length is poorly determined "
                   "from views facing the camera")
    if used < max(15, options.min_views):
        out.append(f"only {used} views: 20-40 varied ones give a steadier calibration")
    problem = distortion_problem(intr)
    if problem is not None:
        out.append(f"the distortion fitted is not a plausible lens: {problem}")
    return tuple(out)
