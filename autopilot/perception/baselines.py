"""The seed reports' down-camera detectors, as baselines for ``autopilot bench`` (selected with
``perception.image.detector: seed000`` and ``perception.pad.detector: seed001``). They return
the same detections as ours, so that everything after detection (estimator, controller) is
the same in a comparison.

``Seed000ImageDetector`` (seed 000, hovering over a known image): ORB with 300 features on the
frame and on one copy of the reference, FLANN (LSH index, for binary descriptors) k-nearest
matching with the ratio test, at least 15 matches, a RANSAC homography whose outline must be a
convex quadrilateral (the report's "the bounding box is a rectangle" check), then
``solvePnPRansac`` on the matches (the reference's keypoints in metres on the plane). The
report's advice for the reference, blurring it as the camera blurs, is followed: it is reduced
to 320 px wide, about its size in the frame from 1-2 m.

``Seed001PadDetector`` (seed 001, landing on a red pad): multi-scale template matching,
``TM_CCOEFF`` over the colour frame (the report's ``IMAGE_COMPARISON_TYPE = cv2.TM_CCOEFF``),
with one template, the pad as printed, in copies on various scales ("a single template of
relatively large size will be stored locally, copies will be made on various scales", its
§1.3.6); the best match over scales wins if it clears a confidence threshold. The scales cover
the pad's apparent size over the whole descent: from ``max_height_m`` above it (above the
land_pad search altitude, 6 m) down to the height where the printed pad fills the frame's
shorter side — the lowest a template can be matched at all (``matchTemplate`` needs the
template inside the frame; with the shipped down camera, 80° over 640 px, about 0.8 m for the
0.8 m disc) — in a geometric progression ``scale_step`` apart (1.25: 13 templates), the worst
mismatch between the pad and the nearest template being the square root of that (±12 %; the
report's own test used 0.5, 1, 1.5, 2 and found that the closest scale locates best; at a step
of √2 rendered frames were missed at some heights). The scales are set from the camera's focal
length and frame on the first frame. The report's threshold was an absolute ``TM_CCOEFF``
value tuned to its template (``CONFIDENCE = 53500000.0``); here it is the same idea made
scale-free: the score over the template's own zero-mean energy at that scale must reach
``min_confidence``. The pad's centre is the matched window's centre; its range, from the
template's scale (the disc's apparent radius).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from autopilot.perception.image_target import ImageTargetDetection
from autopilot.perception.pad import CIRCLE_BOARD_RATIO, PadDetection, circle_pad_texture
from drivers.base import CameraInfo
from drivers.camera_model import project_points, undistort_points

# FLANN's LSH index (FLANN_INDEX_LSH) for ORB's binary descriptors, as OpenCV's tutorials set it
_FLANN_LSH = {"algorithm": 6, "table_number": 6, "key_size": 12, "multi_probe_level": 1}


class Seed000ImageDetector:
    """Seed 000's pipeline (see the module's notes)."""

    def __init__(self, reference_bgr: np.ndarray, size_m: float, *, features: int = 300,
                 reference_px: int = 320, ratio: float = 0.75, min_matches: int = 15) -> None:
        h, w = reference_bgr.shape[:2]
        scale = min(1.0, reference_px / w)
        ref = cv2.resize(reference_bgr, (round(w * scale), round(h * scale)),
                         interpolation=cv2.INTER_AREA)
        self._orb = cv2.ORB_create(nfeatures=features)
        gray = cv2.cvtColor(ref, cv2.COLOR_BGR2GRAY)
        kps, self._ref_desc = self._orb.detectAndCompute(gray, None)
        if self._ref_desc is None or len(kps) < min_matches:
            raise ValueError("the reference image has too few ORB features for seed 000's "
                             "pipeline")
        metres_per_px = size_m / ref.shape[1]
        pts = np.array([k.pt for k in kps], dtype=np.float64)
        self._ref_px = pts
        self._ref_plane = np.column_stack([
            (pts[:, 0] + 0.5 - ref.shape[1] / 2.0) * metres_per_px,
            (pts[:, 1] + 0.5 - ref.shape[0] / 2.0) * metres_per_px, np.zeros(len(pts))])
        self._ref_size_px = (ref.shape[1], ref.shape[0])
        hw, hh = size_m / 2.0, size_m * h / w / 2.0
        self._corners_plane = np.array([[-hw, -hh, 0.0], [hw, -hh, 0.0], [hw, hh, 0.0],
                                        [-hw, hh, 0.0]])
        self._matcher = cv2.FlannBasedMatcher(_FLANN_LSH, {"checks": 50})
        self.ratio, self.min_matches = ratio, min_matches

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> ImageTargetDetection | None:
        gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
        kps, desc = self._orb.detectAndCompute(gray, None)
        if desc is None or len(kps) < self.min_matches:
            return None
        pairs = self._matcher.knnMatch(self._ref_desc, desc, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < self.ratio * p[1].distance]
        if len(good) < self.min_matches:
            return None
        ref_px = self._ref_px[[m.queryIdx for m in good]]
        frame_px = np.array([kps[m.trainIdx].pt for m in good], dtype=np.float64)
        homography, _ = cv2.findHomography(ref_px, frame_px, cv2.RANSAC, 5.0)
        if homography is None:
            return None
        w, h = self._ref_size_px
        outline = cv2.perspectiveTransform(
            np.array([[[0, 0]], [[w, 0]], [[w, h]], [[0, h]]], np.float64), homography)
        if not cv2.isContourConvex(outline.astype(np.float32)):
            return None  # not a rectangle seen in perspective: a false match
        intr = camera.intrinsics
        k, dist = intr.matrix, np.asarray(intr.distortion, dtype=np.float64)
        obj = self._ref_plane[[m.queryIdx for m in good]]
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(obj, frame_px, k, dist)
        if not ok or inliers is None or len(inliers) < 4 or tvec[2, 0] <= 0.0:
            return None
        rotation, _ = cv2.Rodrigues(rvec)
        idx = inliers.ravel()
        projected, _ = cv2.projectPoints(obj[idx], rvec, tvec, k, dist)
        error = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - frame_px[idx]) ** 2,
                                             axis=1))))
        corners, _ = cv2.projectPoints(self._corners_plane, rvec, tvec, k, dist)
        centre, _ = cv2.projectPoints(np.zeros((1, 3)), rvec, tvec, k, dist)
        u, v = centre.reshape(2)
        return ImageTargetDetection(time_s, tvec.reshape(3).copy(), rotation,
                                    corners.reshape(4, 2), (float(u), float(v)), len(good),
                                    len(idx), error)


class Seed001PadDetector:
    """Seed 001's multi-scale template matching (see the module's notes)."""

    kind = "circle"

    def __init__(self, color: str, diameter_m: float, *, max_height_m: float = 10.0,
                 scale_step: float = 1.25, min_confidence: float = 0.5) -> None:
        if not scale_step > 1.0:
            raise ValueError(f"scale_step {scale_step}: must be above 1")
        self.diameter_m = diameter_m
        self.max_height_m = max_height_m
        self.scale_step = scale_step
        self.min_confidence = min_confidence
        self._printed = circle_pad_texture(color, 1024)
        self._for: tuple | None = None  # the camera the templates were made for
        self._templates: list[tuple[np.ndarray, float, float]] = []

    def disc_sizes_px(self, fx: float, frame_min_px: int) -> list[float]:
        """The disc's apparent diameters the templates are made at, for a camera of focal
        length ``fx`` (px) whose frame's shorter side is ``frame_min_px``: from the pad seen
        from ``max_height_m`` to the pad as printed filling the frame's shorter side."""
        smallest = fx * self.diameter_m / self.max_height_m
        largest = frame_min_px / CIRCLE_BOARD_RATIO
        if largest <= smallest:
            return [largest]
        n = math.ceil(math.log(largest / smallest) / math.log(self.scale_step) - 1e-9)
        return [smallest * (largest / smallest) ** (k / n) for k in range(n + 1)]

    def height_range_m(self, fx: float, frame_min_px: int) -> tuple[float, float]:
        """The heights over the pad (lowest, highest) the templates were made for."""
        sizes = self.disc_sizes_px(fx, frame_min_px)
        return fx * self.diameter_m / sizes[-1], fx * self.diameter_m / sizes[0]

    def _prepare(self, camera: CameraInfo, h: int, w: int) -> None:
        key = (camera.intrinsics.fx, h, w)
        if self._for == key:
            return
        self._templates = []
        for disc_px in self.disc_sizes_px(camera.intrinsics.fx, min(h, w)):
            side = min(min(h, w), max(8, round(disc_px * CIRCLE_BOARD_RATIO)))
            t = cv2.resize(self._printed, (side, side), interpolation=cv2.INTER_AREA)
            zero_mean = t.astype(np.float64) - t.reshape(-1, 3).mean(axis=0)
            energy = float(np.sum(zero_mean ** 2))
            self._templates.append((t, side / CIRCLE_BOARD_RATIO / 2.0, energy))
        self._for = key

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo,
               time_s: float) -> PadDetection | None:
        h, w = image_bgr.shape[:2]
        self._prepare(camera, h, w)
        best = None
        for template, radius_px, energy in self._templates:
            th, tw = template.shape[:2]
            res = cv2.matchTemplate(image_bgr, template, cv2.TM_CCOEFF)
            _, max_val, _, max_loc = cv2.minMaxLoc(res)
            confidence = max_val / energy if energy > 0 else 0.0
            if best is None or confidence > best[0]:
                centre = (max_loc[0] + (tw - 1) / 2.0, max_loc[1] + (th - 1) / 2.0)
                best = (confidence, centre, radius_px)
        if best is None or best[0] < self.min_confidence:
            return None
        _, (u, v), radius_px = best
        intr = camera.intrinsics
        n = undistort_points(intr, np.array([[u, v]], dtype=np.float64))[0]
        depth = (self.diameter_m / 2.0) / (radius_px / intr.fx)
        position = depth * np.array([n[0], n[1], 1.0])
        cu, cv_ = project_points(intr, position)
        clipped = u - radius_px < 0 or v - radius_px < 0 or u + radius_px > w or \
            v + radius_px > h
        return PadDetection(time_s, "circle", position, (float(cu), float(cv_)),
                            float(radius_px), clipped=bool(clipped),
                            fit_error=float(max(0.0, 1.0 - best[0])) if math.isfinite(best[0])
                            else 1.0)
