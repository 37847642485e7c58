"""The flight log's channels: topic names, JSON Schemas, and message → record converters.

Records are JSON-shaped dicts (the serialisation boundary; stages exchange typed messages);
they may hold numpy arrays and NaN, which the log writes as numbers and null. Readers treat null
and NaN alike. Times are seconds on the run's clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from drivers.base import (
    Battery,
    CameraInfo,
    CameraIntrinsics,
    FlightMode,
    Health,
    LandedState,
    VehicleState,
)

CAMERA_INFO = "/camera/info"
VEHICLE_STATE = "/vehicle/state"
VEHICLE_STATUS = "/vehicle/status_text"
TARGET_ESTIMATES = "/estimation/target"
CONTROL_TARGET = "/control/target"
SETPOINTS = "/control/setpoint"
MISSION_EVENTS = "/mission/events"
MISSION_PLAN = "/mission/plan"
GROUND_TRUTH = "/sim/ground_truth"
CAMERA_TRUTH = "/sim/camera_info"  # the cameras as they really are (scoring only)
TIME_SYNC = "/vehicle/time_sync"
PLANNED_PATH = "/planning/path"  # a trajectory step's plan, when it starts
PHOTOS = "/photos"  # photos taken by the steps (orbit, survey)
MISSION_STATUS = "/mission/status"  # the status code (autopilot.status), on each change
MISSION_GOALS = "/mission/goals"  # goals run (the goal API), as the plan's step records
RELATIVE_ESTIMATES = "/estimation/relative"  # the relative-state filter (land_on_rover)
#: what the setpoint guards (autopilot.watch) changed, one record per setpoint changed
GUARDED_SETPOINTS = "/control/guard"


def detection_topic(pipeline: str) -> str:
    """The channel of a perception pipeline's per-frame records."""
    return f"/perception/{pipeline}"


def watch_topic(watcher: str, part: str) -> str:
    """A watcher's channel (:mod:`autopilot.watch`): what it saw, what it keeps."""
    return f"/watch/{watcher}/{part}"


def sensor_topic(stream: str) -> str:
    """The channel of one of the vehicle's extra sensor streams (``vehicle.sensors``)."""
    return f"/sensors/{stream}"


#: how a sensor stream's records are read back (replay feeds them to the pipelines that take
#: them): stream → record → sample, registered with the stream's schema by the code that
#: consumes it (:func:`register_sensor`)
SENSOR_RECORDS: dict[str, Callable[[dict], Any]] = {}


def register_sensor(stream: str, schema: dict, from_record: Callable[[dict], Any]) -> None:
    """A sensor stream's channel schema and reader."""
    register_schema(sensor_topic(stream), schema)
    SENSOR_RECORDS[stream] = from_record


def detection_topics(records) -> list[str]:
    """The perception pipelines' channels in a log's records."""
    return sorted(t for t in records if t.startswith("/perception/"))


def camera_image_topic(camera: str) -> str:
    """The channel of a camera's logged frames (``foxglove.CompressedImage``, JPEG)."""
    return f"/camera/{camera}/image/compressed"


def image_topic_camera(topic: str) -> str | None:
    """The camera whose frames a channel holds (None: not a camera image channel)."""
    if topic.startswith("/camera/") and topic.endswith("/image/compressed"):
        return topic[len("/camera/"):-len("/image/compressed")]
    return None


_NUM = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_BOOL = {"type": "boolean"}
_STR = {"type": "string"}


def vector_schema(n: int) -> dict:
    """A JSON Schema: an array of ``n`` numbers (null for NaN)."""
    return {"type": "array", "items": _NUM, "minItems": n, "maxItems": n}


