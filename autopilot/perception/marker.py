"""Square fiducial markers (ArUco, AprilTag): find one marker by its id and measure its pose.

Seed 002 follows ArUco marker 36 (16 cm) at 1 m. Two back ends find the marker's four corners:

* ``aruco`` (default): OpenCV's ``cv2.aruco.ArucoDetector`` (OpenCV 5 API) with any of its
  dictionaries: ``DICT_ARUCO_ORIGINAL`` (the seed's ArUco library markers, the default),
  ``DICT_4X4_50`` … and the AprilTag ones (``DICT_APRILTAG_36h11`` …). Its corners are refined
  by ``edges`` (default): each side of the black square is fitted as a straight line through
  sub-pixel edge points and the corners are the lines' crossings, as AprilTag does
  (:func:`refine_corners_on_edges`, about 1 ms). On synthetic 640×480 views (f = 320 px, blur,
  noise) of a 16 cm marker at 1 m that gives 0.2 mm median position error, against 6 mm with
  OpenCV's ``subpix``, 13 mm with no refinement and 0.8 mm with OpenCV's own AprilTag
  refinement (``apriltag``), which is also 3-5 times slower and finds fewer small markers;
* ``apriltag``: the AprilTag 3 library through ``pupil-apriltags`` (families ``tag36h11``,
  ``tag25h9``, ``tag16h5``, whose ids are those of OpenCV's ``DICT_APRILTAG_*``): as accurate,
  and with ``quad_decimate`` 2 the fastest on a whole frame, but for AprilTag markers only.

Then the pose: ``cv2.solvePnPGeneric(..., SOLVEPNP_IPPE_SQUARE)`` with the camera's distortion
coefficients (the corners stay as detected, in the distorted image; OpenCV undistorts them)
gives both poses a square can have, with their reprojection errors. A small or nearly
fronto-parallel marker is ambiguous: the two poses fit the corners almost equally well and
differ by a tilt reflected about the line of sight (their positions nearly agree, their
orientations do not). The better fitting pose is chosen; when the fit cannot tell them apart
(``ambiguity_ratio`` = best error / other error above ``ambiguity_threshold``) and a hint
carries a previous or predicted orientation, the pose nearer that orientation is chosen
instead. Both poses and the ratio are reported, so that an estimator can trust the position
and weigh the orientation.

Frames. The pose is the marker's in the camera's optical frame (x right, y down, z forward).
The marker frame is OpenCV's (``SOLVEPNP_IPPE_SQUARE``'s): origin at the centre of the black
square, x to the right and y up as the printed marker is read, z out of the marker towards
the viewer (right-handed). ``rotation_cam_marker`` has the marker's axes as its columns
(optical-frame vectors = R @ marker-frame vectors); ``position_cam_m`` is the marker's centre.
A marker seen head-on and upright therefore has R = diag(1, −1, −1). The corners are in
ArUco's order, the printed marker's top-left, top-right, bottom-right, bottom-left, at
(−s/2, s/2, 0), (s/2, s/2, 0), (s/2, −s/2, 0), (−s/2, −s/2, 0) in the marker frame, and in
OpenCV's pixel convention (pixel centres at integer coordinates; the AprilTag edge fits'
half-pixel offset is removed).

Only the configured id is followed; any other ids seen in the searched area are listed. With a
hint of where the marker is expected, a window around it is searched first and the whole image
only if that does not find the marker. Synchronous and stateless apart from its settings (the
caller keeps the previous detection and turns it into a :class:`MarkerHint`); the runtime calls
it in an executor.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from drivers.base import CameraInfo
from drivers.geometry import matrix_to_quat, quat_canonical
from drivers.markers import (
    apriltag_family_name,
    aruco_dictionary,
    aruco_dictionary_name,
)

Backend = Literal["aruco", "apriltag"]
CornerRefinement = Literal["edges", "subpix", "apriltag", "contour", "none"]

#: AprilTag families whose detected corners are the black square's outer corners (what
#: ``size_m`` measures), with OpenCV's name for the same dictionary.
_REFINE = {"edges": cv2.aruco.CORNER_REFINE_NONE,  # then refine_corners_on_edges
           "none": cv2.aruco.CORNER_REFINE_NONE, "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
           "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
           "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG}
#: AprilTag's edge fits put pixel centres at half-integer coordinates; OpenCV at integers.
_APRILTAG_PIXEL_OFFSET = 0.5
_EPS_PX = 1e-3  # added to both reprojection errors: noise-free corners do not make a ratio


@dataclass(frozen=True, slots=True)
class MarkerDetectorSettings:
    """What to look for and how.

    ``size_m`` is the side of the marker's black square (its outer edge). ``dictionary``: an
    OpenCV dictionary name (``DICT_ARUCO_ORIGINAL``, ``DICT_4X4_50``, ``DICT_APRILTAG_36h11``…)
    or, for either back end, an AprilTag family (``tag36h11``, ``tag25h9``, ``tag16h5``).
    """

    marker_id: int = 36
    size_m: float = 0.16
    dictionary: str = "DICT_ARUCO_ORIGINAL"
    backend: Backend = "aruco"
    #: aruco back end: how corners are refined: ``edges`` (line fits, the most accurate),
    #: OpenCV's ``subpix``, ``apriltag`` or ``contour``, or ``none``.
    corner_refinement: CornerRefinement = "edges"
    #: aruco ``subpix``: window half-size as a fraction of a marker cell (OpenCV's
    #: relativeCornerRefinmentWinSize), at most ``subpix_max_window_px``.
    subpix_window_rel: float = 0.5
    subpix_max_window_px: int = 5
    #: Smallest marker looked for: its perimeter in pixels (32: 8 px a side).
    min_perimeter_px: float = 32.0
    #: aruco: bits of the code that may be wrong, as a fraction of what the dictionary can
    #: correct (OpenCV's errorCorrectionRate; 0 accepts exact codes only).
    error_correction_rate: float = 0.6
    #: apriltag back end: image decimation before quad detection (1: full resolution, finds
    #: smaller tags; 2: about 2-3 times faster), blur σ, bits of the code that may be wrong,
    #: and the least decision margin accepted.
    quad_decimate: float = 1.0
    quad_sigma: float = 0.0
    max_hamming: int = 1
    min_decision_margin: float = 20.0
    threads: int = 1
    #: Poses whose reprojection errors have a ratio (best / other) above this are ambiguous:
    #: a hint's orientation, if any, chooses between them. (Synthetic views, 1 and 3 m: the
    #: better fit was the wrong pose in 2 % of the detections below 0.5, 26 % above.)
    ambiguity_threshold: float = 0.5
    #: Search window around a hinted position: half-size in marker sides (the hint's size, or
    #: the smallest marker's), at least ``min_window_px``.
    window_sides: float = 1.5
    min_window_px: int = 40

    def __post_init__(self) -> None:
        if self.backend == "aruco":
            aruco_dictionary_name(self.dictionary)
            if self.corner_refinement not in _REFINE:
                raise ValueError(f"corner_refinement must be one of {', '.join(_REFINE)}")
        elif self.backend == "apriltag":
            apriltag_family_name(self.dictionary)
        else:
            raise ValueError(f"backend must be 'aruco' or 'apriltag', not {self.backend!r}")
        if self.size_m <= 0.0:
            raise ValueError("size_m must be positive")


@dataclass(frozen=True, slots=True, eq=False)
class MarkerPose:
    """A marker pose in the optical frame (see the module notes for the marker frame)."""

    position_cam_m: np.ndarray
    rotation_cam_marker: np.ndarray
    reprojection_error_px: float  # RMS over the four corners

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_cam_m", _frozen(self.position_cam_m, (3,)))
        object.__setattr__(self, "rotation_cam_marker", _frozen(self.rotation_cam_marker, (3, 3)))

    @property
    def normal_cam(self) -> np.ndarray:
        """The marker's z axis (out of its face, towards the viewer) in the optical frame."""
        return self.rotation_cam_marker[:, 2]


