"""The ball pipeline: coloured-ball detection (:mod:`autopilot.perception.ball`) and a
constant-velocity Kalman filter on the ball's world position (:mod:`autopilot.estimation.target`),
as a :class:`~autopilot.pipeline.Pipeline` of kind ``ball``."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.pose_history import PoseHistory
from autopilot.estimation.target import (
    NavigationUncertainty,
    TargetEstimate,
    TargetFilter,
    TargetFilterSettings,
    camera_measurement,
    navigation_drift_rate,
    with_navigation,
)
from autopilot.flightlog import records as ch
from autopilot.perception.ball import BallDetection, BallDetector, BallDetectorSettings
from autopilot.perception.colors import COLORS
from autopilot.pipeline import PipelineSpec, estimate_record, register
from drivers.base import CameraInfo, VehicleState
from drivers.camera_model import project_points
from drivers.geometry import quat_to_matrix

KIND = "ball"


@dataclass(frozen=True, slots=True)
class Hint:
    """Where the tracker expects the ball in a frame, and how big."""

    u_px: float
    v_px: float
    radius_px: float


def detector_settings(cfg: AppConfig) -> BallDetectorSettings:
    ball = cfg.perception.ball
    ranges = tuple(tuple(map(tuple, r)) for r in ball.hsv_ranges) if ball.hsv_ranges \
        else COLORS[ball.color][1]
    return BallDetectorSettings(
        hsv_ranges=ranges, diameter_m=ball.diameter_m, open_kernel_px=ball.open_kernel_px,
        close_kernel_px=ball.close_kernel_px, min_radius_px=ball.min_radius_px,
        max_radius_px=ball.max_radius_px, min_circularity=ball.min_circularity,
        min_fill_ratio=ball.min_fill_ratio, min_solidity=ball.min_solidity)


def filter_settings(cfg: AppConfig) -> TargetFilterSettings:
    t, n = cfg.estimation.target, cfg.estimation.navigation
    return TargetFilterSettings(
        accel_noise_m_s2=t.accel_noise_m_s2, gate_chi2=t.gate_chi2,
        stale_after_s=t.stale_after_s, initial_velocity_std_m_s=t.initial_velocity_std_m_s,
        max_extrapolation_s=t.max_extrapolation_s, pixel_noise_px=t.pixel_noise_px,
        radius_noise_px=t.radius_noise_px, restart_after=t.restart_after,
        confirm_after=t.confirm_after, navigation_noise_m=n.position_noise_m,
        navigation_drift_m2_s=(navigation_drift_rate(
            n.position_std_m, n.position_time_constant_s, n.position_smoothing_s,
            n.drift_window_s),) * 2 + (navigation_drift_rate(
                n.height_std_m, n.height_time_constant_s, n.position_smoothing_s,
                n.drift_window_s),))


def navigation_settings(cfg: AppConfig) -> NavigationUncertainty:
    n, mount = cfg.estimation.navigation, cfg.estimation.camera_mount_std_deg
    # the camera's mount error turns its view as the vehicle's attitude error does: σ per axis
    # of a rotation about the camera, which moves a target across its line of sight in every
    # direction (the attitude term; the yaw term is the heading's own error, counted once)
    return NavigationUncertainty(n.position_std_m,
                                 math.radians(math.hypot(n.attitude_std_deg, mount)),
                                 math.radians(n.yaw_std_deg), n.height_std_m)


class BallPipeline:
    kind = KIND

    def __init__(self, cfg: AppConfig, spec: PipelineSpec | None = None) -> None:
        spec = spec or ball_spec(cfg)
        self.name = spec.key
        self.camera = spec.camera
        self.detector = BallDetector(detector_settings(cfg))
        self.filter_settings = filter_settings(cfg)
        self.filter = TargetFilter(self.filter_settings)
        self.history = PoseHistory()
        self.border_noise_scale = cfg.estimation.target.border_noise_scale
        self.navigation = navigation_settings(cfg)

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)

    def hint(self, time_s: float, camera: CameraInfo) -> Hint | None:
        """Where the tracked target should appear in a frame captured at ``time_s``."""
        if self.filter.is_stale(time_s):
            return None
        est = self.filter.estimate(time_s)
        pose = self.history.pose_at(time_s)
        if est is None or pose is None:
            return None
        r_wb = quat_to_matrix(pose.attitude_q)
        p_cam = camera.rotation_body_cam.T @ (
            r_wb.T @ (est.position_ned_m - pose.position_ned_m) - camera.position_body_m)
        if p_cam[2] <= 0.1:
            return None
        u, v = project_points(camera.intrinsics, p_cam)  # where the lens puts it
        radius = camera.intrinsics.fx * self.detector.settings.diameter_m / 2.0 / \
            float(np.linalg.norm(p_cam))
        return Hint(float(u), float(v), radius)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: Hint | None) -> BallDetection | None:
        if hint is None:
            return self.detector.detect(image_bgr, camera, time_s)
        return self.detector.detect(image_bgr, camera, time_s, (hint.u_px, hint.v_px),
                                    hint.radius_px)

    def estimate(self, time_s: float, camera: CameraInfo,
                 detection: BallDetection) -> dict | None:
        """Fuse a detection; the flight log's estimate record, or None when the vehicle's pose
        at capture time is unknown (the detection is then not used)."""
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        meas = camera_measurement(
            detection.position_cam_m, detection.range_m, detection.radius_px, camera, pose,
            self.filter_settings, time_s,
            noise_scale=self.border_noise_scale if detection.cut_by_border else 1.0)
        result = self.filter.update(meas)
        est = self._with_navigation(self.filter.estimate(time_s), pose.position_ned_m)
        return estimate_record(self.name, time_s, result, meas, est)

    def target(self, time_s: float) -> TargetEstimate | None:
        """The estimate at ``time_s``, its σ including the vehicle's navigation errors."""
        est = self.filter.estimate(time_s)
        if est is None:
            return None
        vehicle = self.history.latest
        return self._with_navigation(est, vehicle.position_ned_m if vehicle is not None
                                     else est.position_ned_m)

    def _with_navigation(self, est: TargetEstimate, vehicle_position_ned_m) -> TargetEstimate:
        return with_navigation(est, vehicle_position_ned_m, self.navigation)

    def detection_record(self, seq: int, time_s: float, camera: str,
                         det: BallDetection | None, hint: Hint | None) -> dict:
        return detection_record(seq, time_s, camera, det, hint)

    def hint_from_record(self, record: dict) -> Hint | None:
        if record.get("hint_u_px") is None:
            return None
        return Hint(record["hint_u_px"], record["hint_v_px"], record["hint_radius_px"])