def record_schema(title: str, **props: dict) -> dict:
    """A JSON Schema: a channel's record, an object of ``props``."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title,
            "type": "object", "properties": props}


_vec, _obj = vector_schema, record_schema  # (short, for the table below)


SCHEMAS: dict[str, dict] = {
    CAMERA_INFO: _obj("CameraInfo", name=_STR, width_px=_INT, height_px=_INT, fx=_NUM, fy=_NUM,
                      cx=_NUM, cy=_NUM, distortion={"type": "array", "items": _NUM},
                      rotation_body_cam=_vec(9), position_body_m=_vec(3), rate_hz=_NUM),
    CAMERA_TRUTH: _obj("CameraTruth", name=_STR, width_px=_INT, height_px=_INT, fx=_NUM,
                       fy=_NUM, cx=_NUM, cy=_NUM, distortion={"type": "array", "items": _NUM},
                       rotation_body_cam=_vec(9), position_body_m=_vec(3), rate_hz=_NUM),
    VEHICLE_STATE: _obj("VehicleState", time_s=_NUM, position_ned_m=_vec(3),
                        velocity_ned_m_s=_vec(3), attitude_q=_vec(4), yaw_rad=_NUM,
                        angular_velocity_frd_rad_s=_vec(3), armed=_BOOL, mode=_STR,
                        landed_state=_STR, distance_to_ground_m=_NUM, battery_voltage_v=_NUM,
                        battery_remaining=_NUM, failsafe=_BOOL, received_s=_NUM),
    VEHICLE_STATUS: _obj("StatusText", time_s=_NUM, text=_STR),
    TARGET_ESTIMATES: _obj("TargetEstimate", time_s=_NUM, pipeline=_STR, measurement_time_s=_NUM,
                           accepted=_BOOL, reinitialised=_BOOL, mahalanobis2=_NUM,
                           measured_position_ned_m=_vec(3), position_ned_m=_vec(3),
                           velocity_ned_m_s=_vec(3), position_std_m=_vec(3),
                           velocity_std_m_s=_vec(3), position_cov_m2=_vec(9), updates=_INT),
    SETPOINTS: _obj("Setpoint", time_s=_NUM, source_frame_time_s=_NUM, latency_ms=_NUM,
                    frame=_STR, position_ned_m=_vec(3), velocity_m_s=_vec(3),
                    acceleration_m_s2=_vec(3), yaw_rad=_NUM, yaw_rate_rad_s=_NUM,
                    expires_s=_NUM, step=_STR, phase=_STR),
    MISSION_EVENTS: _obj("MissionEvent", time_s=_NUM, kind=_STR, step_index=_INT, step=_STR,
                         text=_STR),
    MISSION_PLAN: _obj("MissionPlan", mission=_STR, source=_STR, steps={"type": "array"},
                       driver=_STR, scenario={"type": ["object", "null"]},
                       config={"type": "object"}),
    RELATIVE_ESTIMATES: _obj("RelativeEstimate", time_s=_NUM, pipeline=_STR, source=_STR,
                             measurement_time_s=_NUM, accepted=_BOOL, late=_BOOL, parts=_INT,
                             mahalanobis2=_NUM, relative_position_m=_vec(3),
                             relative_velocity_m_s=_vec(3), position_std_m=_vec(3),
                             velocity_std_m_s=_vec(3), position_cov_m2=_vec(9),
                             heading_rad=_NUM, heading_std_rad=_NUM, bias_m=_vec(3)),
    CONTROL_TARGET: _obj("ControlTarget", time_s=_NUM, pipeline=_STR, step=_STR,
                         step_index=_INT, present=_BOOL, position_ned_m=_vec(3),
                         velocity_ned_m_s=_vec(3), position_std_m=_vec(3), age_s=_NUM,
                         stale=_BOOL, confirmed=_BOOL),
    TIME_SYNC: _obj("TimeSync", time_s=_NUM, vehicle_to_local_s=_NUM, round_trip_s=_NUM),
    GUARDED_SETPOINTS: _obj("GuardedSetpoint", time_s=_NUM, guard=_STR, action=_STR,
                            subject=_STR, step=_STR, phase=_STR),
    PLANNED_PATH: _obj("PlannedPath", time_s=_NUM, step_index=_INT, step=_STR,
                       points_ned_m={"type": "array"}, photo_points_ned_m={"type": "array"},
                       look_at_ned_m={"type": ["array", "null"]}, lines={"type": "array"},
                       polygon={"type": ["array", "null"]}, angle_deg=_NUM, speed_m_s=_NUM,
                       duration_s=_NUM, length_m=_NUM, spacing_m=_NUM, altitude_m=_NUM,
                       radius_m=_NUM, reference={"type": "object"}),
    PHOTOS: _obj("Photo", time_s=_NUM, index=_INT, step_index=_INT, step=_STR, camera=_STR,
                 file={"type": ["string", "null"]}, requested_s=_NUM, lat_deg=_NUM,
                 lon_deg=_NUM, alt_amsl_m=_NUM, position_ned_m=_vec(3), attitude_q=_vec(4),
                 yaw_deg=_NUM, planned_ned_m=_vec(3), look_at_ned_m={"type": ["array", "null"]},
                 height_above_home_m=_NUM),
    MISSION_GOALS: _obj("MissionGoal", time_s=_NUM, goal_id=_STR, name=_STR, index=_INT,
                        params={"type": "object"}, pipelines={"type": "array"}),
    MISSION_STATUS: _obj("MissionStatus", time_s=_NUM, code=_INT, status=_STR, step=_STR,
                         step_index=_INT, goal_id={"type": ["string", "null"]}),
    GROUND_TRUTH: _obj("GroundTruth", time_s=_NUM, vehicle_position_ned_m=_vec(3),
                       vehicle_velocity_ned_m_s=_vec(3), vehicle_attitude_q=_vec(4),
                       wind_ned_m_s=_vec(3), bodies={"type": "object"},
                       armed={"type": ["boolean", "null"]}, mode={"type": ["string", "null"]},
                       landed_state={"type": ["string", "null"]}),
}


#: Nullable JSON Schema types for detection records (a frame without a detection has nulls).
NUM, BOOL = {"type": ["number", "null"]}, {"type": ["boolean", "null"]}
INT, STR = {"type": ["integer", "null"]}, {"type": ["string", "null"]}


def nullable_array(n: int | None = None, items: dict = NUM) -> dict:
    schema: dict = {"type": ["array", "null"], "items": items}
    if n is not None:
        schema.update(minItems=n, maxItems=n)
    return schema


def detection_schema(title: str, **properties: dict) -> dict:
    """A pipeline's detection record schema: the fields every pipeline writes (the frame, the
    target's centre, radius and range in it, the hint, the timing) and ``properties``."""
    return {"title": title, "type": "object", "properties": {
        "time_s": NUM, "seq": INT, "camera": STR, "detected": BOOL, "u_px": NUM, "v_px": NUM,
        "radius_px": NUM, "range_m": NUM, "position_cam_m": nullable_array(3), "score": NUM,
        "hint_u_px": NUM, "hint_v_px": NUM, "hint_radius_px": NUM, "processing_ms": NUM,
        "received_s": NUM, "detected_s": NUM, **properties}}


