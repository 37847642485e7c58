"""Keep-out discs (seed 001's colour semantics: red = land here, *blue = keep away*): flat discs
of one colour on the ground, found in whatever frames the running step's cameras deliver, and
placed on the ground.

**Detection** (:class:`DiscDetector`, in the detection executor): an HSV threshold (the
colour's preset of :mod:`autopilot.perception.colors`, or explicit ranges), an opening and a
closing against the camera's read noise and the codec's blocky chroma, then every external
contour large enough and convex enough (a disc seen from any angle is an ellipse: its blob
fills its convex hull) is a candidate: its outline, minus the points where the frame's border
cuts it, undistorted into normalised coordinates. Nothing about size or shape beyond that is
judged in the image: an oblique view squashes a disc into a thin ellipse, which only the ground
can tell from a blue stripe.

**Ground projection** (:func:`ground_circle`, on the loop, with the pose at the frame's capture
time): each outline point's ray, turned into the world with the camera's mount and the
vehicle's attitude, meets the ground plane (NED down ``ground_down_m``); the circle fitted to
those ground points is the disc — a disc on a plane projects back onto that plane as the
circle it is, at any tilt — and its residual, its radius and the arc of it that was seen say
whether it was one (:func:`accept`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from autopilot.estimation.pose_history import Pose
from autopilot.perception.colors import HsvRange, color_mask, inner_outline
from autopilot.perception.pad import fit_circle
from drivers.base import CameraInfo
from drivers.camera_model import undistort_points
from drivers.geometry import quat_to_matrix


@dataclass(frozen=True, slots=True)
class DiscSettings:
    hsv_ranges: tuple[HsvRange, ...]
    min_area_px: float = 30.0  # blobs smaller than this are noise (or too far to place)
    min_solidity: float = 0.85  # blob area ÷ its convex hull's (a disc's image is convex)
    open_kernel_px: int = 3  # morphology: specks of read noise out
    close_kernel_px: int = 5  # ... and the codec's holes filled
    min_arc_points: int = 10  # outline points off the frame's border
    border_px: int = 2
    max_blobs: int = 8  # the largest this many per frame


@dataclass(frozen=True, slots=True, eq=False)
class DiscBlob:
    """One candidate disc in a frame."""

    center_px: tuple[float, float]  # the blob's centroid (in the distorted frame)
    area_px: float
    #: its outline not cut by the frame's border, undistorted normalised coordinates (N × 2)
    outline_norm: np.ndarray
    clipped: bool  # the frame's border cuts it


@dataclass(frozen=True, slots=True, eq=False)
class DiscDetection:
    """The candidate discs of one frame, largest first."""

    time_s: float
    blobs: tuple[DiscBlob, ...]


class DiscDetector:
    """Blobs of the keep-out colour that may be discs (see the module's notes). Synchronous
    and stateless between frames: safe to run off the loop."""

    def __init__(self, settings: DiscSettings) -> None:
        self.settings = s = settings
        self._open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (s.open_kernel_px,) * 2)
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (s.close_kernel_px,) * 2)

    def mask(self, image_bgr: np.ndarray) -> np.ndarray:
        return color_mask(image_bgr, self.settings.hsv_ranges, self._open, self._close)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> DiscDetection | None:
        s = self.settings
        mask = self.mask(image_bgr)
        h, w = mask.shape
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        found: list[DiscBlob] = []
        for contour in contours:
            area = cv2.contourArea(contour)
            if area < s.min_area_px:
                continue
            hull = cv2.contourArea(cv2.convexHull(contour))
            if hull <= 0 or area / hull < s.min_solidity:
                continue
            pts = contour.reshape(-1, 2).astype(np.float64)
            arc, clipped = inner_outline(contour, w, h, s.border_px, 300)
            if len(arc) < s.min_arc_points:
                continue
            m = cv2.moments(contour)
            centre = (m["m10"] / m["m00"], m["m01"] / m["m00"]) if m["m00"] > 0 \
                else tuple(pts.mean(axis=0))
            found.append(DiscBlob((float(centre[0]), float(centre[1])), float(area),
                                  undistort_points(camera.intrinsics, arc),
                                  clipped))
        if not found:
            return None
        found.sort(key=lambda blob: -blob.area_px)
        return DiscDetection(time_s, tuple(found[:s.max_blobs]))


# -- on the ground -------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class GroundCircle:
    """A candidate disc placed on the ground plane (local NED)."""

    centre_ne_m: np.ndarray  # (north, east)
    radius_m: float
    fit_error: float  # RMS radial residual ÷ radius
    arc_deg: float  # how much of its outline was seen (360: all of it)
    range_m: float  # from the camera to its centre
    height_m: float  # of the camera above the ground

    @property
    def std_m(self) -> float:
        """How far off its centre may be, per degree of pointing error: the slant range²
        over the height (the depression angle's leverage on the ground), at least 1 cm."""
        return max(0.01, math.radians(1.0) * self.range_m ** 2 / max(self.height_m, 0.05))


def ground_points(points_norm: np.ndarray, camera: CameraInfo, pose: Pose,
                  ground_down_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Where normalised image points' rays meet the ground plane at NED down
    ``ground_down_m``: the points (N × 2, north and east; NaN for a ray that does not come
    down to it), the camera's position (NED), and its height above the plane."""
    r_world_body = quat_to_matrix(pose.attitude_q)
    cam = np.asarray(pose.position_ned_m, float) + r_world_body @ camera.position_body_m
    r_world_cam = r_world_body @ camera.rotation_body_cam
    n = np.atleast_2d(np.asarray(points_norm, float))
    rays = r_world_cam @ np.column_stack([n, np.ones(len(n))]).T  # 3 × N
    height = ground_down_m - cam[2]
    out = np.full((len(n), 2), np.nan)
    down = rays[2] > 1e-3  # (a ray at or above the horizon never meets the ground)
    if height > 0.02 and down.any():
        t = height / rays[2, down]
        out[down] = (cam[:2, None] + rays[:2, down] * t).T
    return out, cam, height


def ground_circle(blob: DiscBlob, camera: CameraInfo, pose: Pose,
                  ground_down_m: float = 0.0) -> GroundCircle | None:
    """``blob``'s outline on the ground plane and the circle fitted there (None: too little
    of it comes down to the ground)."""
    points, cam, height = ground_points(blob.outline_norm, camera, pose, ground_down_m)
    ok = np.isfinite(points[:, 0])
    if ok.sum() < max(6, 0.9 * len(points)):
        return None  # (part of it is at or above the horizon: not on the ground)
    points = points[ok]
    centre, radius, rms = fit_circle(points)
    if not math.isfinite(radius) or radius <= 1e-6:
        return None
    angles = np.sort(np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0]))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2.0 * math.pi]))
    arc = 360.0 - math.degrees(float(gaps.max()))
    slant = math.sqrt(float(np.sum((centre - cam[:2]) ** 2)) + height ** 2)
    return GroundCircle(np.asarray(centre, float), float(radius), rms / radius, arc, slant,
                        height)


@dataclass(frozen=True, slots=True)
class DiscAcceptance:
    """What a ground circle must be to count as a keep-out disc."""

    min_radius_m: float = 0.1
    max_radius_m: float = 2.0
    max_fit_error: float = 0.12
    min_arc_deg: float = 200.0  # a short arc fits any circle
    max_range_m: float = 12.0


def accept(circle: GroundCircle, rules: DiscAcceptance) -> str | None:
    """Why ``circle`` is not a keep-out disc (None: it is)."""
    if not rules.min_radius_m <= circle.radius_m <= rules.max_radius_m:
        return f"radius {circle.radius_m:.2f} m"
    if circle.fit_error > rules.max_fit_error:
        return f"not a circle on the ground ({circle.fit_error:.2f})"
    if circle.arc_deg < rules.min_arc_deg:
        return f"only {circle.arc_deg:.0f}° of it seen"
    if circle.range_m > rules.max_range_m:
        return f"{circle.range_m:.1f} m away"
    return None
