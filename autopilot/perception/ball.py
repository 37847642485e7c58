"""Coloured-ball detection (seeds 001 and 003, done properly).

HSV thresholds (several ranges, so red can wrap around hue 0) → morphological opening and
closing → external contours → shape checks (circularity, fill of the enclosing circle, and
enough vertices when the outline is simplified: a cube seen corner-on is a fairly round hexagon)
→ an ellipse fit per candidate. A sphere seen off
the optical axis images as an ellipse elongated radially; its minor semi-axis, with the angle
off-axis, gives the sphere's angular radius exactly, hence the range from the known diameter.
Blobs cut by the image border are fitted on their interior contour points only. A blob that
fails the shape checks may be the ball merged with something of the same colour behind or
beside it: circles refitted around its largest inscribed circles are accepted where the blob's
outline follows them unbroken most of the way round (true of a ball with a box touching it,
which hides one stretch of its outline; not of a box alone, whose inscribed circle meets the
outline in several short stretches); where the tracker expects a ball of that size, half its
outline is enough (a ball in front of a box of its colour). Each candidate's radius is then
moved from the mask's outline to the ball's edge (the colour halfway between the ball's and
the background's): the mask keeps blended pixels down to about a third ball.

Data flow: a camera :class:`~drivers.base.Frame` goes in; a :class:`BallDetection` (or None)
comes out, in the camera's optical frame. Synchronous and stateless apart from its settings;
the runtime calls it in an executor.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from drivers.base import CameraInfo
from drivers.camera_model import is_distorted, undistort_points

HsvRange = tuple[tuple[int, int, int], tuple[int, int, int]]


@dataclass(frozen=True, slots=True)
class BallDetectorSettings:
    hsv_ranges: tuple[HsvRange, ...]
    diameter_m: float
    open_kernel_px: int = 3
    close_kernel_px: int = 5
    min_radius_px: float = 3.0
    max_radius_px: float = 240.0
    min_circularity: float = 0.8
    min_fill_ratio: float = 0.75
    #: a blob covering at least this much of its convex hull is judged as its hull (a ball is
    #: convex: a specular highlight or a shadow outside the colour range only bites its edge);
    #: 1: never
    min_solidity: float = 0.85
    max_axis_ratio: float = 1.6  # major/minor beyond what a sphere off-axis can produce
    min_polygon_vertices: int = 8  # of the outline simplified to 2 % of its length
    min_edge_arc: float = 0.75  # merged blobs: fraction of the circle the outline follows ...
    max_edge_gaps: int = 2  # ... broken in at most this many places
    #: where the tracker expects the ball (its place and size), a merged blob's circle counts
    #: with this much of its outline: a ball passing in front of something of its colour
    #: shows little more than half its edge (the rest lies against the other's face)
    min_tracked_edge_arc: float = 0.5
    tracked_radius_tolerance: float = 0.25  # … if its radius is the expected one within this


@dataclass(frozen=True, slots=True)
class BallCandidate:
    u_px: float
    v_px: float
    radius_px: float  # apparent radius (minor semi-axis of the fitted ellipse)
    circularity: float
    fill_ratio: float
    cut_by_border: bool
    merged: bool = False  # recovered from a blob merged with something else
    #: how far the ball's edge (where a pixel's colour is halfway between the ball's and the
    #: ground's) lies from the mask's outline, already added to ``radius_px``
    #: (see :func:`_edge_offset`)
    edge_offset_px: float = 0.0
    #: the outline points the fit used (image pixels), to refit in the undistorted image
    outline: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def score(self) -> float:
        penalty = (0.8 if self.cut_by_border else 1.0) * (0.9 if self.merged else 1.0)
        return self.circularity * self.fill_ratio * penalty


@dataclass(frozen=True, slots=True, eq=False)
class BallDetection:
    """A ball found in one frame. Position and bearing are in the camera's optical frame."""

    time_s: float  # the frame's capture time
    camera: str
    u_px: float
    v_px: float
    radius_px: float
    range_m: float
    position_cam_m: np.ndarray
    score: float
    candidates: int  # how many blobs passed the shape checks
    cut_by_border: bool
    others: tuple[BallCandidate, ...] = field(default=())

    def __post_init__(self) -> None:
        arr = np.array(self.position_cam_m, dtype=float)
        arr.flags.writeable = False
        object.__setattr__(self, "position_cam_m", arr)


