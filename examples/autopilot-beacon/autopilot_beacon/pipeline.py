"""The beacon's perception pipeline (kind ``beacon``): the colour's largest blob in the down
camera, its centre's ray placed on the ground with the vehicle's pose at the frame's capture
time, and those fixes smoothed into a position estimate."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import cv2
import numpy as np

from autopilot.estimation.pose_history import PoseHistory
from autopilot.estimation.target import TargetEstimate, UpdateResult
from autopilot.pipeline import PipelineSpec, estimate_record, register
from drivers.base import CameraInfo, VehicleState
from drivers.camera_model import pixel_rays
from drivers.geometry import quat_to_matrix

KIND = "beacon"


@dataclass(frozen=True, slots=True)
class BeaconDetection:
    u_px: float
    v_px: float
    area_px: float
    score: float  # the blob's share of its bounding box (a square seen from above: near 1)


def settings_of(config):
    return config.targets[KIND]


def beacon_spec(config, size_m: float) -> PipelineSpec:
    return PipelineSpec(KIND, settings_of(config).camera, truth_body="beacon",
                        target_size_m=size_m)


class BeaconPipeline:
    kind = KIND

    def __init__(self, config, spec: PipelineSpec) -> None:
        self.name = spec.key
        self.camera = spec.camera
        self.settings = settings_of(config)
        self.history = PoseHistory()
        self._position: np.ndarray | None = None
        self._fix_s = -np.inf
        self._updates = 0

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)

    def hint(self, time_s: float, camera: CameraInfo) -> None:
        return None  # the whole frame is searched (a blob of colour is cheap to find)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None) -> BeaconDetection | None:
        s = self.settings
        hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
        mask = cv2.inRange(hsv, np.array(s.hsv_low, np.uint8), np.array(s.hsv_high, np.uint8))
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return None
        blob = max(contours, key=cv2.contourArea)
        area = float(cv2.contourArea(blob))
        if area < s.min_area_px:
            return None
        m = cv2.moments(blob)
        _, _, w, h = cv2.boundingRect(blob)
        return BeaconDetection(m["m10"] / m["m00"], m["m01"] / m["m00"], area,
                               min(1.0, area / max(w * h, 1)))

    def estimate(self, time_s: float, camera: CameraInfo,
                 detection: BeaconDetection) -> dict | None:
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        r_wb = quat_to_matrix(pose.attitude_q)
        ray = r_wb @ camera.rotation_body_cam @ pixel_rays(
            camera.intrinsics, np.array([detection.u_px, detection.v_px]))
        origin = pose.position_ned_m + r_wb @ camera.position_body_m
        if ray[2] <= 1e-3:
            return None  # not towards the ground
        fix = origin + (-origin[2] / ray[2]) * ray  # where the ray meets the ground (z = 0)
        a = self.settings.smoothing
        first = self._position is None
        self._position = fix if first else (1.0 - a) * self._position + a * fix
        self._fix_s, self._updates = time_s, self._updates + 1
        return estimate_record(self.name, time_s, UpdateResult(True, 0.0, first),
                               SimpleNamespace(position_ned_m=fix), self.target(time_s))

    def target(self, time_s: float) -> TargetEstimate | None:
        if self._position is None:
            return None
        age = max(0.0, time_s - self._fix_s)
        sigma = self.settings.fix_noise_m * np.sqrt(self.settings.smoothing)
        cov = np.diag([sigma ** 2] * 3 + [0.05 ** 2] * 3)
        return TargetEstimate(time_s, self._position.copy(), np.zeros(3), cov, age,
                              age > self.settings.stale_after_s, self._updates,
                              self._updates >= 3)

    def detection_record(self, seq: int, time_s: float, camera: str,
                         det: BeaconDetection | None, hint: object | None) -> dict:
        record = {"time_s": time_s, "seq": seq, "camera": camera, "detected": det is not None}
        if det is None:
            return {**record, "u_px": None, "v_px": None, "area_px": None, "score": None}
        return {**record, "u_px": det.u_px, "v_px": det.v_px, "area_px": det.area_px,
                "score": det.score}

    def hint_from_record(self, record: dict) -> None:
        return None


register(KIND, BeaconPipeline)
