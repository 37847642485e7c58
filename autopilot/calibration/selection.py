"""Which views to calibrate with: sharp and varied, no near-duplicates."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from autopilot.calibration.board import BoardSpec
from autopilot.calibration.detection import BoardView


@dataclass(frozen=True, slots=True)
class CalibrationOptions:
    """How views are chosen and the camera is fitted."""

    #: At most this many views go into the fit (the most diverse of the usable ones).
    max_views: int = 40
    #: Fewer usable views than this: no calibration (:class:`CalibrationFailed`).
    min_views: int = 10
    #: Views whose edges are wider than this times the median view's are not used (see
    #: :attr:`BoardView.edge_width_px`; the limit is never below ``sharp_edge_width_px``:
    #: that sharp is sharp enough). Relative, as lenses, sensors and compression differ.
    blur_factor: float = 1.5
    sharp_edge_width_px: float = 1.8
    #: A view whose corners are, on average, within this share of the image diagonal of an
    #: already chosen view's (the same corners) adds nothing: a near-duplicate.
    duplicate_fraction: float = 0.02
    #: After a fit, views whose RMS error exceeds this times the median view's (and
    #: ``outlier_floor_px``) are dropped and the camera is fitted again (up to 3 times).
    outlier_factor: float = 3.0
    outlier_floor_px: float = 0.3
    #: Distortion model: OpenCV's k1 k2 p1 p2 k3 by default; without k3 (narrow lenses, few
    #: views); or the rational model (8 coefficients: wide-angle lenses).
    fix_k3: bool = False
    rational: bool = False


DEFAULT_OPTIONS = CalibrationOptions()


@dataclass(frozen=True, slots=True)
class Rejection:
    name: str
    reason: Literal["blurry", "duplicate", "not_needed", "outlier"]
    detail: str


@dataclass(frozen=True, slots=True, eq=False)
class Selection:
    views: tuple[BoardView, ...]
    rejected: tuple[Rejection, ...]


@dataclass(frozen=True, slots=True)
class BoardPose:
    centre_px: tuple[float, float]  # of the corners seen
    scale: float  # the whole board's width over the image's (about; the rough camera)
    tilt_deg: float  # between the board's normal and the optical axis
    tilt_xy_deg: tuple[float, float]  # about the camera's x (top towards / away) and y axes


def rough_camera(views: Sequence[BoardView], board: BoardSpec,
                  image_size: tuple[int, int]) -> np.ndarray:
    """A camera matrix from the views' homographies (principal point at the centre), good
    enough to tell views' tilts apart; a 60° lens if they do not determine it."""
    w, h = image_size
    fallback = np.array([[w * 0.866, 0.0, (w - 1) / 2.0], [0.0, w * 0.866, (h - 1) / 2.0],
                         [0.0, 0.0, 1.0]])
    obj = board.object_points_m()
    usable = [v for v in views if len(v.corner_ids) >= 6][:200]
    if len(usable) < 2:
        return fallback
    try:
        k = cv2.initCameraMatrix2D([obj[v.corner_ids] for v in usable],
                                   [v.image_points_px.astype(np.float32) for v in usable],
                                   (w, h))
    except cv2.error:
        return fallback
    f = 0.5 * (k[0, 0] + k[1, 1])
    if not (math.isfinite(f) and 0.2 * w < f < 20.0 * w):
        return fallback
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def board_pose(view: BoardView, board: BoardSpec, k: np.ndarray, dist: np.ndarray | None,
          image_size: tuple[int, int], rvec: np.ndarray | None = None,
          tvec: np.ndarray | None = None) -> BoardPose:
    """Where a view has the board: its pose as given (a fit's), or else solved for with
    camera matrix ``k`` and distortion ``dist``."""
    obj = board.object_points_m()[view.corner_ids]
    if rvec is None:
        ok, rvec, tvec = cv2.solvePnP(obj, view.image_points_px, k, dist,
                                      flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            rvec, tvec = np.zeros(3), np.array([0.0, 0.0, 1.0])
    r, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    normal = r[:, 2] * (1.0 if r[2, 2] >= 0 else -1.0)
    tilt = math.degrees(math.acos(min(1.0, abs(float(normal[2])))))
    tilt_xy = (math.degrees(math.atan2(normal[1], normal[2])),
               math.degrees(math.atan2(normal[0], normal[2])))
    outline, _ = cv2.projectPoints(board.outline_m(), rvec, tvec, k, None)
    outline = outline.reshape(-1, 2)
    width = 0.5 * (np.linalg.norm(outline[1] - outline[0])
                   + np.linalg.norm(outline[2] - outline[3]))
    centre = view.image_points_px.mean(axis=0)
    return BoardPose((float(centre[0]), float(centre[1])), float(width / image_size[0]), tilt,
                 (float(tilt_xy[0]), float(tilt_xy[1])))


def select_views(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
                 options: CalibrationOptions = CalibrationOptions()) -> Selection:
    """The views to calibrate with: sharp ones (see :class:`CalibrationOptions`), no two
    nearly the same (the sharper, fuller one kept), and of those, if more than
    ``max_views``, up to half of them for coverage (one by one, the view reaching most of the
    image not yet reached), the rest for diversity (one by one, the view farthest from those
    already chosen in position in the image, board size and tilt)."""
    rejected: list[Rejection] = []
    finite = [v.edge_width_px for v in views if math.isfinite(v.edge_width_px)]
    median = float(np.median(finite)) if finite else math.nan
    limit = max(options.sharp_edge_width_px, options.blur_factor * median) \
        if math.isfinite(median) else math.inf
    sharp = []
    for v in views:
        if math.isfinite(v.edge_width_px) and v.edge_width_px > limit:
            rejected.append(Rejection(v.name, "blurry", f"edges {v.edge_width_px:.1f} px wide "
                                      f"(limit {limit:.1f} px)"))
        else:
            sharp.append(v)

    # near-duplicates: best first (most corners, then sharpest)
    diagonal = math.hypot(*image_size)
    order = sorted(sharp, key=lambda v: (-len(v.corner_ids),
                                         v.edge_width_px if math.isfinite(v.edge_width_px)
                                         else math.inf))
    distinct: list[BoardView] = []
    lookup: list[dict[int, int]] = []
    for v in order:
        ids = {int(i): k for k, i in enumerate(v.corner_ids)}
        duplicate = None
        for other, other_ids in zip(distinct, lookup, strict=True):
            common = [i for i in ids if i in other_ids]
            if len(common) < max(4, 0.5 * min(len(ids), len(other_ids))):
                continue
            a = v.image_points_px[[ids[i] for i in common]]
            b = other.image_points_px[[other_ids[i] for i in common]]
            if float(np.linalg.norm(a - b, axis=1).mean()) < options.duplicate_fraction * diagonal:
                duplicate = other
                break
        if duplicate is not None:
            rejected.append(Rejection(v.name, "duplicate", f"nearly the same as "
                                      f"{duplicate.name}"))
        else:
            distinct.append(v)
            lookup.append(ids)

    if len(distinct) <= options.max_views:
        return Selection(tuple(distinct), tuple(rejected))
    # first, coverage: one by one, the view whose corners fall in most cells of a fine grid
    # that no chosen view reaches yet (the image's edges and corners are where the lens model
    # is otherwise extrapolated), for up to half the views
    w, h = image_size
    gx, gy = 16, 12
    cells = np.zeros((len(distinct), gx * gy), bool)
    for i, v in enumerate(distinct):
        p = v.image_points_px
        ix = np.clip((p[:, 0] + 0.5) * gx / w, 0, gx - 1).astype(int)
        iy = np.clip((p[:, 1] + 0.5) * gy / h, 0, gy - 1).astype(int)
        cells[i, iy * gx + ix] = True
    chosen: list[int] = []
    covered = np.zeros(gx * gy, bool)
    while len(chosen) < options.max_views // 2:
        gain = (cells & ~covered).sum(axis=1)
        best = int(np.argmax(gain))  # ties: the earlier, fuller view
        if gain[best] == 0:
            break
        chosen.append(best)
        covered |= cells[best]
    # then diversity of pose: each next view the farthest from those chosen in position in
    # the image, board size and tilt (farthest-point sampling)
    k = rough_camera(distinct, board, image_size)
    poses = [board_pose(v, board, k, None, image_size) for v in distinct]
    features = np.array([[p.centre_px[0] / w, p.centre_px[1] / h, p.scale,
                          p.tilt_xy_deg[0] / 60.0, p.tilt_xy_deg[1] / 60.0] for p in poses])
    chosen = chosen or [0]  # (no coverage pick: the fullest view; the list is sorted so)
    nearest = np.min(np.linalg.norm(features[:, None, :] - features[None, chosen, :], axis=2),
                     axis=1)
    while len(chosen) < options.max_views:
        nxt = int(np.argmax(nearest))
        chosen.append(nxt)
        nearest = np.minimum(nearest, np.linalg.norm(features - features[nxt], axis=1))
    keep = set(chosen)
    for i, v in enumerate(distinct):
        if i not in keep:
            rejected.append(Rejection(v.name, "not_needed", f"{options.max_views} more "
                                      "diverse views were enough"))
    return Selection(tuple(distinct[i] for i in sorted(keep)), tuple(rejected))