class BallDetector:
    def __init__(self, settings: BallDetectorSettings) -> None:
        self.settings = settings
        self._open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (settings.open_kernel_px,) * 2)
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE,
                                                (settings.close_kernel_px,) * 2)

    def mask(self, image_bgr: np.ndarray) -> np.ndarray:
        """Binary mask of pixels in the colour ranges, cleaned by opening and closing."""
        hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
        mask = None
        for lo, hi in self.settings.hsv_ranges:
            part = cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
            mask = part if mask is None else cv2.bitwise_or(mask, part)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._open)
        return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._close)

    def candidates(self, image_bgr: np.ndarray,
                   window: tuple[int, int, int, int] | None = None,
                   min_edge_arc: float | None = None) -> list[BallCandidate]:
        """Every blob that looks like a ball, best first (image coordinates).

        With a ``window`` (x0, y0, x1, y1) only that part of the image is searched, and only
        balls lying wholly inside it count (one cut by the window's edge would be mis-fitted).
        ``min_edge_arc``: how much of a merged blob's circle its outline must follow (default:
        the settings')."""
        s = self.settings
        height, width = image_bgr.shape[:2]
        x0, y0 = 0, 0
        if window is not None:
            x0, y0, x1, y1 = window
            mask = self.mask(image_bgr[y0:y1, x0:x1])
        else:
            mask = self.mask(image_bgr)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE,
                                       offset=(x0, y0))
        found = []
        min_area = math.pi * s.min_radius_px ** 2 * 0.5
        for contour in contours:
            area = cv2.contourArea(contour)
            if area < min_area or len(contour) < 6:
                continue
            candidate = self._whole_blob(contour, area, width, height)
            if candidate is not None:
                found.append(candidate)
            elif area > 4.0 * min_area:
                found.extend(self._merged_balls(contour, width, height,
                                                s.min_edge_arc if min_edge_arc is None
                                                else min_edge_arc))
        if window is not None:
            found = [c for c in found if _inside(c, window, width, height)]
        found = [_at_edge(image_bgr, c) for c in found]
        found.sort(key=lambda c: c.score, reverse=True)
        return found

    def _whole_blob(self, contour: np.ndarray, area: float, width: int,
                    height: int) -> BallCandidate | None:
        """The blob as one ball, if it passes the shape checks."""
        s = self.settings
        outline = None  # the outline's points the fit may use (all of them unless bitten)
        if s.min_solidity < 1.0:
            hull_idx = cv2.convexHull(contour, returnPoints=False)
            hull = contour[hull_idx.ravel()]
            hull_area = cv2.contourArea(hull)
            if area >= s.min_solidity * hull_area:
                on_hull = _off_bites(contour, hull_idx)
                if on_hull is not None:
                    # bitten: judged as its hull, fitted to the outline where it is the
                    # hull's (the bite's edge is not the ball's)
                    outline = contour.reshape(-1, 2)[on_hull]
                    contour, area = hull, hull_area
        pts = contour.reshape(-1, 2)
        on_border = _on_border(pts, width, height)
        cut = bool(on_border.any())
        if outline is not None:  # the bitten blob's outline, where it is the ball's
            pts = outline
            on_border = _on_border(pts, width, height)
        if cut:
            inner = pts[~on_border]
            if len(inner) < 0.4 * len(pts) or len(inner) < 8:
                return None  # too little of the outline is visible to fit
            fit_pts = inner.astype(np.float32)
        else:
            fit_pts = pts.astype(np.float32)
        if len(fit_pts) < 6:
            return None
        (cu, cv_), (ax1, ax2), _ = cv2.fitEllipse(fit_pts)
        # contour points are pixel centres on the blob's edge: half a pixel inside it
        major, minor = max(ax1, ax2) / 2.0 + 0.5, min(ax1, ax2) / 2.0 + 0.5
        if not s.min_radius_px <= minor <= s.max_radius_px or major / minor > s.max_axis_ratio:
            return None
        perimeter = cv2.arcLength(contour, True)
        if cut:
            circularity = 1.0 - _circle_fit_residual(fit_pts, cu, cv_, major, minor)
            ellipse_area = math.pi * major * minor
            visible = max(_visible_fraction(cu, cv_, major, width, height), 1e-6)
            fill = min(1.0, (area + 0.5 * perimeter) / ellipse_area / visible)
        else:
            circularity = min(1.0, 4.0 * math.pi * area / (perimeter * perimeter)
                              * _pixel_circularity_correction(minor))
            # against the smallest enclosing circle: ~1 for a ball (≥ 0.87 off-axis), 0.64 for
            # a square, far less for poles and bars
            _, enclosing = cv2.minEnclosingCircle(contour)
            fill = min(1.0, (area + 0.5 * perimeter) / (math.pi * (enclosing + 0.5) ** 2))
        if circularity < s.min_circularity or fill < s.min_fill_ratio:
            return None
        # a round outline reduces to many vertices, a cube's hexagon or square to few (below
        # about 6 px of radius even a circle reduces to few: the test says nothing there)
        if not cut and minor >= 6.0 and len(cv2.approxPolyDP(contour, 0.02 * perimeter, True)) \
                < s.min_polygon_vertices:
            return None
        return BallCandidate(cu, cv_, minor, circularity, fill, cut, outline=fit_pts)

    def _merged_balls(self, contour: np.ndarray, width: int, height: int,
                      min_edge_arc: float) -> list[BallCandidate]:
        """Balls inside a blob that is not one (a ball with something of its colour touching
        it). Try the blob's largest inscribed circles in turn: refit a circle to the outline
        points near each, and keep it if those points go most of the way round."""
        s = self.settings
        x, y, w, h = cv2.boundingRect(contour)
        blob = np.zeros((h + 4, w + 4), np.uint8)
        cv2.drawContours(blob, [contour], -1, 255, cv2.FILLED, offset=(2 - x, 2 - y))
        inside = cv2.distanceTransform(blob, cv2.DIST_L2, 5)
        pts = contour.reshape(-1, 2).astype(np.float64)
        found = []
        for _ in range(3):
            _, r_in, _, (px, py) = cv2.minMaxLoc(inside)
            if r_in + 0.5 < 2.0 * s.min_radius_px:
                break  # too small to tell a circle from a corner
            cv2.circle(inside, (px, py), math.ceil(1.2 * r_in), 0, cv2.FILLED)
            circle = self._circle_around(pts, px + x - 2.0, py + y - 2.0, r_in + 0.5)
            if circle is None:
                continue
            cu, cv_, radius, arc, gaps, outline = circle
            if arc < min_edge_arc or gaps > s.max_edge_gaps or radius > s.max_radius_px:
                continue
            cut = cu - radius < 0 or cv_ - radius < 0 or cu + radius > width - 1 or \
                cv_ + radius > height - 1
            found.append(BallCandidate(float(cu), float(cv_), float(radius), arc, 1.0, cut,
                                       merged=True, outline=outline))
        return found

    @staticmethod
    def _circle_around(pts: np.ndarray, cu: float, cv_: float,
                       radius: float
                       ) -> tuple[float, float, float, float, int, np.ndarray] | None:
        """Refit a circle to the outline points near a starting circle; its centre, radius,
        the fraction of it that outline points follow (in 10° sectors) and in how many places
        that is broken. Something touching a ball hides one stretch of its outline, a pole
        across it two; a polygon's inscribed circle meets the outline in several short
        stretches."""
        for tolerance in (2.0, 1.2, 1.0):
            near = np.abs(np.hypot(pts[:, 0] - cu, pts[:, 1] - cv_) - radius) < \
                max(tolerance, 0.08 * radius)
            if near.sum() < 8:
                return None
            cu, cv_, radius = _fit_circle(pts[near])
        off = np.hypot(pts[:, 0] - cu, pts[:, 1] - cv_) - radius
        on = np.abs(off) < max(0.7, 0.05 * radius)
        angles = np.arctan2(pts[on, 1] - cv_, pts[on, 0] - cu)
        covered = np.zeros(36, dtype=bool)
        covered[((angles + math.pi) / (2.0 * math.pi) * 36).astype(int) % 36] = True
        # outline points are pixel centres, half a pixel inside the edge
        return cu, cv_, radius + 0.5, float(covered.mean()), _circular_gaps(covered), pts[on]

    def _window(self, image_bgr: np.ndarray, centre: Sequence[float],
                radius_px: float | None) -> tuple[int, int, int, int] | None:
        height, width = image_bgr.shape[:2]
        u, v = centre
        if not (0 <= u < width and 0 <= v < height):
            return None
        half = max(48.0, 3.0 * (radius_px or 0.0))
        x0, y0 = max(0, int(u - half)), max(0, int(v - half))
        x1, y1 = min(width, int(u + half) + 1), min(height, int(v + half) + 1)
        return x0, y0, x1, y1

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               predicted_uv: Sequence[float] | None = None,
               predicted_radius_px: float | None = None) -> BallDetection | None:
        """The ball in a frame, or None.

        With a prediction (where the tracker expects the ball, and how big), a window around it
        is searched first and the whole image only if that finds nothing conclusive; the
        candidate nearest the prediction wins. Without one, the most ball-like candidate."""
        found: list[BallCandidate] = []
        window = None
        if predicted_uv is not None:
            window = self._window(image_bgr, predicted_uv, predicted_radius_px)
            found = self.candidates(image_bgr, window)
        if not found:
            found = self.candidates(image_bgr)
        if not found and window is not None and predicted_radius_px:
            found = self._tracked(image_bgr, window, predicted_uv, predicted_radius_px)
        if not found:
            return None
        if predicted_uv is not None:
            pu, pv = predicted_uv
            best = min(found, key=lambda c: math.hypot(c.u_px - pu, c.v_px - pv))
        else:
            best = found[0]
        position = self._position(camera, best)
        return BallDetection(
            time_s=time_s,
            camera=camera.name,
            u_px=best.u_px,
            v_px=best.v_px,
            radius_px=best.radius_px,
            range_m=float(np.linalg.norm(position)),
            position_cam_m=position,
            score=best.score,
            candidates=len(found),
            cut_by_border=best.cut_by_border,
            others=tuple(c for c in found if c is not best),
        )


    def _tracked(self, image_bgr: np.ndarray, window: tuple[int, int, int, int],
                 predicted_uv: Sequence[float], predicted_radius_px: float
                 ) -> list[BallCandidate]:
        """The ball where the tracker expects it, merged with something of its colour and
        showing less of its edge than an unexpected ball must: a circle of the expected size
        near the expected place (within its radius)."""
        s = self.settings
        pu, pv = predicted_uv
        return [c for c in self.candidates(image_bgr, window, s.min_tracked_edge_arc)
                if c.merged and abs(c.radius_px - predicted_radius_px)
                <= s.tracked_radius_tolerance * predicted_radius_px
                and math.hypot(c.u_px - pu, c.v_px - pv) <= predicted_radius_px]

    def _position(self, camera: CameraInfo, c: BallCandidate) -> np.ndarray:
        """The ball's centre in the optical frame. Through a distorting lens the outline is
        undistorted first and fitted again: the apparent size (hence the range) is that of
        the ideal pinhole image, not the lens-squeezed one (3.5 % of range at the edges of a
        mild barrel lens)."""
        intr = camera.intrinsics
        diameter = self.settings.diameter_m
        if not is_distorted(intr) or c.outline is None or len(c.outline) < 6:
            return ball_position(camera, c.u_px, c.v_px, c.radius_px, diameter)
        ideal = undistort_points(intr, np.asarray(c.outline, np.float64), to_pixels=True)
        if c.merged:
            cu, cv_, radius = _fit_circle(ideal)
            radius += 0.5
        else:
            (cu, cv_), (ax1, ax2), _ = cv2.fitEllipse(ideal.astype(np.float32))
            radius = min(ax1, ax2) / 2.0 + 0.5
        radius += c.edge_offset_px  # (the lens scales it by < 1 % over a ball's size)
        x, y = (cu - intr.cx) / intr.fx, (cv_ - intr.cy) / intr.fy
        return sphere_position(x, y, radius, math.sqrt(intr.fx * intr.fy), diameter)


