"""A known flat image on the ground, seen by the down camera (seed 000's hover target).

The image frame: origin at the image's centre on its printed face, x along its columns (to the
right), y along its rows (down the image), z into the ground — seen from above with its top
towards heading ψ, x points to ψ + 90° and z down, so a camera looking straight down at it
with the image upright in its frame sees ``R_cam_image`` = identity. ``size_m`` is the printed
width (along x); the height follows the image's aspect ratio.

Detection: features (ORB by default; AKAZE selectable) of the reference image computed once,
matched in each frame with a brute-force Hamming matcher and Lowe's ratio test, a homography
from the plane (metres) to the frame's undistorted image plane fitted with OpenCV's USAC
(MAGSAC++), then the plane's pose from its inliers with ``solvePnP`` (IPPE, then refined
with Levenberg–Marquardt) through the camera's intrinsics and distortion.

Between full detections the inliers are tracked from frame to frame (pyramidal Lucas–Kanade,
kept only where tracking back lands within half a pixel of where it started), and the pose
comes from the tracked points through the same homography check and PnP: a few milliseconds
instead of a full feature search, and the same points from frame to frame (less jitter). A full
detection runs at least every ``track_frames`` frames, and whenever too few points survive.

The default target (:func:`default_target_image`) is generated here, deterministically: shapes
of many sizes, colours and orientations scattered without repeating (seed 000's advice: well
distributed, non-repeating features), so that every part of it matches one place only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from drivers.base import CameraInfo

#: The mission parameter value that selects the generated target.
DEFAULT_TARGET = "default"
DEFAULT_TARGET_SEED = 20261123

FeatureKind = Literal["orb", "akaze"]


class ImageTargetError(ValueError):
    pass


def default_target_image(size_px: int = 1024, seed: int = DEFAULT_TARGET_SEED) -> np.ndarray:
    """The shipped target (BGR, ``size_px`` square): a light page with a few hundred filled and
    outlined shapes — ellipses, polygons, rectangles, strokes — of sizes from 1 % to 20 % of its
    width, in saturated and grey tones, at random places and angles, and a dark frame."""
    rng = np.random.default_rng(seed)
    s = size_px
    image = np.full((s, s, 3), 235, np.uint8)
    # a faint large-scale shading, so that flat areas are not perfectly flat
    ramp = cv2.resize(rng.uniform(-18, 18, (6, 6)).astype(np.float32), (s, s),
                      interpolation=cv2.INTER_CUBIC)
    image = np.clip(image.astype(np.float32) + ramp[:, :, None], 0, 255).astype(np.uint8)

    def colour() -> tuple[int, int, int]:
        if rng.random() < 0.35:
            g = int(rng.integers(0, 120))
            return (g, g, g)
        return tuple(int(c) for c in rng.integers(0, 256, 3))

    for _ in range(420):
        size = s * float(np.exp(rng.uniform(np.log(0.01), np.log(0.2))))
        cx, cy = (float(v) for v in rng.uniform(0.05 * s, 0.95 * s, 2))
        kind = rng.integers(0, 4)
        thick = -1 if rng.random() < 0.7 else max(1, int(size / 12))
        if kind == 0:
            axes = (max(1, int(size / 2)), max(1, int(size / 2 * rng.uniform(0.3, 1.0))))
            cv2.ellipse(image, (int(cx), int(cy)), axes, float(rng.uniform(0, 180)), 0, 360,
                        colour(), thick, cv2.LINE_AA)
        elif kind in (1, 2):
            n = 3 if kind == 1 else int(rng.integers(4, 8))
            angles = np.sort(rng.uniform(0, 2 * math.pi, n))
            radii = size / 2 * rng.uniform(0.5, 1.0, n)
            pts = np.stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)], 1)
            pts = pts.astype(np.int32).reshape(-1, 1, 2)
            if thick < 0:
                cv2.fillPoly(image, [pts], colour(), cv2.LINE_AA)
            else:
                cv2.polylines(image, [pts], True, colour(), thick, cv2.LINE_AA)
        else:
            a = rng.uniform(0, 2 * math.pi)
            d = np.array([math.cos(a), math.sin(a)]) * size / 2
            p0 = (int(cx - d[0]), int(cy - d[1]))
            p1 = (int(cx + d[0]), int(cy + d[1]))
            cv2.line(image, p0, p1, colour(), max(1, int(size / 15)), cv2.LINE_AA)
    border = max(2, s // 64)
    cv2.rectangle(image, (0, 0), (s - 1, s - 1), (30, 30, 30), border)
    return image


def load_target_image(source: str | Path) -> np.ndarray:
    """The reference image (BGR): the generated default, or an image file."""
    if str(source) == DEFAULT_TARGET:
        return default_target_image()
    path = Path(source)
    if not path.is_file():
        raise ImageTargetError(f"{path}: no such image file")
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ImageTargetError(f"{path}: not an image OpenCV can read (PNG, JPEG, …)")
    if min(image.shape[:2]) < 64:
        raise ImageTargetError(f"{path}: {image.shape[1]}×{image.shape[0]} px is too small "
                               "to find features in (at least 64 px a side)")
    return image


@dataclass(frozen=True, slots=True)
class ImageTargetSettings:
    size_m: float  # printed width
    features: FeatureKind = "orb"
    #: features kept in the reference (its working copy is ``reference_px`` wide) and per frame
    reference_features: int = 1200
    frame_features: int = 800
    reference_px: int = 800
    ratio: float = 0.75  # Lowe's ratio test
    #: inlier threshold of the homography, in pixels of the frame
    ransac_px: float = 2.5
    min_inliers: int = 15
    #: frames tracked (Lucas–Kanade) between full detections; 0: a full detection every frame
    track_frames: int = 0


@dataclass(frozen=True, slots=True)
class ImageTargetDetection:
    time_s: float
    #: the image's centre in the camera's optical frame (m), and ``R_cam_image``
    position_cam_m: np.ndarray
    rotation_cam_image: np.ndarray
    #: the image's four corners in the frame (px; top-left, top-right, bottom-right,
    #: bottom-left), its centre (px), matches and inliers, RMS reprojection error of inliers
    corners_px: np.ndarray
    center_px: tuple[float, float]
    matches: int
    inliers: int
    reprojection_error_px: float
    tracked: bool = False  # from points tracked since the last full detection

    @property
    def range_m(self) -> float:
        return float(np.linalg.norm(self.position_cam_m))


def planar_pose(obj: np.ndarray, img: np.ndarray, k: np.ndarray, dist: np.ndarray):
    """A plane's pose from points on it (``obj``, z = 0) and their pixels: IPPE refined by
    Levenberg–Marquardt through the lens. (rvec, tvec, R_cam_plane, RMS reprojection error px),
    or None if it fails or the plane is behind the camera or seen from below."""
    ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec, tvec)
    rotation, _ = cv2.Rodrigues(rvec)
    if tvec[2, 0] <= 0.0 or rotation[2, 2] <= 0.0:
        return None
    projected, _ = cv2.projectPoints(obj, rvec, tvec, k, dist)
    error = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - img) ** 2, axis=1))))
    return rvec, tvec, rotation, error


class ImageTargetDetector:
    """Finds one known planar image and measures its pose (see the module's notes)."""

    def __init__(self, reference_bgr: np.ndarray, settings: ImageTargetSettings) -> None:
        self.settings = s = settings
        h, w = reference_bgr.shape[:2]
        self._ref_features = self._make_features(s.reference_features)
        self._frame_features = self._make_features(s.frame_features)
        # the reference at a few widths (each an octave below the last): seen from higher up
        # the image is smaller in the frame than ORB's own pyramid reaches
        descriptors, plane = [], []
        width = min(w, s.reference_px)
        while width >= 100:
            scale = width / w
            ref = cv2.resize(reference_bgr, (round(w * scale), round(h * scale)),
                             interpolation=cv2.INTER_AREA)
            gray = cv2.cvtColor(ref, cv2.COLOR_BGR2GRAY)
            kps, desc = self._ref_features.detectAndCompute(gray, None)
            if desc is not None and kps:
                metres_per_px = s.size_m / ref.shape[1]
                pts = np.array([k.pt for k in kps], dtype=np.float64)
                # OpenCV's pixel centres are at integer coordinates: the image spans -0.5 … w - 0.5
                plane.append(np.column_stack([
                    (pts[:, 0] + 0.5 - ref.shape[1] / 2.0) * metres_per_px,
                    (pts[:, 1] + 0.5 - ref.shape[0] / 2.0) * metres_per_px,
                    np.zeros(len(pts))]))
                descriptors.append(desc)
            width //= 2
        count = sum(len(p) for p in plane)
        if count < 4 * s.min_inliers:
            raise ImageTargetError(
                f"the target image has too few features ({count}; at least "
                f"{4 * s.min_inliers}): use one with more detail, well spread and not repeating")
        self._ref_desc = np.vstack(descriptors)
        self._ref_plane = np.vstack(plane)
        ref = reference_bgr
        self.height_m = s.size_m * ref.shape[0] / ref.shape[1]
        hw, hh = s.size_m / 2.0, self.height_m / 2.0
        self.corners_plane_m = np.array([[-hw, -hh, 0.0], [hw, -hh, 0.0], [hw, hh, 0.0],
                                         [-hw, hh, 0.0]])
        norm = cv2.NORM_HAMMING
        self._matcher = cv2.BFMatcher(norm, crossCheck=False)
        # frame-to-frame tracking: the last frame (grey), its inliers (px) and their plane points
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._tracked = 0

    def _make_features(self, count: int):
        if self.settings.features == "akaze":
            return cv2.AKAZE_create(threshold=5e-4)
        return cv2.ORB_create(nfeatures=count, scaleFactor=1.2, nlevels=8, edgeThreshold=15,
                              patchSize=31, fastThreshold=12)

    @property
    def reference_keypoints(self) -> int:
        return len(self._ref_plane)

    def reset(self) -> None:
        """Forget the tracked points: the next frame gets a full detection."""
        self._last = None

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> ImageTargetDetection | None:
        gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
        if self._last is not None and self._tracked < self.settings.track_frames:
            found = self._track(gray, camera, time_s)
            if found is not None:
                self._tracked += 1
                return found
        self._tracked = 0
        return self._full(gray, camera, time_s)

    def _track(self, gray: np.ndarray, camera: CameraInfo,
               time_s: float) -> ImageTargetDetection | None:
        last_gray, last_px, plane = self._last
        self._last = None
        p0 = last_px.astype(np.float32).reshape(-1, 1, 2)
        lk = {"winSize": (21, 21), "maxLevel": 3,
              "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)}
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(last_gray, gray, p0, None, **lk)
        if p1 is None:
            return None
        back, st2, _ = cv2.calcOpticalFlowPyrLK(gray, last_gray, p1, None, **lk)
        ok = (st1.ravel() == 1) & (st2.ravel() == 1) & \
            (np.linalg.norm((back - p0).reshape(-1, 2), axis=1) < 0.5)
        if int(ok.sum()) < 2 * self.settings.min_inliers:
            return None
        found = self._pose(plane[ok], p1.reshape(-1, 2)[ok].astype(np.float64), camera, time_s,
                           int(ok.sum()), gray, tracked=True)
        return found

    def _full(self, gray: np.ndarray, camera: CameraInfo,
              time_s: float) -> ImageTargetDetection | None:
        s = self.settings
        self._last = None
        kps, desc = self._frame_features.detectAndCompute(gray, None)
        if desc is None or len(kps) < s.min_inliers:
            return None
        pairs = self._matcher.knnMatch(desc, self._ref_desc, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < s.ratio * p[1].distance]
        if len(good) < s.min_inliers:
            return None
        frame_px = np.array([kps[m.queryIdx].pt for m in good], dtype=np.float64)
        plane = self._ref_plane[[m.trainIdx for m in good]]
        return self._pose(plane, frame_px, camera, time_s, len(good), gray)

    def _pose(self, plane: np.ndarray, frame_px: np.ndarray, camera: CameraInfo, time_s: float,
              matches: int, gray: np.ndarray, tracked: bool = False
              ) -> ImageTargetDetection | None:
        """The plane's pose from matched points: homography inliers (USAC), IPPE, LM."""
        s = self.settings
        intr = camera.intrinsics
        k = intr.matrix
        dist = np.asarray(intr.distortion, dtype=np.float64)
        # the homography between the plane (m) and the undistorted, normalised image
        normalised = cv2.undistortPoints(frame_px.reshape(-1, 1, 2), k, dist).reshape(-1, 2)
        homography, mask = cv2.findHomography(
            plane[:, :2], normalised, cv2.USAC_MAGSAC, s.ransac_px / intr.fx, maxIters=2000,
            confidence=0.999)
        if homography is None or mask is None:
            return None
        inliers = mask.ravel().astype(bool)
        if int(inliers.sum()) < s.min_inliers:
            return None
        obj, img = plane[inliers], frame_px[inliers]
        pose = planar_pose(obj, img, k, dist)
        if pose is None:
            return None
        rvec, tvec, rotation, error = pose
        corners, _ = cv2.projectPoints(self.corners_plane_m, rvec, tvec, k, dist)
        centre, _ = cv2.projectPoints(np.zeros((1, 3)), rvec, tvec, k, dist)
        u, v = centre.reshape(2)
        if s.track_frames > 0:
            self._last = (gray, img.copy(), obj.copy())
        return ImageTargetDetection(time_s, tvec.reshape(3).copy(), rotation,
                                    corners.reshape(4, 2), (float(u), float(v)), matches,
                                    int(inliers.sum()), error, tracked)
