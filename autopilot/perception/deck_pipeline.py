"""The deck pipeline: a rover's landing deck tracked relative to the drone — the relative-state
filter of :mod:`autopilot.estimation.relative`, fed by the deck's tag in the down camera's
frames, the vehicle's UWB ranges and the rover's own reports (:meth:`DeckPipeline.add_sensor`),
the rangefinder and the drone's velocity (telemetry) — as a :class:`~autopilot.pipeline.Pipeline`
of kind ``deck``.

Its target (what ``land_on_rover`` flies on) is the deck's top centre *in the drone's own local
frame*: the drone's position estimate at that moment minus the relative position. The drone's
own navigation error is common to both, so the offboard setpoint built on it puts the vehicle
over the deck whatever that error is; its covariance is the relative one.

``PipelineSpec.target`` says which sources this landing uses: ``uwb=1,tag=1`` (seed 004's
``use_uwb`` / ``use_marker``). Without the tag the pipeline reads no camera.
"""

from __future__ import annotations

import math

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.pose_history import PoseHistory
from autopilot.estimation.relative import RelativeFilter
from autopilot.estimation.relative_types import (
    DeckGeometry,
    RelativeEstimate,
    RelativeSettings,
    tag_measurement,
)
from autopilot.estimation.seed004 import Seed004Filter, Seed004Settings
from autopilot.estimation.target import TargetEstimate
from autopilot.flightlog import records as ch
from autopilot.perception.pad import MarkerPadDetector, MarkerPadSettings, marker_pad_layout
from autopilot.perception.pad_pipeline import detection_record
from autopilot.pipeline import PipelineSpec, register
from drivers.base import CameraInfo, RoverState, UwbRanges, VehicleState
from drivers.geometry import quat_to_matrix

KIND = "deck"
ROVER_BODY = "rover"  # the simulator's truth body of a scenario's rover (its deck's top centre)
#: no update from UWB, the tag or the rover's reports for this long: the estimate is stale
STALE_AFTER_S = 1.5


def deck_spec(cfg: AppConfig, use_uwb: bool = True, use_marker: bool = True,
              strategy: str = "ours") -> PipelineSpec:
    """The deck pipeline a landing with these sources (and estimation strategy) uses: one
    per combination."""
    name = KIND if use_uwb and use_marker else \
        f"{KIND}_{'uwb' if use_uwb else 'nouwb'}_{'tag' if use_marker else 'notag'}"
    if strategy != "ours":
        name += f"_{strategy}"
    return PipelineSpec(KIND, cfg.rover.camera if use_marker else "", truth_body=ROVER_BODY,
                        target_size_m=cfg.rover.tag.size_m, name=name,
                        target=f"uwb={int(use_uwb)},tag={int(use_marker)},strategy={strategy}")


def parse_deck_target(target: str) -> tuple[bool, bool, str]:
    """(use_uwb, use_tag, strategy) of a spec's ``target``."""
    flags = dict(part.split("=", 1) for part in (target or "uwb=1,tag=1").split(","))
    return (flags.get("uwb", "1") == "1", flags.get("tag", "1") == "1",
            flags.get("strategy", "ours"))


def relative_settings(cfg: AppConfig) -> RelativeSettings:
    e = cfg.estimation.relative
    return RelativeSettings(
        accel_noise_m_s2=e.accel_noise_m_s2, jerk_noise_m_s3=e.jerk_noise_m_s3,
        accel_time_constant_s=e.accel_time_constant_s,
        yaw_accel_noise_rad_s2=e.yaw_accel_noise_rad_s2,
        drone_velocity_noise_m_s=e.drone_velocity_noise_m_s,
        uwb_range_noise_m=e.uwb_range_noise_m, uwb_gate_chi2=e.uwb_gate_chi2,
        rangefinder_noise_m=e.rangefinder_noise_m,
        rover_velocity_noise_m_s=e.rover_velocity_noise_m_s,
        rover_heading_noise_rad=math.radians(e.rover_heading_noise_deg),
        compass_bias_std_rad=math.radians(e.compass_bias_std_deg),
        course_noise_rad=math.radians(e.course_noise_deg),
        rough_position_std_m=e.rough_position_std_m,
        bias_time_constant_s=e.bias_time_constant_s, gate_chi2=e.gate_chi2,
        history_s=e.history_s, max_extrapolation_s=e.max_extrapolation_s)