def _on_border(pts: np.ndarray, width: int, height: int) -> np.ndarray:
    """Which outline points lie on the image's border (the blob is cut there)."""
    return (pts[:, 0] <= 0) | (pts[:, 1] <= 0) | (pts[:, 0] >= width - 1) | \
        (pts[:, 1] >= height - 1)


#: a dent in an outline deeper than this is a bite, not the pixel staircase of a round edge
#: (a digitised disc's staircase dents by at most 0.6–0.9 px, growing with its radius)
BITE_DEPTH_PX = 1.0


def _off_bites(contour: np.ndarray, hull_idx: np.ndarray | None = None) -> np.ndarray | None:
    """Which of the outline's points lie on its convex hull (``hull_idx``: its indices into
    the outline, if already found) — within 1 px of the chord across each dent deeper than
    :data:`BITE_DEPTH_PX`; None if it has no such dent."""
    if hull_idx is None:
        hull_idx = cv2.convexHull(contour, returnPoints=False)
    try:
        defects = cv2.convexityDefects(contour, hull_idx)
    except cv2.error:  # a self-intersecting outline: no hull to judge it by
        return None
    if defects is None:
        return None
    defects = defects.reshape(-1, 4)  # (start, end, farthest, depth × 256) per dent
    deep = defects[defects[:, 3] > BITE_DEPTH_PX * 256.0]
    if len(deep) == 0:
        return None
    pts = contour.reshape(-1, 2).astype(np.float64)
    n = len(pts)
    keep = np.ones(n, bool)
    for start, end, _, _ in deep:
        idx = np.arange(start, end + (n if end < start else 0) + 1) % n
        a, b = pts[start], pts[end]
        chord = b - a
        length = float(np.hypot(*chord))
        if length < 1e-9:
            continue
        rel = pts[idx] - a
        dist = np.abs(chord[0] * rel[:, 1] - chord[1] * rel[:, 0]) / length
        keep[idx[dist > 1.0]] = False
    return keep


