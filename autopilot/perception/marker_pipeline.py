"""The marker pipeline: a fiducial marker (:mod:`autopilot.perception.marker`) tracked in the
world — its centre by the constant-velocity Kalman filter of :mod:`autopilot.estimation.target`,
the direction its face points by :class:`~autopilot.estimation.heading.HeadingFilter` — as a
:class:`~autopilot.pipeline.Pipeline` of kind ``marker``.

The pose of a square marker is ambiguous when it is small or seen nearly head-on: its two IPPE
poses fit the corners about equally well and differ by a tilt mirrored about the line of sight.
Positions agree; face directions do not. The detector is given the predicted orientation as a
hint (it picks the nearer pose when the fit cannot tell), and here the heading of an ambiguous
detection is trusted less; if the chosen pose's heading falls outside the filter's gate and the
other pose's falls inside, the other one is used.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.heading import HeadingEstimate, HeadingFilter, HeadingSettings
from autopilot.estimation.pose_history import Pose, PoseHistory
from autopilot.estimation.target import (
    TargetEstimate,
    TargetFilter,
    camera_measurement,
    with_navigation,
)
from autopilot.flightlog import records as ch
from autopilot.perception.ball_pipeline import filter_settings, navigation_settings
from autopilot.perception.marker import (
    MarkerDetection,
    MarkerDetector,
    MarkerDetectorSettings,
    MarkerHint,
)
from autopilot.pipeline import PipelineSpec, estimate_record, register
from drivers.base import CameraInfo, VehicleState
from drivers.camera_model import project_points
from drivers.geometry import quat_to_matrix

KIND = "marker"
#: the face is "upright" enough to have a heading while its normal is this far from vertical
_MAX_NORMAL_DOWN = 0.9


def detector_settings(cfg: AppConfig) -> MarkerDetectorSettings:
    m = cfg.perception.marker
    return MarkerDetectorSettings(marker_id=m.id, size_m=m.size_m, dictionary=m.dictionary,
                                  backend=m.backend, corner_refinement=m.corner_refinement,
                                  min_perimeter_px=m.min_perimeter_px)


def marker_spec(cfg: AppConfig, truth_body: str = "marker") -> PipelineSpec:
    m = cfg.perception.marker
    return PipelineSpec(KIND, m.camera, truth_body=truth_body, target_size_m=m.size_m)


def face_rotation_ned(heading_rad: float) -> np.ndarray:
    """An upright marker whose face points along ``heading_rad``: its axes (columns; OpenCV's
    marker frame: x right as read, y up, z out of the face) in NED."""
    z = np.array([math.cos(heading_rad), math.sin(heading_rad), 0.0])
    y = np.array([0.0, 0.0, -1.0])
    return np.column_stack((np.cross(y, z), y, z))


def oriented_target(pipeline, kind: str, time_s: float,
                    vehicle_position_ned_m=None) -> TargetEstimate | None:
    """A pipeline's target with a heading (a marker's face, an image's top): the centre from
    ``pipeline.filter`` (σ including the vehicle's navigation errors) and the heading from
    ``pipeline.heading`` while it is fresh."""
    est = pipeline.filter.estimate(time_s)
    if est is None:
        return None
    if vehicle_position_ned_m is None:
        latest = pipeline.history.latest
        vehicle_position_ned_m = latest.position_ned_m if latest is not None \
            else est.position_ned_m
    est = with_navigation(est, vehicle_position_ned_m, pipeline.navigation)
    settings = pipeline.filter_settings
    heading: HeadingEstimate | None = pipeline.heading.estimate(time_s,
                                                                settings.max_extrapolation_s)
    fresh = heading is not None and heading.age_s <= settings.stale_after_s
    return dataclasses.replace(
        est, kind=kind,
        heading_rad=heading.heading_rad if fresh else None,
        heading_rate_rad_s=heading.rate_rad_s if fresh else 0.0,
        heading_std_rad=heading.std_rad if fresh else None)


class MarkerPipeline:
    kind = KIND

    def __init__(self, cfg: AppConfig, spec: PipelineSpec | None = None) -> None:
        spec = spec or marker_spec(cfg)
        self.name = spec.key
        self.camera = spec.camera
        self.detector = MarkerDetector(detector_settings(cfg))
        e = cfg.estimation.marker
        self.filter_settings = dataclasses.replace(
            filter_settings(cfg), pixel_noise_px=e.pixel_noise_px,
            radius_noise_px=e.size_noise_px)
        self.filter = TargetFilter(self.filter_settings)
        t = cfg.estimation.target
        self.heading = HeadingFilter(HeadingSettings(
            accel_noise_rad_s2=math.radians(e.heading_accel_noise_deg_s2),
            initial_rate_std_rad_s=math.radians(90.0), gate_chi2=10.8,
            stale_after_s=t.stale_after_s))
        self.heading_std_rad = math.radians(e.heading_noise_deg)
        self.ambiguous_heading_std_rad = math.radians(e.ambiguous_heading_noise_deg)
        self.history = PoseHistory()
        self.navigation = navigation_settings(cfg)
        self.size_m = cfg.perception.marker.size_m
        self._last_heading_used: str = ""

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)

    # -- detection --------------------------------------------------------------------------

    def hint(self, time_s: float, camera: CameraInfo) -> MarkerHint | None:
        """Where the tracked marker should appear in a frame captured at ``time_s``, how big,
        and its predicted orientation (to resolve an ambiguous pose)."""
        if self.filter.is_stale(time_s):
            return None
        est = self.filter.estimate(time_s)
        pose = self.history.pose_at(time_s)
        if est is None or pose is None:
            return None
        r_wc = self._r_world_cam(pose, camera)
        p_cam = r_wc.T @ (est.position_ned_m - self._camera_position(pose, camera))
        if p_cam[2] <= 0.1:
            return None
        u, v = project_points(camera.intrinsics, p_cam)
        size_px = camera.intrinsics.fx * self.size_m / float(np.linalg.norm(p_cam))
        heading = self.heading.estimate(time_s, self.filter_settings.max_extrapolation_s)
        rotation = None if heading is None else r_wc.T @ face_rotation_ned(heading.heading_rad)
        return MarkerHint((float(u), float(v)), size_px, rotation)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: MarkerHint | None) -> MarkerDetection | None:
        return self.detector.detect(image_bgr, camera, time_s, hint)

    # -- estimation -------------------------------------------------------------------------

    def estimate(self, time_s: float, camera: CameraInfo,
                 detection: MarkerDetection) -> dict | None:
        """Fuse a detection; the flight log's estimate record, or None when the vehicle's pose
        at capture time is unknown (the detection is then not used)."""
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        meas = camera_measurement(detection.position_cam_m, detection.range_m,
                                  detection.size_px / 2.0, camera, pose, self.filter_settings,
                                  time_s)
        result = self.filter.update(meas)
        heading_used = None
        if result.accepted:
            heading_used = self._update_heading(time_s, camera, pose, detection)
        est = self.target(time_s, pose.position_ned_m)
        return estimate_record(self.name, time_s, result, meas, est,
                               heading_rad=est.heading_rad, heading_std_rad=est.heading_std_rad,
                               heading_source=heading_used)

    def _update_heading(self, time_s: float, camera: CameraInfo, pose: Pose,
                        detection: MarkerDetection) -> str | None:
        """Fuse the face direction of the chosen pose, or of the other one when only that one
        agrees with the track. Which was used: "chosen", "alternative" or None."""
        r_wc = self._r_world_cam(pose, camera)
        std = self.ambiguous_heading_std_rad if detection.ambiguous else self.heading_std_rad
        candidates = [("chosen", detection.normal_cam)]
        if detection.ambiguous:
            candidates.append(("alternative", detection.alternative.normal_cam))
        for label, normal_cam in candidates:
            normal = r_wc @ normal_cam
            if abs(normal[2]) > _MAX_NORMAL_DOWN:
                continue
            heading = math.atan2(normal[1], normal[0])
            if self.heading.innovation2(time_s, heading, std) <= self.heading.settings.gate_chi2:
                self.heading.update(time_s, heading, std)
                return label
        return None

    def target(self, time_s: float, vehicle_position_ned_m=None) -> TargetEstimate | None:
        """The marker at ``time_s``: its centre (σ including the vehicle's navigation errors)
        and the direction its face points."""
        return oriented_target(self, KIND, time_s, vehicle_position_ned_m)

    # -- records ----------------------------------------------------------------------------

    def detection_record(self, seq: int, time_s: float, camera: str,
                         det: MarkerDetection | None, hint: MarkerHint | None) -> dict:
        return detection_record(seq, time_s, camera, det, hint)

    def hint_from_record(self, record: dict) -> MarkerHint | None:
        if record.get("hint_u_px") is None:
            return None
        q = record.get("hint_quaternion_cam_marker")
        rotation = quat_to_matrix(np.asarray(q, float)) if q and None not in q else None
        return MarkerHint((record["hint_u_px"], record["hint_v_px"]),
                          2.0 * record["hint_radius_px"], rotation)

    @staticmethod
    def _r_world_cam(pose: Pose, camera: CameraInfo) -> np.ndarray:
        return quat_to_matrix(pose.attitude_q) @ camera.rotation_body_cam

    @staticmethod
    def _camera_position(pose: Pose, camera: CameraInfo) -> np.ndarray:
        return pose.position_ned_m + quat_to_matrix(pose.attitude_q) @ camera.position_body_m


def detection_record(seq: int, time_s: float, camera: str, det: MarkerDetection | None,
                     hint: MarkerHint | None) -> dict:
    """The flight log's record of one processed frame. ``u_px``/``v_px`` (the marker's centre
    in the image) and ``radius_px`` (half its side) mean what they mean for any target."""
    from drivers.geometry import matrix_to_quat

    has_hint = hint is not None and hint.center_px is not None
    record = {"time_s": time_s, "seq": seq, "camera": camera, "detected": det is not None,
              "hint_u_px": hint.center_px[0] if has_hint else None,
              "hint_v_px": hint.center_px[1] if has_hint else None,
              "hint_radius_px": hint.size_px / 2.0 if has_hint and hint.size_px else None,
              "hint_quaternion_cam_marker":
                  matrix_to_quat(hint.rotation_cam_marker) if has_hint
                  and hint.rotation_cam_marker is not None else None}
    if det is None:
        return {**record, "u_px": None, "v_px": None, "radius_px": None, "range_m": None,
                "position_cam_m": [None] * 3, "marker_id": None, "corners_px": None,
                "quaternion_cam_marker": None, "reprojection_error_px": None,
                "ambiguity_ratio": None, "ambiguous": None, "chosen_by": None,
                "other_ids": [], "score": None}
    u, v = det.center_px
    return {**record, "u_px": float(u), "v_px": float(v), "radius_px": det.size_px / 2.0,
            "range_m": det.range_m, "position_cam_m": det.position_cam_m,
            "marker_id": det.marker_id, "corners_px": det.corners_px.reshape(-1),
            "quaternion_cam_marker": det.quaternion,
            "reprojection_error_px": det.reprojection_error_px,
            "ambiguity_ratio": det.ambiguity_ratio, "ambiguous": det.ambiguous,
            "chosen_by": det.chosen_by, "other_ids": list(det.other_ids), "score": None}


register(KIND, MarkerPipeline)
ch.register_schema(ch.detection_topic(KIND), ch.detection_schema(
    "MarkerDetection", marker_id=ch.INT, corners_px=ch.nullable_array(8),
    quaternion_cam_marker=ch.nullable_array(4), reprojection_error_px=ch.NUM,
    ambiguity_ratio=ch.NUM, ambiguous=ch.BOOL, chosen_by=ch.STR,
    other_ids={"type": "array", "items": {"type": "integer"}},
    hint_quaternion_cam_marker=ch.nullable_array(4)))