def deck_geometry(cfg: AppConfig) -> DeckGeometry:
    r = cfg.rover
    return DeckGeometry(tuple(r.deck_size_m), r.deck_height_m,
                        tuple(tuple(a) for a in r.uwb.anchors_frd_m), tuple(r.uwb.tag_frd_m))


def relative_record(name: str, est: RelativeEstimate, result=None) -> dict:
    """The flight log's record of the relative filter after one measurement
    (``/estimation/relative``)."""
    cov = est.covariance
    return {"time_s": est.time_s, "pipeline": name,
            "source": result.source if result is not None else "",
            "measurement_time_s": result.time_s if result is not None else est.time_s,
            "accepted": bool(result.accepted) if result is not None else True,
            "late": bool(result.late) if result is not None else False,
            "parts": int(result.parts) if result is not None else 0,
            "mahalanobis2": float(result.mahalanobis2) if result is not None else 0.0,
            "relative_position_m": est.position_m, "relative_velocity_m_s": est.velocity_m_s,
            "position_std_m": est.position_std_m,
            "velocity_std_m_s": np.sqrt(np.diag(cov)[3:]),
            "position_cov_m2": cov[:3, :3].reshape(-1), "heading_rad": est.heading_rad,
            "heading_std_rad": est.heading_std_rad, "bias_m": est.bias_m}