def ball_spec(cfg: AppConfig, truth_body: str = "ball") -> PipelineSpec:
    ball = cfg.perception.ball
    return PipelineSpec(KIND, ball.camera, truth_body=truth_body,
                        target_size_m=ball.diameter_m)


def detection_record(seq: int, time_s: float, camera: str, det: BallDetection | None,
                     hint: Hint | None) -> dict:
    """The flight log's record of one processed frame."""
    record = {"time_s": time_s, "seq": seq, "camera": camera, "detected": det is not None,
              "hint_u_px": hint.u_px if hint else None,
              "hint_v_px": hint.v_px if hint else None,
              "hint_radius_px": hint.radius_px if hint else None}
    if det is None:
        return {**record, "u_px": None, "v_px": None, "radius_px": None, "range_m": None,
                "position_cam_m": [None] * 3, "score": None, "candidates": 0,
                "cut_by_border": False}
    return {**record, "u_px": det.u_px, "v_px": det.v_px, "radius_px": det.radius_px,
            "range_m": det.range_m, "position_cam_m": det.position_cam_m, "score": det.score,
            "candidates": det.candidates, "cut_by_border": det.cut_by_border}


register(KIND, BallPipeline)
ch.register_schema(ch.detection_topic(KIND), ch.record_schema(
    "BallDetection", time_s=ch.NUM, seq=ch.INT, camera=ch.STR, detected=ch.BOOL, u_px=ch.NUM,
    v_px=ch.NUM, radius_px=ch.NUM, range_m=ch.NUM, position_cam_m=ch.vector_schema(3),
    score=ch.NUM, candidates=ch.INT, cut_by_border=ch.BOOL, processing_ms=ch.NUM,
    received_s=ch.NUM, detected_s=ch.NUM, hint_u_px=ch.NUM, hint_v_px=ch.NUM,
    hint_radius_px=ch.NUM))
