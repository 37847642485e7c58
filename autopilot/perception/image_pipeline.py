"""The image pipeline: a known flat image (:mod:`autopilot.perception.image_target`) tracked in
the world — its centre by the constant-velocity Kalman filter of
:mod:`autopilot.estimation.target`, the direction of its top by
:class:`~autopilot.estimation.heading.HeadingFilter` — as a
:class:`~autopilot.pipeline.Pipeline` of kind ``image``.

Which image, and its printed width, are the step's (``PipelineSpec.target`` — the generated
default or a file — and ``target_size_m``); how it is found is ``perception.image``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.heading import HeadingFilter, HeadingSettings
from autopilot.estimation.level_mount import LevelMountEstimator, LevelMountSettings
from autopilot.estimation.pose_history import PoseHistory
from autopilot.estimation.target import (
    TargetEstimate,
    TargetFilter,
    camera_measurement,
)
from autopilot.flightlog import records as ch
from autopilot.perception.ball_pipeline import filter_settings, navigation_settings
from autopilot.perception.image_target import (
    DEFAULT_TARGET,
    ImageTargetDetection,
    ImageTargetDetector,
    ImageTargetSettings,
    load_target_image,
)
from autopilot.perception.marker_pipeline import oriented_target
from autopilot.pipeline import PipelineSpec, estimate_record, register
from drivers.base import CameraInfo, VehicleState
from drivers.geometry import matrix_to_quat, quat_to_matrix

KIND = "image"


def detector_settings(cfg: AppConfig, size_m: float) -> ImageTargetSettings:
    i = cfg.perception.image
    return ImageTargetSettings(size_m=size_m, features=i.features,
                               reference_features=i.reference_features,
                               frame_features=i.frame_features, reference_px=i.reference_px,
                               ratio=i.ratio, ransac_px=i.ransac_px, min_inliers=i.min_inliers,
                               track_frames=i.track_frames)


def set_ground_target_filters(pipeline, cfg: AppConfig, e) -> None:
    """A target lying on the ground (an image, a pad): its position filter with the noises of
    its estimation section ``e`` (``estimation.image`` / ``.pad``), and the filter of the
    heading of its top."""
    pipeline.filter_settings = dataclasses.replace(
        filter_settings(cfg), pixel_noise_px=e.position_noise_px,
        radius_noise_px=e.size_noise_px, accel_noise_m_s2=e.accel_noise_m_s2,
        initial_velocity_std_m_s=e.initial_velocity_std_m_s)
    pipeline.filter = TargetFilter(pipeline.filter_settings)
    pipeline.heading = HeadingFilter(HeadingSettings(
        accel_noise_rad_s2=math.radians(30.0), initial_rate_std_rad_s=math.radians(30.0),
        gate_chi2=10.8, stale_after_s=cfg.estimation.target.stale_after_s))
    pipeline.heading_std_rad = math.radians(e.heading_noise_deg)


def image_spec(cfg: AppConfig, image: str = DEFAULT_TARGET, size_m: float = 1.0,
               truth_body: str = "image") -> PipelineSpec:
    return PipelineSpec(KIND, cfg.perception.image.camera, truth_body=truth_body,
                        target_size_m=size_m, target=image)


def image_heading(rotation_world_image: np.ndarray) -> float:
    """The heading (NED) of the image's top: its −y axis, in the horizontal plane."""
    top = -rotation_world_image[:, 1]
    return math.atan2(top[1], top[0])