class DeckPipeline:
    kind = KIND

    def __init__(self, cfg: AppConfig, spec: PipelineSpec | None = None) -> None:
        spec = spec or deck_spec(cfg)
        self.name = spec.key
        self.camera = spec.camera
        self.size_m = spec.target_size_m
        use_uwb, use_tag, self.strategy = parse_deck_target(spec.target)
        tag = cfg.rover.tag
        self.layout = marker_pad_layout(tag.size_m, tag.ids, tag.dictionary)
        self.detector = MarkerPadDetector(MarkerPadSettings(
            self.layout, backend=cfg.perception.pad.backend,
            min_perimeter_px=cfg.perception.pad.min_perimeter_px))
        self.deck_height_m = cfg.rover.deck_height_m
        self.filter = RelativeFilter(relative_settings(cfg), deck_geometry(cfg),
                                     use_uwb=use_uwb, use_tag=use_tag)
        #: seed 004's fused filter (a baseline): used instead of ours when chosen
        self.seed004 = Seed004Filter(
            Seed004Settings(**cfg.estimation.seed004.model_dump()), deck_geometry(cfg),
            use_uwb=use_uwb, use_marker=use_tag) if self.strategy == "seed004" else None
        self._use_uwb, self._use_tag = use_uwb, use_tag
        e = cfg.estimation.relative
        self._tag_noise = (e.tag_pixel_noise_px, e.tag_range_noise_fraction,
                           math.radians(e.tag_heading_noise_deg))
        self._attitude_std = math.radians(math.hypot(
            cfg.estimation.navigation.attitude_std_deg, cfg.estimation.camera_mount_std_deg))
        self.history = PoseHistory(span_s=max(3.0, 2.0 * e.history_s),
                                   max_extrapolation_s=0.3)
        self._last_reading = math.nan
        self._records: list[dict] = []

    # -- inputs ----------------------------------------------------------------------------

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)
        if self.seed004 is not None:  # PX4's local position and the laser altimeter
            self.seed004.add_px4(state.time_s, state.position_ned_m)
            r = state.distance_to_ground_m
            if math.isfinite(r) and r != self._last_reading:
                self.seed004.add_range(state.time_s, r)
            self._last_reading = r
            return
        self.filter.add_velocity(state.time_s, state.velocity_ned_m_s)
        r = state.distance_to_ground_m
        if math.isfinite(r) and r != self._last_reading:
            tilt_cos = float(quat_to_matrix(state.attitude_q)[2, 2])
            if tilt_cos > 0.5:
                self.filter.add_range(state.time_s, r * tilt_cos)
        self._last_reading = r
        self._collect()

    def add_sensor(self, sample: object) -> None:
        """A UWB reading or a rover report (see :attr:`drivers.base.Vehicle.sensors`)."""
        if self.seed004 is not None:
            self._seed004_sensor(sample)
            return
        if isinstance(sample, UwbRanges):
            pose = self.history.pose_at(sample.time_s)
            if pose is not None:
                self.filter.add_uwb(sample.time_s, sample.anchor_ids, sample.ranges_m,
                                    pose.attitude_q)
        elif isinstance(sample, RoverState):
            drone = self._drone_at(sample.time_s)
            if drone is not None:
                position, velocity = drone
                deck = np.asarray(sample.position_ned_m, dtype=float) \
                    + np.array([0.0, 0.0, -self.deck_height_m])
                self.filter.add_rover(
                    sample.time_s, position - deck,
                    velocity - np.asarray(sample.velocity_ned_m_s, dtype=float),
                    sample.heading_rad, velocity_std_m_s=sample.velocity_std_m_s,
                    heading_std_rad=sample.heading_std_rad,
                    rover_velocity_m_s=sample.velocity_ned_m_s)
        self._collect()

    def _seed004_sensor(self, sample: object) -> None:
        if isinstance(sample, RoverState):
            self.seed004.add_compass(sample.time_s, sample.heading_rad)
            if not self._use_uwb:  # the client's rough rover_position (seed 004, 4.4.1)
                self.seed004.add_rover_position(np.asarray(sample.position_ned_m, dtype=float)
                                                + np.array([0.0, 0.0, -self.deck_height_m]))
        elif isinstance(sample, UwbRanges) and self._use_uwb:
            pose = self.history.pose_at(sample.time_s)
            if pose is not None:
                self.seed004.add_uwb(sample.time_s, sample.anchor_ids, sample.ranges_m,
                                     quat_to_matrix(pose.attitude_q))

    def _drone_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        pose = self.history.pose_at(time_s)
        latest = self.history.latest
        if pose is None or latest is None:
            return None
        # velocity: the newest sample at or before the time (it changes slowly)
        velocity = np.asarray(latest.velocity_ned_m_s) if time_s >= latest.time_s \
            else self._velocity_at(time_s)
        return np.asarray(pose.position_ned_m), velocity

    def _velocity_at(self, time_s: float) -> np.ndarray:
        best = None
        for state in reversed(self.history._states):  # newest first; short history
            best = state
            if state.time_s <= time_s:
                break
        return np.asarray(best.velocity_ned_m_s)

    def _collect(self) -> None:
        results = self.filter.take_results()
        if not results:
            return
        est = self.filter.estimate()
        if est is None:
            return
        self._records.extend(relative_record(self.name, est, r) for r in results)

    def take_records(self) -> list[dict]:
        """The filter's records since the last call (for ``/estimation/relative``)."""
        out, self._records = self._records, []
        return out

    # -- the camera ------------------------------------------------------------------------

    def hint(self, time_s: float, camera: CameraInfo) -> None:
        return None

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None):
        return self.detector.detect(image_bgr, camera, time_s)

    def estimate(self, time_s: float, camera: CameraInfo, detection) -> dict | None:
        pose = self.history.pose_at(time_s)
        if pose is None:
            return None
        pixel, fraction, heading_std = self._tag_noise
        m = tag_measurement(detection.position_cam_m, detection.rotation_cam_pad,
                            quat_to_matrix(pose.attitude_q), camera.rotation_body_cam,
                            camera.position_body_m, camera.intrinsics.fx,
                            pixel_noise_px=pixel, range_noise_fraction=fraction,
                            attitude_std_rad=self._attitude_std, heading_std_rad=heading_std)
        # the tag is printed on the deck: its centre is the deck's top centre
        if self.seed004 is not None:
            if self._use_tag:
                self.seed004.add_tag(time_s, m.relative_m)
            return None
        self.filter.add_tag(time_s, m.relative_m, m.covariance, m.heading_rad,
                            m.heading_std_rad)
        self._collect()
        return None  # the filter's records go to /estimation/relative (take_records)

    def relative(self, time_s: float) -> RelativeEstimate | None:
        return self.filter.estimate(time_s)

    def target(self, time_s: float, vehicle_position_ned_m=None) -> TargetEstimate | None:
        """The deck's top centre at ``time_s`` in the drone's local frame (see the notes)."""
        source = self.seed004 if self.seed004 is not None else self.filter
        rel = source.estimate(time_s)
        drone_at = self._drone_at(time_s)  # the drone's own estimate at that moment
        if rel is None or drone_at is None:
            return None
        drone, velocity = drone_at
        last = max(rel.last_update_s[s] for s in ("uwb", "tag", "rover"))
        age = time_s - last
        updates = sum(source.updates.values())
        return TargetEstimate(
            time_s=time_s, position_ned_m=drone - rel.position_m,
            velocity_ned_m_s=velocity - rel.velocity_m_s,
            covariance=rel.covariance, age_s=age, stale=age > STALE_AFTER_S,
            updates=updates, confirmed=updates >= 3, kind=KIND,
            heading_rad=rel.heading_rad, heading_rate_rad_s=rel.yaw_rate_rad_s,
            heading_std_rad=rel.heading_std_rad,
            acceleration_ned_m_s2=rel.rover_acceleration_m_s2)

    def detection_record(self, seq: int, time_s: float, camera: str, det,
                         hint: object | None) -> dict:
        return detection_record(seq, time_s, camera, det)

    def hint_from_record(self, record: dict) -> None:
        return None