def register_schema(topic: str, schema: dict) -> None:
    """A channel's JSON Schema (pipelines register theirs as they are defined)."""
    SCHEMAS[topic] = schema


def clean(value: Any) -> Any:
    """numpy → lists/floats, NaN/inf → None, recursively."""
    if isinstance(value, np.ndarray):
        return [clean(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items()}
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def camera_info_record(info: CameraInfo) -> dict:
    i = info.intrinsics
    return {"name": info.name, "width_px": i.width_px, "height_px": i.height_px,
            "fx": i.fx, "fy": i.fy, "cx": i.cx, "cy": i.cy, "distortion": list(i.distortion),
            "rotation_body_cam": info.rotation_body_cam.reshape(-1),
            "position_body_m": info.position_body_m, "rate_hz": info.rate_hz}


def vehicle_state_record(s: VehicleState) -> dict:
    return {"time_s": s.time_s, "position_ned_m": s.position_ned_m,
            "velocity_ned_m_s": s.velocity_ned_m_s, "attitude_q": s.attitude_q,
            "yaw_rad": s.yaw_rad, "angular_velocity_frd_rad_s": s.angular_velocity_frd_rad_s,
            "armed": s.armed, "mode": s.mode.value, "landed_state": s.landed_state.value,
            "distance_to_ground_m": s.distance_to_ground_m,
            "battery_voltage_v": s.battery.voltage_v,
            "battery_remaining": s.battery.remaining_fraction, "failsafe": s.failsafe}


def ground_truth_record(gt) -> dict:
    return {
        "time_s": gt.time_s,
        "vehicle_position_ned_m": gt.vehicle.position_ned_m,
        "vehicle_velocity_ned_m_s": gt.vehicle.velocity_ned_m_s,
        "vehicle_attitude_q": gt.vehicle.attitude_q,
        "wind_ned_m_s": gt.wind_ned_m_s,
        "bodies": {name: {"position_ned_m": b.position_ned_m,
                          "velocity_ned_m_s": b.velocity_ned_m_s,
                          "attitude_q": b.attitude_q}
                   for name, b in gt.bodies.items() if name != "ground"},
        "armed": getattr(gt, "armed", None), "mode": getattr(gt, "mode", None),
        "landed_state": getattr(gt, "landed_state", None),
    }


def num(value: Any) -> float:
    """A record's number (null → NaN)."""
    return math.nan if value is None else float(value)


def vec(values: Any) -> np.ndarray:
    """A record's vector (nulls → NaN)."""
    return np.array([num(v) for v in values], dtype=float)


def time_key(time_s: float) -> int:
    """A sample time as integer nanoseconds: the key that matches one frame's records across
    channels (the log's own timestamps are nanoseconds)."""
    return round(time_s * 1e9)


def camera_info_from_record(rec: dict) -> CameraInfo:
    """The :class:`CameraInfo` a ``/camera/info`` record describes."""
    intrinsics = CameraIntrinsics(
        width_px=int(rec["width_px"]), height_px=int(rec["height_px"]), fx=num(rec["fx"]),
        fy=num(rec["fy"]), cx=num(rec["cx"]), cy=num(rec["cy"]),
        distortion=tuple(num(d) for d in rec.get("distortion") or (0.0,) * 5))
    return CameraInfo(rec["name"], intrinsics, vec(rec["rotation_body_cam"]).reshape(3, 3),
                      vec(rec["position_body_m"]), num(rec["rate_hz"]))


def vehicle_state_from_record(rec: dict) -> VehicleState:
    """The :class:`VehicleState` a ``/vehicle/state`` record holds (what the log keeps of it:
    health flags and battery current are not logged and come back as defaults)."""
    return VehicleState(
        time_s=num(rec["time_s"]), position_ned_m=vec(rec["position_ned_m"]),
        velocity_ned_m_s=vec(rec["velocity_ned_m_s"]), attitude_q=vec(rec["attitude_q"]),
        angular_velocity_frd_rad_s=vec(rec["angular_velocity_frd_rad_s"]),
        armed=bool(rec["armed"]), mode=FlightMode(rec["mode"]),
        landed_state=LandedState(rec["landed_state"]),
        distance_to_ground_m=num(rec["distance_to_ground_m"]),
        battery=Battery(num(rec["battery_voltage_v"]), math.nan, num(rec["battery_remaining"])),
        health=Health(), failsafe=bool(rec.get("failsafe", False)))
