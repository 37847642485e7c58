"""The pad pipeline: a landing pad (:mod:`autopilot.perception.pad`) tracked in the world — its
centre by the constant-velocity Kalman filter of :mod:`autopilot.estimation.target`, a marker
pad's heading by :class:`~autopilot.estimation.heading.HeadingFilter` — as a
:class:`~autopilot.pipeline.Pipeline` of kind ``pad``.

What to look for is the step's, in ``PipelineSpec.target`` (:func:`pad_target`):
``circle:<colour>`` or ``markers:<id>,<id>,…`` (the centre marker first), and its size.

Range. A marker pad's PnP pose carries its own range. A circle's apparent size gives one too,
but a pixel of blur is a few per cent of it from high up, and near the ground the disc overflows
the frame. So when the rangefinder reads, the circle's outline is placed on the ground instead:
each outline point's ray, turned into the world with the attitude at capture time, meets the
ground at the height the rangefinder measured (its reading along the body's z axis, projected on
the vertical); the circle fitted there gives the centre, and its diameter must match the pad's
(``perception.pad.size_tolerance``) — another object of that colour does not.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.pose_history import Pose, PoseHistory
from autopilot.estimation.target import (
    TargetEstimate,
    camera_measurement,
)
from autopilot.flightlog import records as ch
from autopilot.perception.ball_pipeline import navigation_settings
from autopilot.perception.colors import COLORS
from autopilot.perception.image_pipeline import image_heading, set_ground_target_filters
from autopilot.perception.marker_pipeline import oriented_target
from autopilot.perception.pad import (
    CirclePadDetector,
    CirclePadSettings,
    MarkerPadDetector,
    MarkerPadSettings,
    PadDetection,
    fit_circle,
    marker_pad_layout,
)
from autopilot.pipeline import PipelineSpec, estimate_record, register
from drivers.base import CameraInfo, VehicleState
from drivers.geometry import matrix_to_quat, quat_to_matrix

KIND = "pad"
DEFAULT_IDS = (0, 1, 2, 3, 4)


def pad_target(kind: str, color: str = "red", ids=DEFAULT_IDS) -> str:
    """The spec's ``target`` for a pad: ``circle:red``, ``markers:0,1,2,3,4``."""
    if kind == "circle":
        return f"circle:{color}"
    return "markers:" + ",".join(str(int(i)) for i in ids)


def parse_pad_target(target: str) -> tuple[str, str, tuple[int, ...]]:
    """(kind, colour, ids) of a spec's ``target``."""
    kind, _, rest = (target or "circle:red").partition(":")
    if kind == "circle":
        return kind, rest or "red", DEFAULT_IDS
    if kind == "markers":
        return kind, "", tuple(int(i) for i in rest.split(",")) if rest else DEFAULT_IDS
    raise ValueError(f"unknown pad {target!r} (expected circle:<colour> or markers:<ids>)")


def pad_spec(cfg: AppConfig, kind: str = "circle", size_m: float = 0.8, *, color: str = "red",
             ids=DEFAULT_IDS, truth_body: str = "pad") -> PipelineSpec:
    return PipelineSpec(KIND, cfg.perception.pad.camera, truth_body=truth_body,
                        target_size_m=size_m, target=pad_target(kind, color, ids))


def make_detector(cfg: AppConfig, target: str, size_m: float, detector: str | None = None):
    """The pad's detector (``detector``: ours or seed001; default the configuration's)."""
    kind, color, ids = parse_pad_target(target)
    p = cfg.perception.pad
    if (detector or p.detector) == "seed001":
        if kind != "circle":
            raise ValueError("perception.pad.detector: seed001 (template matching) finds "
                             "circle pads only")
        from autopilot.perception.baselines import Seed001PadDetector

        return Seed001PadDetector(color, size_m)
    if kind == "circle":
        ranges = tuple(tuple(map(tuple, r)) for r in p.hsv_ranges) if p.hsv_ranges \
            else COLORS[color][1]
        return CirclePadDetector(CirclePadSettings(
            diameter_m=size_m, hsv_ranges=ranges, min_radius_px=p.min_radius_px,
            max_fit_error=p.max_fit_error))
    return MarkerPadDetector(MarkerPadSettings(
        marker_pad_layout(size_m, ids, p.dictionary), backend=p.backend,
        min_perimeter_px=p.min_perimeter_px))


