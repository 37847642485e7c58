"""What the relative-state filter of the rover landing takes and gives: its settings, the
deck's geometry, its estimate and its per-update results, and a tag detection turned into a
relative position measurement (:func:`tag_measurement`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, slots=True)
class RelativeSettings:
    accel_noise_m_s2: float = 0.5
    jerk_noise_m_s3: float = 3.0
    accel_time_constant_s: float = 2.0
    vertical_accel_noise_m_s2: float = 0.3
    yaw_accel_noise_rad_s2: float = 0.5
    drone_velocity_noise_m_s: float = 0.03
    uwb_range_noise_m: float = 0.1
    uwb_gate_chi2: float = 9.0
    rangefinder_noise_m: float = 0.02
    range_gate_chi2: float = 9.0
    rover_velocity_noise_m_s: float = 0.1
    rover_heading_noise_rad: float = math.radians(4.0)
    compass_bias_std_rad: float = math.radians(3.0)
    compass_bias_time_constant_s: float = 120.0
    course_noise_rad: float = math.radians(1.5)  # beyond the velocity noise's share (skid)
    course_min_speed_m_s: float = 0.5
    rough_position_std_m: tuple[float, float, float] = (1.5, 1.5, 1.5)
    rough_white_std_m: float = 0.2  # the part of the rough position's error that is not a bias
    bias_time_constant_s: float = 120.0
    gate_chi2: float = 16.3
    history_s: float = 1.0
    max_extrapolation_s: float = 0.5
    initial_velocity_std_m_s: float = 1.0
    initial_yaw_rate_std_rad_s: float = 0.3


@dataclass(frozen=True, slots=True)
class DeckGeometry:
    """The rover as the filter knows it: the deck (length along the rover, width) and its top's
    height above the rover's reference point; UWB anchors (FRD from the reference point) and
    the drone's tag (body FRD)."""

    deck_size_m: tuple[float, float]
    deck_height_m: float
    anchors_frd_m: tuple[tuple[float, float, float], ...] = ()
    tag_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True, eq=False)
class RelativeEstimate:
    time_s: float  # what the state is at
    position_m: np.ndarray  # drone − deck centre (NED)
    velocity_m_s: np.ndarray
    covariance: np.ndarray  # 6 × 6, position then velocity
    heading_rad: float
    heading_std_rad: float
    yaw_rate_rad_s: float
    bias_m: np.ndarray
    rover_acceleration_m_s2: np.ndarray  # NED (horizontal; down 0)
    #: when each source last updated the filter (−inf: never)
    last_update_s: dict[str, float]

    @property
    def position_std_m(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance)[:3])


@dataclass(frozen=True, slots=True)
class FusionResult:
    source: str
    time_s: float
    accepted: bool
    mahalanobis2: float  # the largest over the measurement's parts
    parts: int = 1  # ranges fused (UWB), or 1
    late: bool = False  # inserted before newer data (replayed)


@dataclass(frozen=True, slots=True)
class TagMeasurement:
    """A tag detection turned into the drone's position relative to the deck (NED)."""

    relative_m: np.ndarray
    covariance: np.ndarray
    heading_rad: float | None
    heading_std_rad: float
    range_m: float = field(default=math.nan)


def tag_measurement(position_cam_m, rotation_cam_pad, r_world_body: np.ndarray,
                    rotation_body_cam: np.ndarray, camera_position_body_m, fx_px: float, *,
                    pixel_noise_px: float, range_noise_fraction: float,
                    attitude_std_rad: float, heading_std_rad: float) -> TagMeasurement:
    """The drone's body origin relative to the deck's centre (the tag's), from the tag's
    position in the camera frame, the camera's mounting and the drone's attitude at capture
    time. Noise: the bearing's (``pixel_noise_px`` at focal length ``fx_px``) and the range's
    (a fraction of it) in the camera frame, plus the attitude's error times the range."""
    p_cam = np.asarray(position_cam_m, dtype=float)
    r_world_cam = r_world_body @ rotation_body_cam
    offset = r_world_body @ np.asarray(camera_position_body_m, dtype=float) \
        + r_world_cam @ p_cam
    rng = float(np.linalg.norm(p_cam))
    lateral = rng * pixel_noise_px / fx_px
    along = max(range_noise_fraction * rng, 0.003)
    cov_cam = np.diag([lateral ** 2, lateral ** 2, along ** 2])
    cov = r_world_cam @ cov_cam @ r_world_cam.T + np.eye(3) * (rng * attitude_std_rad) ** 2 \
        + np.eye(3) * 0.003 ** 2
    heading = None
    if rotation_cam_pad is not None:
        top = -(r_world_cam @ np.asarray(rotation_cam_pad, dtype=float))[:, 1]
        heading = math.atan2(top[1], top[0])
    return TagMeasurement(-offset, cov, heading, heading_std_rad, rng)
