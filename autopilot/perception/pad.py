"""Landing pads seen by the down camera (seed 001): a coloured circle, or a nested marker pad.

**Circle pad** (seed 001: red = land here, blue = keep away). A disc of one colour, ``size_m``
across, printed on a white square a quarter larger. Found by colour (the HSV ranges of
:mod:`autopilot.perception.colors`), not by template: it is the same at every scale and angle.
Each blob's outline, minus the points where the frame's border cuts it, is undistorted and fitted
with a circle, so a pad that overflows the frame near the ground is still measured from the arc
that shows. The detector gives the centre's direction and a range from the apparent size; the
pipeline then places the outline on the ground with the vehicle's attitude and the rangefinder's
height and fits the circle there (exact for a tilted camera; the size check rejects blobs of the
right colour but the wrong size).

**Marker pad** (``markers``): a white square ``size_m`` wide carrying five fiducial markers of
one dictionary — four large ones around the centre (each 0.34 of the pad, readable from far up)
and a small one in the middle (0.1 of the pad, readable when the camera is a few tens of
centimetres above it and the large ones have left the frame). Every marker of the pad that is
seen adds its four corners to one PnP solve for the pad's pose (centre and heading of its top).

Both give a :class:`PadDetection`; the pad's frame is an image's: x to its right, y towards its
bottom edge, z into the ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from autopilot.perception.colors import COLORS, HsvRange, color_mask, inner_outline
from autopilot.perception.image_target import planar_pose
from autopilot.perception.marker import MarkerDetector, MarkerDetectorSettings
from drivers.base import CameraInfo
from drivers.camera_model import distortion_coefficients, project_points, undistort_points
from drivers.markers import aruco_dictionary

PadKind = Literal["circle", "markers"]
PAD_KINDS: tuple[str, ...] = ("circle", "markers")

#: the white square around a circle pad, relative to the disc's diameter
CIRCLE_BOARD_RATIO = 1.25
#: the marker pad's layout, relative to its side: the large markers' side and centre offset,
#: the small centre marker's side
_LARGE, _OFFSET, _SMALL = 0.34, 0.26, 0.10
#: texels across a marker pad's texture (the layout is rounded to whole marker cells of it)
_PAD_TEXELS = 1800


# -- the pads themselves (what the simulator prints, what the detectors look for) ---------------


@dataclass(frozen=True, slots=True)
class PadMarker:
    marker_id: int
    center_m: tuple[float, float]  # in the pad's frame (x right, y down as printed)
    side_m: float

    def corners_m(self) -> np.ndarray:
        """Its four corners (TL, TR, BR, BL as printed: OpenCV's order), 4×3 in the pad frame."""
        x, y, h = self.center_m[0], self.center_m[1], self.side_m / 2.0
        return np.array([[x - h, y - h, 0.0], [x + h, y - h, 0.0], [x + h, y + h, 0.0],
                         [x - h, y + h, 0.0]])


@dataclass(frozen=True, slots=True)
class MarkerPadLayout:
    size_m: float
    dictionary: str
    markers: tuple[PadMarker, ...]  # the centre marker first

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(m.marker_id for m in self.markers)


def marker_pad_layout(size_m: float, ids: tuple[int, ...] | list[int],
                      dictionary: str = "DICT_4X4_50") -> MarkerPadLayout:
    """The nested marker pad: ``ids[0]`` small in the centre, ``ids[1:5]`` large around it
    (top-left, top-right, bottom-right, bottom-left). Sizes are those its texture prints
    (whole cells of :data:`_PAD_TEXELS` texels)."""
    ids = tuple(int(i) for i in ids)
    if len(ids) != 5 or len(set(ids)) != 5:
        raise ValueError(f"a marker pad has five different marker ids, not {list(ids)}")
    d = aruco_dictionary(dictionary)
    bad = [i for i in ids if not 0 <= i < d.bytesList.shape[0]]
    if bad:
        raise ValueError(f"{dictionary} has no marker {bad[0]} "
                         f"(ids 0 to {d.bytesList.shape[0] - 1})")
    cells = d.markerSize + 2
    m_per_texel = size_m / _PAD_TEXELS

    def side(ratio: float) -> float:
        return max(1, round(ratio * _PAD_TEXELS / cells)) * cells * m_per_texel

    def centre(ratio: float, side_m: float) -> float:  # on the texel grid, so it prints exactly
        texels = round(ratio * _PAD_TEXELS - side_m / m_per_texel / 2.0)
        return (texels + side_m / m_per_texel / 2.0) * m_per_texel

    large, small = side(_LARGE), side(_SMALL)
    off = centre(_OFFSET, large)
    markers = [PadMarker(ids[0], (0.0, 0.0), small)]
    for k, (sx, sy) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        markers.append(PadMarker(ids[k + 1], (sx * off, sy * off), large))
    return MarkerPadLayout(size_m, dictionary, tuple(markers))


def marker_pad_texture(layout: MarkerPadLayout) -> np.ndarray:
    """The marker pad as printed (BGR, :data:`_PAD_TEXELS` square)."""
    n = _PAD_TEXELS
    d = aruco_dictionary(layout.dictionary)
    image = np.full((n, n), 255, np.uint8)
    texel = layout.size_m / n
    for m in layout.markers:
        side = round(m.side_m / texel)
        x0 = round((m.center_m[0] + layout.size_m / 2.0) / texel - side / 2.0)
        y0 = round((m.center_m[1] + layout.size_m / 2.0) / texel - side / 2.0)
        image[y0:y0 + side, x0:x0 + side] = cv2.aruco.generateImageMarker(d, m.marker_id, side,
                                                                           borderBits=1)
    return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)