@dataclasses.dataclass(frozen=True, slots=True)
class GroundFit:
    """A circle pad's outline placed on the ground: its centre (NED) and diameter there."""

    centre_ned_m: np.ndarray
    diameter_m: float
    height_m: float  # the camera's height above the ground


def ground_level(state: VehicleState) -> float:
    """The ground's level under the vehicle (local NED down) from its rangefinder reading
    (along the body's z axis); NaN without a reading, or tilted more than 60°."""
    r = state.distance_to_ground_m
    tilt_cos = float(quat_to_matrix(state.attitude_q)[2, 2])
    if not math.isfinite(r) or tilt_cos < 0.5:
        return math.nan
    return float(state.position_ned_m[2]) + r * tilt_cos


def ground_fit(detection: PadDetection, camera: CameraInfo, pose: Pose,
               range_m: float = math.nan, *,
               ground_down_m: float = math.nan) -> GroundFit | None:
    """The circle's outline on the ground plane: at ``ground_down_m`` (local NED), or
    ``range_m`` (a rangefinder's reading along the body's z axis) below the vehicle."""
    if detection.outline_norm is None:
        return None
    r_world_body = quat_to_matrix(pose.attitude_q)
    if math.isfinite(ground_down_m):
        ground_down = ground_down_m
    elif math.isfinite(range_m) and r_world_body[2, 2] >= 0.5:
        ground_down = pose.position_ned_m[2] + range_m * r_world_body[2, 2]
    else:
        return None
    cam = pose.position_ned_m + r_world_body @ camera.position_body_m
    r_world_cam = r_world_body @ camera.rotation_body_cam
    n = detection.outline_norm
    rays = r_world_cam @ np.column_stack([n, np.ones(len(n))]).T  # 3 × N
    height = ground_down - cam[2]
    if height <= 0.02 or np.any(rays[2] <= 1e-3):
        return None
    t = height / rays[2]
    points = cam[:2, None] + rays[:2] * t  # 2 × N on the ground
    centre, radius, _ = fit_circle(points.T)
    return GroundFit(np.array([centre[0], centre[1], ground_down]), 2.0 * radius, height)