register(KIND, DeckPipeline)
ch.register_schema(ch.detection_topic(KIND), ch.detection_schema(
    "DeckTagDetection", quaternion_cam_pad=ch.nullable_array(4), clipped=ch.BOOL,
    ids=ch.nullable_array(items={"type": "integer"}), fit_error=ch.NUM))


def uwb_ranges_from_record(r: dict) -> UwbRanges:
    return UwbRanges(float(r["time_s"]), tuple(int(i) for i in r["anchor_ids"]),
                     tuple(ch.num(v) for v in r["ranges_m"]))


def rover_state_from_record(r: dict) -> RoverState:
    return RoverState(float(r["time_s"]), ch.vec(r["position_ned_m"]),
                      ch.vec(r["velocity_ned_m_s"]), ch.num(r.get("heading_rad")),
                      ch.num(r.get("position_std_m")), ch.num(r.get("velocity_std_m_s")),
                      ch.num(r.get("heading_std_rad")), int(r.get("system_id") or 0))


# the extra sensor streams this pipeline takes (drivers.capabilities.SENSOR_STREAMS): logged on
# /sensors/<stream>, read back for replay in this order
ch.register_sensor("uwb", ch.record_schema(
    "UwbRanges", time_s=ch.NUM, anchor_ids={"type": "array", "items": {"type": "integer"}},
    ranges_m={"type": "array", "items": ch.NUM}, received_s=ch.NUM), uwb_ranges_from_record)
ch.register_sensor("rover", ch.record_schema(
    "RoverState", time_s=ch.NUM, position_ned_m=ch.vector_schema(3),
    velocity_ned_m_s=ch.vector_schema(3), heading_rad=ch.NUM, position_std_m=ch.NUM,
    velocity_std_m_s=ch.NUM, heading_std_rad=ch.NUM, system_id={"type": "integer"},
    received_s=ch.NUM), rover_state_from_record)