@dataclass(frozen=True, slots=True, eq=False)
class MarkerDetection:
    """The followed marker found in one frame, with its pose in the camera's optical frame."""

    time_s: float  # the frame's capture time
    camera: str
    marker_id: int
    corners_px: np.ndarray  # 4×2, TL TR BR BL of the printed marker, as detected (distorted)
    position_cam_m: np.ndarray  # the black square's centre
    rotation_cam_marker: np.ndarray  # 3×3, columns: the marker's x, y, z axes
    range_m: float
    reprojection_error_px: float
    #: Best / other reprojection error of the two IPPE poses: near 0 one pose fits and the
    #: other does not; near 1 the corners cannot tell them apart.
    ambiguity_ratio: float
    ambiguous: bool  # ambiguity_ratio above the settings' threshold
    #: How the pose was chosen: "fit" (the better reprojection error) or "hint" (ambiguous,
    #: nearer the hint's orientation).
    chosen_by: str
    alternative: MarkerPose  # the other IPPE pose
    size_px: float  # mean side length in the image
    other_ids: tuple[int, ...] = ()  # other markers seen in the searched area, sorted
    window: tuple[int, int, int, int] | None = None  # (x0, y0, x1, y1) searched; None: all
    #: apriltag back end: the detection's decision margin (NaN for aruco).
    decision_margin: float = math.nan

    def __post_init__(self) -> None:
        object.__setattr__(self, "corners_px", _frozen(self.corners_px, (4, 2)))
        object.__setattr__(self, "position_cam_m", _frozen(self.position_cam_m, (3,)))
        object.__setattr__(self, "rotation_cam_marker", _frozen(self.rotation_cam_marker, (3, 3)))

    @property
    def center_px(self) -> np.ndarray:
        """Where the marker's centre is in the image (the diagonals' crossing, as detected)."""
        return _diagonal_crossing(self.corners_px)

    @property
    def quaternion(self) -> np.ndarray:
        """``rotation_cam_marker`` as a unit quaternion (w, x, y, z), w ≥ 0."""
        return quat_canonical(matrix_to_quat(self.rotation_cam_marker))

    @property
    def normal_cam(self) -> np.ndarray:
        """The marker's z axis (out of its face, towards the viewer) in the optical frame."""
        return self.rotation_cam_marker[:, 2]

    @property
    def pose(self) -> MarkerPose:
        return MarkerPose(self.position_cam_m, self.rotation_cam_marker,
                          self.reprojection_error_px)