class PadPipeline:
    kind = KIND

    def __init__(self, cfg: AppConfig, spec: PipelineSpec | None = None) -> None:
        spec = spec or pad_spec(cfg)
        self.name = spec.key
        self.camera = spec.camera
        self.size_m = spec.target_size_m
        self.pad_kind = parse_pad_target(spec.target)[0]
        self.detector = make_detector(cfg, spec.target, self.size_m)
        self.size_tolerance = cfg.perception.pad.size_tolerance
        e = cfg.estimation.pad
        self.height_noise_m = e.height_noise_m
        set_ground_target_filters(self, cfg, e)
        self.history = PoseHistory()
        self._ranges: deque[tuple[float, float]] = deque(maxlen=200)  # (time, ground level)
        self._last_reading = math.nan
        self.navigation = navigation_settings(cfg)
        self.last_fit: GroundFit | None = None

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)
        # the ground's level at each new reading, when it first shows: telemetry repeats the
        # last reading (a rangefinder at 10 Hz, positions at 50 Hz), and a held reading with
        # a newer altitude would put the ground wrong by the climb since the reading
        r = state.distance_to_ground_m
        if math.isfinite(r) and r != self._last_reading:
            level = ground_level(state)
            if math.isfinite(level):
                self._ranges.append((state.time_s, level))
        self._last_reading = r

    def ground_at(self, time_s: float, max_gap_s: float = 0.5, count: int = 5) -> float:
        """The ground's level (local NED down): the median of the ``count`` readings nearest
        ``time_s`` within ``max_gap_s`` (a lone outlier — a missed return read as the maximum
        range, a short reading off debris — is voted out); NaN: none that close."""
        near: list[tuple[float, float]] = []
        for t, level in reversed(self._ranges):
            if abs(t - time_s) <= max_gap_s:
                near.append((abs(t - time_s), level))
            elif t < time_s - max_gap_s:
                break
        if not near:
            return math.nan
        near.sort()
        return float(np.median([level for _, level in near[:count]]))

    def hint(self, time_s: float, camera: CameraInfo) -> None:
        return None  # the whole frame is searched (colour masks and markers are cheap)

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None) -> PadDetection | None:
        return self.detector.detect(image_bgr, camera, time_s)

    def estimate(self, time_s: float, camera: CameraInfo, detection: PadDetection) -> dict | None:
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        position_cam = detection.position_cam_m
        radius_px = detection.radius_px
        noise_scale = 1.0
        self.last_fit = None
        if detection.kind == "circle":
            fit = ground_fit(detection, camera, pose, ground_down_m=self.ground_at(time_s))
            if fit is not None:
                if abs(fit.diameter_m / self.size_m - 1.0) > self.size_tolerance:
                    return None  # the wrong size for the pad (or the reading is not its ground)
                self.last_fit = fit
                r_world_body = quat_to_matrix(pose.attitude_q)
                r_world_cam = r_world_body @ camera.rotation_body_cam
                cam = pose.position_ned_m + r_world_body @ camera.position_body_m
                position_cam = r_world_cam.T @ (fit.centre_ned_m - cam)
                # range noise: the height's (as an apparent radius that would give it)
                radius_px = float(np.linalg.norm(position_cam)) \
                    * self.filter_settings.radius_noise_px / self.height_noise_m
            elif detection.clipped:
                noise_scale = 3.0  # a cut disc's size says little about its range
        meas = camera_measurement(position_cam, float(np.linalg.norm(position_cam)), radius_px,
                                  camera, pose, self.filter_settings, time_s, noise_scale)
        result = self.filter.update(meas)
        if result.accepted and detection.rotation_cam_pad is not None:
            r_world_cam = quat_to_matrix(pose.attitude_q) @ camera.rotation_body_cam
            heading = image_heading(r_world_cam @ detection.rotation_cam_pad)
            if self.heading.innovation2(time_s, heading, self.heading_std_rad) <= \
                    self.heading.settings.gate_chi2:
                self.heading.update(time_s, heading, self.heading_std_rad)
        est = self.target(time_s, pose.position_ned_m)
        return estimate_record(self.name, time_s, result, meas, est,
                               heading_rad=est.heading_rad, heading_std_rad=est.heading_std_rad,
                               ground_fit=self.last_fit is not None)

    def target(self, time_s: float, vehicle_position_ned_m=None) -> TargetEstimate | None:
        """The pad at ``time_s``: its centre (σ including the vehicle's navigation errors) and,
        for a marker pad, the heading of its top."""
        return oriented_target(self, KIND, time_s, vehicle_position_ned_m)

    def detection_record(self, seq: int, time_s: float, camera: str,
                         det: PadDetection | None, hint: object | None) -> dict:
        return detection_record(seq, time_s, camera, det)

    def hint_from_record(self, record: dict) -> None:
        return None


def detection_record(seq: int, time_s: float, camera: str, det: PadDetection | None) -> dict:
    """The flight log's record of one processed frame (``u_px``/``v_px``: the pad's centre;
    ``radius_px``: half its apparent width, as for any target)."""
    record = {"time_s": time_s, "seq": seq, "camera": camera, "detected": det is not None,
              "hint_u_px": None, "hint_v_px": None, "hint_radius_px": None}
    if det is None:
        return {**record, "u_px": None, "v_px": None, "radius_px": None, "range_m": None,
                "position_cam_m": [None] * 3, "quaternion_cam_pad": None, "clipped": None,
                "ids": None, "fit_error": None, "score": None}
    u, v = det.center_px
    return {**record, "u_px": u, "v_px": v, "radius_px": det.radius_px, "range_m": det.range_m,
            "position_cam_m": det.position_cam_m,
            "quaternion_cam_pad": None if det.rotation_cam_pad is None
            else matrix_to_quat(det.rotation_cam_pad),
            "clipped": det.clipped, "ids": list(det.ids), "fit_error": det.fit_error,
            "score": None}


register(KIND, PadPipeline)
ch.register_schema(ch.detection_topic(KIND), ch.detection_schema(
    "PadDetection", quaternion_cam_pad=ch.nullable_array(4), clipped=ch.BOOL,
    ids=ch.nullable_array(items={"type": "integer"}), fit_error=ch.NUM))