class ImagePipeline:
    kind = KIND

    def __init__(self, cfg: AppConfig, spec: PipelineSpec | None = None) -> None:
        spec = spec or image_spec(cfg)
        self.name = spec.key
        self.camera = spec.camera
        self.size_m = spec.target_size_m
        reference = load_target_image(spec.target or DEFAULT_TARGET)
        if cfg.perception.image.detector == "seed000":
            from autopilot.perception.baselines import Seed000ImageDetector

            self.detector = Seed000ImageDetector(reference, self.size_m)
        else:
            self.detector = ImageTargetDetector(reference, detector_settings(cfg, self.size_m))
        set_ground_target_filters(self, cfg, cfg.estimation.image)
        self.history = PoseHistory()
        self.navigation = navigation_settings(cfg)
        self._attitude_std_deg = cfg.estimation.navigation.attitude_std_deg
        e = cfg.estimation.image
        #: the down camera's mount tilt learned from the image, which lies level
        self.mount = LevelMountEstimator(LevelMountSettings(
            e.mount_min_frames, max_tilt_deg=e.mount_max_tilt_deg,
            residual_std_deg=e.mount_residual_std_deg)) \
            if e.learn_mount and cfg.estimation.camera_mount_std_deg > 0.0 else None
        self._mount_camera: CameraInfo | None = None  # as corrected on the last frame

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)

    def hint(self, time_s: float, camera: CameraInfo) -> None:
        return None  # the whole frame is searched (the detector tracks between searches)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None) -> ImageTargetDetection | None:
        return self.detector.detect(image_bgr, camera, time_s)

    def estimate(self, time_s: float, camera: CameraInfo,
                 detection: ImageTargetDetection) -> dict | None:
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        nominal = camera
        width_px = camera.intrinsics.fx * self.size_m / max(detection.range_m, 1e-6)

        def measured(cam: CameraInfo):
            return camera_measurement(detection.position_cam_m, detection.range_m,
                                      width_px / 2.0, cam, pose, self.filter_settings, time_s)

        if self.mount is None:
            meas = measured(nominal)
        else:
            camera = self.mount.corrected(nominal)
            meas = measured(camera)
            # the estimate moves as the correction does (all at once when first learned)
            before = self._mount_camera or nominal
            if before is not camera:
                self.filter.shift(meas.position_ned_m - measured(before).position_ned_m)
            self._mount_camera = camera
        result = self.filter.update(meas)
        if result.accepted:
            r_world_body = quat_to_matrix(pose.attitude_q)
            if self.mount is not None:
                self._learn_mount(r_world_body, nominal, detection.rotation_cam_image)
            r_world_cam = r_world_body @ camera.rotation_body_cam
            heading = image_heading(r_world_cam @ detection.rotation_cam_image)
            if self.heading.innovation2(time_s, heading, self.heading_std_rad) <= \
                    self.heading.settings.gate_chi2:
                self.heading.update(time_s, heading, self.heading_std_rad)
        est = self.target(time_s, pose.position_ned_m)
        learned = self.mount.estimate() if self.mount is not None else None
        return estimate_record(self.name, time_s, result, meas, est,
                               heading_rad=est.heading_rad, heading_std_rad=est.heading_std_rad,
                               mount_tilt_deg=None if learned is None else list(learned.tilt_deg))

    def _learn_mount(self, r_world_body: np.ndarray, camera: CameraInfo,
                     r_cam_image: np.ndarray) -> None:
        """One more frame of the level image for the mount's tilt; once learned, the
        estimate's σ carries the learned tilt's uncertainty instead of the mount's."""
        if not self.mount.add(r_world_body, camera, r_cam_image):
            return
        learned = self.mount.estimate()
        if learned is not None:
            self.navigation = dataclasses.replace(self.navigation, attitude_std_rad=math.radians(
                math.hypot(self._attitude_std_deg, learned.std_deg)))

    def target(self, time_s: float, vehicle_position_ned_m=None) -> TargetEstimate | None:
        """The image at ``time_s``: its centre (σ including the vehicle's navigation errors)
        and the heading of its top."""
        return oriented_target(self, KIND, time_s, vehicle_position_ned_m)

    def detection_record(self, seq: int, time_s: float, camera: str,
                         det: ImageTargetDetection | None, hint: object | None) -> dict:
        return detection_record(seq, time_s, camera, det)

    def hint_from_record(self, record: dict) -> None:
        return None


def detection_record(seq: int, time_s: float, camera: str,
                     det: ImageTargetDetection | None) -> dict:
    """The flight log's record of one processed frame. ``u_px``/``v_px`` (the image's centre)
    and ``radius_px`` (half its apparent width) mean what they mean for any target."""
    record = {"time_s": time_s, "seq": seq, "camera": camera, "detected": det is not None,
              "hint_u_px": None, "hint_v_px": None, "hint_radius_px": None}
    if det is None:
        return {**record, "u_px": None, "v_px": None, "radius_px": None, "range_m": None,
                "position_cam_m": [None] * 3, "corners_px": None,
                "quaternion_cam_image": None, "matches": None, "inliers": None,
                "reprojection_error_px": None, "score": None, "tracked": None}
    u, v = det.center_px
    width = float(np.linalg.norm(det.corners_px[1] - det.corners_px[0]))
    return {**record, "u_px": u, "v_px": v, "radius_px": width / 2.0, "range_m": det.range_m,
            "position_cam_m": det.position_cam_m, "corners_px": det.corners_px.reshape(-1),
            "quaternion_cam_image": matrix_to_quat(det.rotation_cam_image),
            "matches": det.matches, "inliers": det.inliers,
            "reprojection_error_px": det.reprojection_error_px, "score": None,
            "tracked": det.tracked}


register(KIND, ImagePipeline)
ch.register_schema(ch.detection_topic(KIND), ch.detection_schema(
    "ImageTargetDetection", corners_px=ch.nullable_array(8),
    quaternion_cam_image=ch.nullable_array(4), matches=ch.INT, inliers=ch.INT,
    reprojection_error_px=ch.NUM, tracked=ch.BOOL))