def circle_pad_texture(color: str, size_px: int = 1024) -> np.ndarray:
    """A circle pad as printed (BGR): the disc on a white square :data:`CIRCLE_BOARD_RATIO`
    times its diameter."""
    rgba = COLORS[color][0]
    bgr = tuple(round(255 * c) for c in (rgba[2], rgba[1], rgba[0]))
    image = np.full((size_px, size_px, 3), 255, np.uint8)
    radius = size_px / CIRCLE_BOARD_RATIO / 2.0
    shift = 4  # sub-pixel drawing: the disc is centred exactly
    c = round((size_px - 1) / 2.0 * (1 << shift))
    cv2.circle(image, (c, c), round(radius * (1 << shift)), bgr, -1, cv2.LINE_AA, shift)
    return image


# -- detection -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PadDetection:
    time_s: float
    kind: str  # "circle" | "markers"
    #: the pad's centre in the camera's optical frame (m): markers from PnP; circle from the
    #: direction of the fitted centre and the range its apparent size gives
    position_cam_m: np.ndarray
    center_px: tuple[float, float]  # in the (distorted) frame
    radius_px: float  # half the pad's apparent width (circle: the disc's radius)
    #: markers: R_cam_pad; circle: None (a disc has no heading)
    rotation_cam_pad: np.ndarray | None = None
    #: circle: its outline not cut by the frame's border, undistorted normalised coordinates
    outline_norm: np.ndarray | None = None
    clipped: bool = False  # the frame's border cuts it
    ids: tuple[int, ...] = ()  # markers: the pad's markers seen
    fit_error: float = 0.0  # circle: RMS radial residual ÷ radius; markers: RMS reprojection px

    @property
    def range_m(self) -> float:
        return float(np.linalg.norm(self.position_cam_m))