@dataclass(frozen=True, slots=True, eq=False)
class MarkerHint:
    """What the caller expects: where to look, and which orientation to prefer when the pose is
    ambiguous. Any field may be None."""

    center_px: tuple[float, float] | None = None  # predicted centre in the (distorted) image
    size_px: float | None = None  # predicted side length
    rotation_cam_marker: np.ndarray | None = None  # previous or predicted orientation

    @classmethod
    def from_detection(cls, detection: MarkerDetection) -> MarkerHint:
        """Look where the marker was last seen and prefer its last orientation."""
        u, v = detection.center_px
        return cls((float(u), float(v)), detection.size_px, detection.rotation_cam_marker)


@dataclass(frozen=True, slots=True, eq=False)
class MarkerCorners:
    """A marker of the dictionary found in an image: its id and corners (no pose yet)."""

    marker_id: int
    corners: np.ndarray  # 4×2 float64, TL TR BR BL, full-image pixels, OpenCV's convention
    decision_margin: float = math.nan  # apriltag back end only


class MarkerDetector:
    def __init__(self, settings: MarkerDetectorSettings | None = None) -> None:
        self.settings = s = settings or MarkerDetectorSettings()
        half = s.size_m / 2.0
        self._object_points = np.array([[-half, half, 0.0], [half, half, 0.0],
                                        [half, -half, 0.0], [-half, -half, 0.0]])
        self._aruco: cv2.aruco.ArucoDetector | None = None
        self._apriltag = None
        self._lock = threading.Lock()  # the back ends' detectors are not re-entrant
        if s.backend == "aruco":
            dictionary = aruco_dictionary(s.dictionary)
            self._params = cv2.aruco.DetectorParameters()
            self._params.cornerRefinementMethod = _REFINE[s.corner_refinement]
            self._params.relativeCornerRefinmentWinSize = s.subpix_window_rel
            self._params.cornerRefinementWinSize = s.subpix_max_window_px
            self._params.errorCorrectionRate = s.error_correction_rate
            self._params.maxMarkerPerimeterRate = 4.0
            self._params_for: tuple[int, int] | None = None
            self._aruco = cv2.aruco.ArucoDetector(dictionary, self._params,
                                                  cv2.aruco.RefineParameters())
            self._cells = dictionary.markerSize + 2  # code bits and the black border
        else:
            self._apriltag = _apriltag_detector_class()(
                families=apriltag_family_name(s.dictionary), nthreads=s.threads,
                quad_decimate=s.quad_decimate, quad_sigma=s.quad_sigma, refine_edges=1,
                decode_sharpening=0.25)

    # -- corners ---------------------------------------------------------------------------

    def find(self, image: np.ndarray,
             window: tuple[int, int, int, int] | None = None) -> list[MarkerCorners]:
        """Every marker of the dictionary in the image (or a window of it): ids and corners."""
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        x0, y0 = 0, 0
        if window is not None:
            x0, y0, x1, y1 = window
            gray = gray[y0:y1, x0:x1]
        with self._lock:
            found = self._find_aruco(gray) if self._aruco is not None \
                else self._find_apriltag(gray)
        if x0 or y0:
            offset = np.array((x0, y0), dtype=float)
            found = [MarkerCorners(f.marker_id, f.corners + offset, f.decision_margin)
                     for f in found]
        return found

    def _find_aruco(self, gray: np.ndarray) -> list[MarkerCorners]:
        h, w = gray.shape[:2]
        if self._params_for != (w, h):  # perimeter limits are relative to the image's size
            self._params.minMarkerPerimeterRate = min(
                self.settings.min_perimeter_px / max(w, h), 4.0)
            self._aruco.setDetectorParameters(self._params)
            self._params_for = (w, h)
        corners, ids, _ = self._aruco.detectMarkers(gray)
        if ids is None:
            return []
        refinement = self.settings.corner_refinement
        shift = _APRILTAG_PIXEL_OFFSET if refinement == "apriltag" else 0.0
        found = [MarkerCorners(int(i), c.reshape(4, 2).astype(np.float64) - shift)
                 for i, c in zip(ids.ravel(), corners, strict=True)]
        if refinement == "edges":
            found = [MarkerCorners(f.marker_id,
                                   refine_corners_on_edges(gray, f.corners, self._cells))
                     for f in found]
        return found

    def _find_apriltag(self, gray: np.ndarray) -> list[MarkerCorners]:
        s = self.settings
        out = []
        for d in self._apriltag.detect(np.ascontiguousarray(gray)):
            if d.hamming > s.max_hamming or d.decision_margin < s.min_decision_margin:
                continue
            # AprilTag lists the printed tag's top-right, top-left, bottom-left and
            # bottom-right corners (counter-clockwise in its own y-up frame); ArUco's order
            # is top-left, top-right, bottom-right, bottom-left
            corners = np.asarray(d.corners, dtype=np.float64)[[1, 0, 3, 2]]
            out.append(MarkerCorners(int(d.tag_id), corners - _APRILTAG_PIXEL_OFFSET,
                              float(d.decision_margin)))
        return out

    # -- pose ------------------------------------------------------------------------------

    def poses(self, corners_px: np.ndarray, camera: CameraInfo) -> list[MarkerPose]:
        """Both IPPE poses of a square with these corners, the better fitting first."""
        intr = camera.intrinsics
        ok, rvecs, tvecs, errors = cv2.solvePnPGeneric(
            self._object_points, np.ascontiguousarray(corners_px, np.float64).reshape(4, 1, 2),
            intr.matrix, np.asarray(intr.distortion, np.float64),
            flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            return []
        errors = np.asarray(errors, dtype=float).ravel()
        poses = [MarkerPose(np.asarray(t, float).ravel(), cv2.Rodrigues(r)[0], float(e))
                 for r, t, e in zip(rvecs, tvecs, errors, strict=True)]
        return sorted(poses, key=lambda p: p.reprojection_error_px)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: MarkerHint | None = None) -> MarkerDetection | None:
        """The followed marker in a frame, or None.

        With a hint's position, the window around it is searched first and the whole image
        only if the marker is not in it; the marker nearest the hint wins if the id is seen
        more than once (without a hint: the largest)."""
        s = self.settings
        gray = image_bgr if image_bgr.ndim == 2 else cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
        window = None
        found: list[MarkerCorners] = []
        if hint is not None and hint.center_px is not None:
            window = self.window(gray.shape, hint.center_px, hint.size_px)
            if window is not None:
                found = self.find(gray, window)
        if not any(f.marker_id == s.marker_id for f in found):
            window = None
            found = self.find(gray)
        ours = [f for f in found if f.marker_id == s.marker_id]
        if not ours:
            return None
        if hint is not None and hint.center_px is not None:
            hu, hv = hint.center_px
            best = min(ours, key=lambda f: math.hypot(*(f.corners.mean(axis=0) - (hu, hv))))
        else:
            best = max(ours, key=lambda f: cv2.arcLength(f.corners.astype(np.float32), True))
        poses = self.poses(best.corners, camera)
        if len(poses) < 2:
            return None
        first, second = poses[0], poses[1]
        ratio = (first.reprojection_error_px + _EPS_PX) / (second.reprojection_error_px
                                                            + _EPS_PX)
        ambiguous = ratio > s.ambiguity_threshold
        chosen, other, chosen_by = first, second, "fit"
        if ambiguous and hint is not None and hint.rotation_cam_marker is not None:
            prior = np.asarray(hint.rotation_cam_marker, dtype=float)
            if rotation_angle(second.rotation_cam_marker, prior) < \
                    rotation_angle(first.rotation_cam_marker, prior):
                chosen, other = second, first
            chosen_by = "hint"
        sides = np.linalg.norm(best.corners - np.roll(best.corners, -1, axis=0), axis=1)
        return MarkerDetection(
            time_s=time_s,
            camera=camera.name,
            marker_id=best.marker_id,
            corners_px=best.corners,
            position_cam_m=chosen.position_cam_m,
            rotation_cam_marker=chosen.rotation_cam_marker,
            range_m=float(np.linalg.norm(chosen.position_cam_m)),
            reprojection_error_px=chosen.reprojection_error_px,
            ambiguity_ratio=float(min(ratio, 1.0)),
            ambiguous=bool(ambiguous),
            chosen_by=chosen_by,
            alternative=other,
            size_px=float(sides.mean()),
            other_ids=tuple(sorted({f.marker_id for f in found} - {s.marker_id})),
            window=window,
            decision_margin=best.decision_margin,
        )

    def window(self, shape: Sequence[int], center_px: Sequence[float],
               size_px: float | None) -> tuple[int, int, int, int] | None:
        """The search window (x0, y0, x1, y1) around a predicted centre; None if the centre is
        outside the image or the window would be most of it."""
        s = self.settings
        height, width = shape[:2]
        u, v = center_px
        if not (0 <= u < width and 0 <= v < height):
            return None
        side = size_px if size_px else s.min_perimeter_px / 4.0
        half = max(float(s.min_window_px), s.window_sides * side)
        x0, y0 = max(0, int(u - half)), max(0, int(v - half))
        x1, y1 = min(width, int(u + half) + 1), min(height, int(v + half) + 1)
        if (x1 - x0) * (y1 - y0) > 0.6 * width * height:
            return None
        return x0, y0, x1, y1


