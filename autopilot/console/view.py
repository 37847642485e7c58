"""The vehicle's state as the console and the goal API show it: plain functions of a
telemetry sample, shared by the autopilot's runtime and the simulator's own console."""

from __future__ import annotations

import math

import numpy as np

from autopilot.values import ValueBoard
from drivers.base import VehicleState

_NO_STATE = {"position_ned_m": None, "velocity_ned_m_s": None, "yaw_deg": None, "armed": None,
             "mode": None, "battery_fraction": None, "in_air": None}


def _battery(s: VehicleState) -> float | None:
    fraction = s.battery.remaining_fraction
    return fraction if math.isfinite(fraction) else None


def vehicle_status(s: VehicleState | None) -> dict:
    """``/api/status``'s vehicle fields (None each, before the first sample)."""
    if s is None:
        return dict(_NO_STATE)
    return {"position_ned_m": [float(v) for v in s.position_ned_m],
            "velocity_ned_m_s": [float(v) for v in s.velocity_ned_m_s],
            "yaw_deg": math.degrees(s.yaw_rad), "armed": s.armed, "mode": s.mode.value,
            "battery_fraction": _battery(s), "in_air": s.in_air}


def pose_record(s: VehicleState | None):
    """(position, attitude, the state's fields the overlay shows), or None."""
    if s is None:
        return None
    return (np.asarray(s.position_ned_m, dtype=float), np.asarray(s.attitude_q),
            {"mode": s.mode.value, "battery_remaining": _battery(s)})


def publish_vehicle(board: ValueBoard, s: VehicleState) -> None:
    """The vehicle's own ``name::value`` pairs: mode, armed, height, speed, battery."""
    board.publish("mode", s.mode.value)
    board.publish("armed", s.armed)
    board.publish("alt_m", round(s.altitude_m, 2), "m")
    board.publish("speed_m_s", round(float(np.linalg.norm(s.velocity_ned_m_s)), 2), "m/s")
    battery = _battery(s)
    board.publish("battery", f"{100 * battery:.0f} %" if battery is not None else "?")


def vehicle_map(s: VehicleState | None, home_ned_m, path_id: int = 0) -> dict:
    """The mini-map's vehicle part: where it is and faces, and home."""
    out = {"position_ne_m": None, "yaw_deg": None, "target_ne_m": None,
           "target_sigma_m": None, "path_id": path_id,
           "home_ne_m": [float(home_ned_m[0]), float(home_ned_m[1])]
           if home_ned_m is not None else None}
    if s is not None:
        out["position_ne_m"] = [round(float(s.position_ned_m[0]), 3),
                                round(float(s.position_ned_m[1]), 3)]
        out["yaw_deg"] = round(math.degrees(s.yaw_rad), 1)
    return out