def fit_circle(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares circle through 2-D points (algebraic fit, then Gauss-Newton on the
    geometric distances): centre, radius, RMS radial residual."""
    p = np.asarray(points, dtype=float)
    a = np.column_stack([2.0 * p[:, 0], 2.0 * p[:, 1], np.ones(len(p))])
    b = np.sum(p ** 2, axis=1)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    c = sol[:2]
    r = math.sqrt(max(sol[2] + c @ c, 1e-12))
    for _ in range(5):
        d = p - c
        dist = np.linalg.norm(d, axis=1)
        dist = np.where(dist < 1e-12, 1e-12, dist)
        resid = dist - r
        jac = np.column_stack([-d[:, 0] / dist, -d[:, 1] / dist, -np.ones(len(p))])
        step, *_ = np.linalg.lstsq(jac, -resid, rcond=None)
        c = c + step[:2]
        r = r + step[2]
    resid = np.linalg.norm(p - c, axis=1) - r
    return c, abs(float(r)), float(np.sqrt(np.mean(resid ** 2)))


@dataclass(frozen=True, slots=True)
class CirclePadSettings:
    diameter_m: float
    hsv_ranges: tuple[HsvRange, ...]
    min_radius_px: float = 4.0
    max_fit_error: float = 0.06  # RMS radial residual ÷ radius (a disc's outline is a circle)
    min_fill: float = 0.8  # whole in view: blob area ÷ fitted circle's area
    min_arc_points: int = 12  # outline points not on the border
    border_px: int = 2


class CirclePadDetector:
    """The largest disc of the pad's colour in a frame (see the module's notes)."""

    kind = "circle"

    def __init__(self, settings: CirclePadSettings) -> None:
        self.settings = settings
        self._open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))

    def mask(self, image_bgr: np.ndarray) -> np.ndarray:
        return color_mask(image_bgr, self.settings.hsv_ranges, self._open, self._close)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> PadDetection | None:
        s = self.settings
        mask = self.mask(image_bgr)
        h, w = mask.shape
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        intr = camera.intrinsics
        best: PadDetection | None = None
        for contour in contours:
            area = cv2.contourArea(contour)
            if area < math.pi * s.min_radius_px ** 2 * 0.5:
                continue
            arc, clipped = inner_outline(contour, w, h, s.border_px, 400)
            if len(arc) < s.min_arc_points:
                continue
            norm = undistort_points(intr, arc)
            centre_n, radius_n, rms = fit_circle(norm)
            # the outline runs through the blob's edge pixels' centres, half a pixel inside
            radius_n += 0.5 / intr.fx
            radius_px = radius_n * intr.fx
            if radius_px < s.min_radius_px or rms > s.max_fit_error * radius_n:
                continue
            if not clipped and area < s.min_fill * math.pi * (radius_px ** 2):
                continue
            if clipped:  # the arc must bulge the way a disc does: the blob inside the circle
                inside = cv2.pointPolygonTest(
                    contour, tuple(float(v) for v in project_points(
                        intr, np.array([*centre_n, 1.0]))), False)
                if inside < 0 and radius_px < max(w, h):
                    continue
            if best is not None and radius_px <= best.radius_px:
                continue
            depth = (s.diameter_m / 2.0) / radius_n  # nadir: the disc faces the camera
            position = depth * np.array([centre_n[0], centre_n[1], 1.0])
            u, v = project_points(intr, position)
            best = PadDetection(time_s, "circle", position, (float(u), float(v)),
                                float(radius_px), outline_norm=norm, clipped=clipped,
                                fit_error=rms / radius_n)
        return best


@dataclass(frozen=True, slots=True)
class MarkerPadSettings:
    layout: MarkerPadLayout
    backend: str = "aruco"
    corner_refinement: str = "edges"
    min_perimeter_px: float = 24.0


class MarkerPadDetector:
    """The marker pad's pose from every one of its markers in view (one PnP over all their
    corners). Markers of other ids (another pad, decoys) are ignored."""

    kind = "markers"

    def __init__(self, settings: MarkerPadSettings) -> None:
        self.settings = s = settings
        self.layout = s.layout
        self._markers = {m.marker_id: m for m in s.layout.markers}
        self._finder = MarkerDetector(MarkerDetectorSettings(
            marker_id=s.layout.ids[0], size_m=s.layout.markers[0].side_m,
            dictionary=s.layout.dictionary, backend=s.backend,
            corner_refinement=s.corner_refinement, min_perimeter_px=s.min_perimeter_px))

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> PadDetection | None:
        found = [f for f in self._finder.find(image_bgr) if f.marker_id in self._markers]
        if not found:
            return None
        seen: dict[int, np.ndarray] = {}
        for f in found:  # a repeated id (a second pad): keep the larger
            size = cv2.arcLength(f.corners.astype(np.float32), True)
            if f.marker_id not in seen or size > cv2.arcLength(
                    seen[f.marker_id].astype(np.float32), True):
                seen[f.marker_id] = f.corners
        obj = np.vstack([self._markers[i].corners_m() for i in seen])
        img = np.vstack([seen[i] for i in seen])
        intr = camera.intrinsics
        pose = planar_pose(obj, img, intr.matrix, distortion_coefficients(intr))
        if pose is None:
            return None
        _, tvec, rotation, error = pose
        position = tvec.reshape(3).copy()
        u, v = project_points(intr, position)
        radius_px = intr.fx * self.layout.size_m / 2.0 / max(position[2], 1e-6)
        return PadDetection(time_s, "markers", position, (float(u), float(v)), float(radius_px),
                            rotation_cam_pad=rotation, ids=tuple(sorted(seen)),
                            fit_error=error)


def pad_texture(kind: str, size_m: float, *, color: str = "red", ids=(0, 1, 2, 3, 4),
                dictionary: str = "DICT_4X4_50") -> tuple[np.ndarray, float]:
    """A pad's printed face and the width it spans on the ground (a circle's white square is
    wider than its disc)."""
    if kind == "circle":
        return circle_pad_texture(color), size_m * CIRCLE_BOARD_RATIO
    if kind == "markers":
        return marker_pad_texture(marker_pad_layout(size_m, ids, dictionary)), size_m
    raise ValueError(f"unknown pad kind {kind!r} (known: {', '.join(PAD_KINDS)})")