@functools.cache
def _apriltag_detector_class():
    """pupil-apriltags' ``Detector``, freeing its C objects in the right order.

    Its own ``__del__`` (1.0.4.post11, the latest) destroys the tag families before the
    detector, whose destruction then reads the freed families: heap corruption, seen here as
    ``malloc(): mismatching next->prev_size`` or a segmentation fault when the detector is
    collected, usually at exit (pupil-labs/apriltags issues 34 and 46; the same fix went into
    the dt-apriltags fork)."""
    try:
        import pupil_apriltags
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("the apriltag back end needs pupil-apriltags "
                          "(pip install pupil-apriltags)") from exc

    class Detector(pupil_apriltags.Detector):
        def __del__(self) -> None:
            detector = getattr(self, "tag_detector_ptr", None)
            if detector is None:
                return
            self.tag_detector_ptr = None  # the base class's __del__ is not called
            libc = self.libc
            libc.apriltag_detector_destroy.restype = None
            libc.apriltag_detector_destroy(detector)
            for family, pointer in self.tag_families.items():
                destroy = getattr(libc, f"{family}_destroy")
                destroy.restype = None
                destroy(pointer)

    return Detector


def refine_corners_on_edges(gray: np.ndarray, corners: np.ndarray, cells: int,
                            samples: int = 12, iterations: int = 4) -> np.ndarray:
    """Corners of a black square refined as the crossings of its four edges, each fitted as a
    straight line through sub-pixel edge points (as AprilTag does).

    Along each side, at ``samples`` points clear of the corners, the grey level is sampled
    across the edge (quarter-pixel steps, within half a code cell either side so that the
    code's own edges stay out); the edge point is the centroid of the dark-to-bright
    gradient, re-centred ``iterations`` times. A symmetric blur does not move it. Lens
    distortion bends the edges slightly; over a marker of a few tens of pixels that is far
    below the noise. Corners in ArUco's order, OpenCV's pixel convention; ``cells``: the
    marker's side in code cells including the black border. Below about 3 px a cell the
    code's inner edges, blurred, pull the fitted edges outwards (a marker seen 1-2 % too
    large)."""
    c = np.asarray(corners, dtype=np.float64)
    centre = c.mean(axis=0)
    side = float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))
    reach = max(1.0, min(0.45 * side / cells, 3.0))
    steps = np.arange(-reach, reach + 1e-9, 0.25)
    mids = 0.5 * (steps[:-1] + steps[1:])
    along = np.linspace(0.12, 0.88, samples)
    lines = []
    for i in range(4):
        a, b = c[i], c[(i + 1) % 4]
        length = float(np.linalg.norm(b - a))
        if length < 1e-6:
            return c
        d = (b - a) / length
        normal = np.array([d[1], -d[0]])
        if np.dot(normal, 0.5 * (a + b) - centre) < 0.0:
            normal = -normal  # outwards: from the black square to the white around it
        pts = a + along[:, None] * (b - a)
        offset = np.zeros(samples)
        for _ in range(iterations):
            grid = pts[:, None, :] + (offset[:, None] + steps[None, :])[:, :, None] * normal
            values = cv2.remap(gray, grid[..., 0].astype(np.float32),
                               grid[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
            rise = np.clip(np.diff(values, axis=1), 0.0, None)
            weight = rise.sum(axis=1)
            ok = weight > 1e-6
            offset = offset + np.where(ok, (rise * mids).sum(axis=1) / np.where(ok, weight, 1.0),
                                       0.0)
        edge = pts + offset[:, None] * normal
        mean = edge.mean(axis=0)
        _, _, vt = np.linalg.svd(edge - mean)
        lines.append((mean, vt[0]))
    out = np.empty((4, 2))
    for i in range(4):  # corner i joins side i - 1 and side i
        (p1, d1), (p2, d2) = lines[i - 1], lines[i]
        a = np.column_stack((d1, -d2))
        if abs(np.linalg.det(a)) < 1e-9:
            return c
        t = np.linalg.solve(a, p2 - p1)
        out[i] = p1 + t[0] * d1
    if np.abs(out - c).max() > max(2.0, 0.5 * side / cells):
        return c  # the fit went astray (an edge hidden or cut by the image border)
    return out


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) of the rotation between two rotation matrices."""
    c = (np.trace(np.asarray(a).T @ np.asarray(b)) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, float(c))))


def _diagonal_crossing(corners: np.ndarray) -> np.ndarray:
    p0, p1, p2, p3 = np.asarray(corners, dtype=float)
    d1, d2 = p2 - p0, p3 - p1
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(den) < 1e-12:
        return corners.mean(axis=0)
    t = ((p1[0] - p0[0]) * d2[1] - (p1[1] - p0[1]) * d2[0]) / den
    return p0 + t * d1


def _frozen(values, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(values, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"expected an array of shape {shape}, got {arr.shape}")
    arr.flags.writeable = False
    return arr