def _circular_gaps(flags: np.ndarray) -> int:
    """How many runs of False a circular sequence of flags has."""
    return int(np.count_nonzero(~flags & np.roll(flags, 1))) if flags.any() else 1


#: the edge is looked for this far (px) either side of the mask's outline
EDGE_SEARCH_PX = 3.0
#: … where the colour changes by at least this much (BGR distance) from inside to outside (a
#: clear edge against the background, not against something of the ball's colour)
EDGE_MIN_CONTRAST = 60.0
#: smaller balls are left as their mask gives them: the search would reach across the ball,
#: whose shaded limb then reads as background
EDGE_MIN_RADIUS_PX = 6.0


def _edge_offset(image_bgr: np.ndarray, c: BallCandidate) -> float | None:
    """How far (px, outwards positive) the ball's edge lies from its mask's outline.

    The mask keeps every pixel still saturated enough, so a blended edge pixel that is only a
    third ball is in it: on an antialiased disc of radius 16 px the outline lies 0.2 px outside
    the edge, 0.5 px with a pixel of blur, and the range comes out 1–3 % short. Along the
    outward normal at up to 48 outline points, each pixel's colour is placed between the
    ball's just inside and the background's just outside (a blend is linear in colour, so
    halfway is where the edge cuts the pixel); the median of where that crosses one half is
    the offset. None without enough clear edge (a ball against something of its colour)."""
    if c.outline is None or len(c.outline) < 8 or c.radius_px < EDGE_MIN_RADIUS_PX:
        return None
    pts = np.asarray(c.outline, np.float64)
    pts = pts[:: max(1, len(pts) // 48)]
    normal = pts - (c.u_px, c.v_px)
    length = np.hypot(normal[:, 0], normal[:, 1])
    keep = length > 1.0
    pts, normal = pts[keep], normal[keep] / length[keep, None]
    if len(pts) < 8:
        return None
    height, width = image_bgr.shape[:2]
    r = c.radius_px + EDGE_SEARCH_PX + 2.0
    x0, y0 = max(0, int(c.u_px - r)), max(0, int(c.v_px - r))
    x1, y1 = min(width, int(c.u_px + r) + 2), min(height, int(c.v_px + r) + 2)
    if x1 - x0 < 2 or y1 - y0 < 2:
        # a fit whose centre lies off the image (a sliver at its border): nothing to measure
        # (cv2.remap refuses an empty crop; its error failed the step once)
        return None
    crop = image_bgr[y0:y1, x0:x1].astype(np.float32)
    # outline points are pixel centres half a pixel inside the mask's edge
    steps = np.arange(-EDGE_SEARCH_PX, EDGE_SEARCH_PX + 1e-9, 0.25) + 0.5
    at = pts[:, None, :] + normal[:, None, :] * steps[None, :, None] - (x0, y0)
    profile = cv2.remap(crop, at[..., 0].astype(np.float32), at[..., 1].astype(np.float32),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)  # (points, steps, 3)
    inner, outer = profile[:, :4].mean(axis=1), profile[:, -4:].mean(axis=1)
    span = inner - outer
    contrast = np.sqrt((span * span).sum(axis=1))
    clear = contrast >= EDGE_MIN_CONTRAST
    if clear.sum() < 8:
        return None
    # how much ball each sample is: 1 inside, 0 outside
    share = ((profile[clear] - outer[clear, None, :]) * span[clear, None, :]).sum(axis=2) \
        / (contrast[clear, None] ** 2)
    below = share < 0.5
    first = np.argmax(below, axis=1)  # the first sample past the edge
    ok = below.any(axis=1) & (first > 0)
    if ok.sum() < 8:
        return None
    rows = np.nonzero(ok)[0]
    a, b = share[rows, first[rows] - 1], share[rows, first[rows]]
    frac = (a - 0.5) / np.maximum(a - b, 1e-6)
    crossing = steps[first[rows] - 1] + 0.25 * frac - 0.5
    return float(np.clip(np.median(crossing), -1.5, 1.5))


def _at_edge(image_bgr: np.ndarray, c: BallCandidate) -> BallCandidate:
    """The candidate with its radius moved to the ball's edge (:func:`_edge_offset`)."""
    offset = _edge_offset(image_bgr, c)
    if offset is None:
        return c
    return replace(c, radius_px=c.radius_px + offset, edge_offset_px=offset)


def _inside(c: BallCandidate, window: tuple[int, int, int, int], width: int,
            height: int) -> bool:
    """Is the candidate clear of the window's edges (image edges excepted)?"""
    x0, y0, x1, y1 = window
    r = c.radius_px + 1.0
    return ((x0 == 0 or c.u_px - r >= x0) and (y0 == 0 or c.v_px - r >= y0)
            and (x1 == width or c.u_px + r <= x1 - 1) and (y1 == height or c.v_px + r <= y1 - 1))


def _fit_circle(points: np.ndarray) -> tuple[float, float, float]:
    """Least-squares (Kåsa) circle through points: centre and radius."""
    a = np.column_stack((points[:, 0], points[:, 1], np.ones(len(points))))
    b = -(points[:, 0] ** 2 + points[:, 1] ** 2)
    d, e, f = np.linalg.lstsq(a, b, rcond=None)[0]
    cu, cv_ = -d / 2.0, -e / 2.0
    return cu, cv_, math.sqrt(max(cu * cu + cv_ * cv_ - f, 0.0))


def ball_position(camera: CameraInfo, u_px: float, v_px: float, radius_px: float,
                  diameter_m: float) -> np.ndarray:
    """Centre of a sphere of known diameter in the optical frame, from its image.

    For a sphere of angular radius α seen at angle θ off the optical axis, the image is an
    ellipse whose minor semi-axis is b = f·sin α / √(cos²θ − sin²α); hence
    sin α = b·cos θ / √(f² + b²) and the range is R / sin α.
    """
    intr = camera.intrinsics
    x, y = undistort_points(intr, (u_px, v_px))
    return sphere_position(float(x), float(y), radius_px, math.sqrt(intr.fx * intr.fy),
                           diameter_m)


def sphere_position(x: float, y: float, radius_px: float, f_px: float,
                    diameter_m: float) -> np.ndarray:
    """A sphere's centre from its ideal (pinhole) image: the centre's normalised coordinates
    (x, y) and the ellipse's minor semi-axis ``radius_px``, with focal length ``f_px``."""
    direction = np.array([x, y, 1.0])
    direction /= np.linalg.norm(direction)
    cos_theta = direction[2]
    sin_alpha = radius_px * cos_theta / math.sqrt(f_px * f_px + radius_px * radius_px)
    return direction * (diameter_m / 2.0) / sin_alpha


def _pixel_circularity_correction(radius_px: float) -> float:
    """Pixelated discs have a jagged, longer outline: 4πA/P² of a digitised circle of radius r
    is below 1 by roughly 1/(1 + 1.5/r); undo that so the threshold means the same at any size."""
    return 1.0 + 1.5 / max(radius_px, 1.0)


def _circle_fit_residual(points: np.ndarray, cu: float, cv_: float, major: float,
                         minor: float) -> float:
    """RMS distance of points from the fitted outline, relative to the radius."""
    radius = 0.5 * (major + minor)
    d = np.hypot(points[:, 0] - cu, points[:, 1] - cv_) - (radius - 0.5)
    return float(np.sqrt(np.mean(d * d)) / radius)


def _visible_fraction(cu: float, cv_: float, radius: float, width: int, height: int) -> float:
    """Fraction of a disc's area inside the image (sampled on a coarse grid)."""
    g = np.linspace(-1.0, 1.0, 21)
    gx, gy = np.meshgrid(g, g)
    inside_disc = gx * gx + gy * gy <= 1.0
    x, y = cu + gx * radius, cv_ + gy * radius
    inside_img = (x >= 0) & (x <= width - 1) & (y >= 0) & (y <= height - 1)
    return float((inside_disc & inside_img).sum() / inside_disc.sum())
