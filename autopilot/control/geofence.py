"""The autopilot's own geofence: every setpoint is checked before it goes to the vehicle (the
vehicle's geofence — PX4's GF_* — is the second line, not the only one).

A fence is a maximum horizontal distance from home, a maximum height above home and/or a
polygon (north, east in the local frame). A position setpoint breaches it when its target is
outside; a velocity setpoint when it would carry the vehicle outside within ``lookahead_s`` and
further out than it is. Plain synchronous code: the runtime asks, and on a breach sends nothing
and hands the mission to its fallback (hold, land).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Point, Polygon

from drivers.base import Setpoint, SetpointFrame, VehicleState
from drivers.geometry import quat_to_matrix


@dataclass(frozen=True, slots=True)
class FenceSettings:
    max_distance_m: float | None = None  # horizontal, from home
    max_altitude_m: float | None = None  # above home
    polygon_ne_m: tuple[tuple[float, float], ...] | None = None
    lookahead_s: float = 1.0

    @property
    def active(self) -> bool:
        return bool(self.max_distance_m or self.max_altitude_m or self.polygon_ne_m)


class Geofence:
    def __init__(self, settings: FenceSettings) -> None:
        self.settings = settings
        self._polygon = Polygon(settings.polygon_ne_m) if settings.polygon_ne_m else None

    def outside(self, point_ned: np.ndarray, home_ned: np.ndarray) -> str | None:
        """Why ``point_ned`` is outside the fence (None: inside)."""
        s = self.settings
        rel = np.asarray(point_ned, dtype=float) - home_ned
        distance = math.hypot(rel[0], rel[1])
        if s.max_distance_m and distance > s.max_distance_m:
            return f"{distance:.1f} m from home (max_distance_m {s.max_distance_m:g})"
        if s.max_altitude_m and -rel[2] > s.max_altitude_m:
            return f"{-rel[2]:.1f} m above home (max_altitude_m {s.max_altitude_m:g})"
        if self._polygon is not None and not self._polygon.covers(
                Point(float(point_ned[0]), float(point_ned[1]))):
            return f"outside the polygon at ({point_ned[0]:.1f}, {point_ned[1]:.1f}) m"
        return None

    def _excess(self, point_ned: np.ndarray, home_ned: np.ndarray) -> float:
        """How far beyond the fence (≤ 0: inside), to tell outward from inward motion."""
        s = self.settings
        rel = np.asarray(point_ned, dtype=float) - home_ned
        out = -math.inf
        if s.max_distance_m:
            out = max(out, math.hypot(rel[0], rel[1]) - s.max_distance_m)
        if s.max_altitude_m:
            out = max(out, -rel[2] - s.max_altitude_m)
        if self._polygon is not None:
            p = Point(float(point_ned[0]), float(point_ned[1]))
            gap = self._polygon.exterior.distance(p)
            out = max(out, gap if not self._polygon.covers(p) else -gap)
        return out

    def check(self, setpoint: Setpoint, state: VehicleState, home_ned: np.ndarray | None
              ) -> str | None:
        """Why ``setpoint`` may not be sent (None: it may)."""
        if not self.settings.active:
            return None
        home = np.zeros(3) if home_ned is None else np.asarray(home_ned, dtype=float)
        position = np.asarray(setpoint.position_ned_m, dtype=float)
        here = np.asarray(state.position_ned_m, dtype=float)
        target = np.where(np.isfinite(position), position, here)
        if np.any(np.isfinite(position)):
            why = self.outside(target, home)
            if why is not None:
                return f"setpoint target {why}"
        velocity = np.asarray(setpoint.velocity_m_s, dtype=float)
        if np.any(np.isfinite(velocity)):
            v = np.nan_to_num(velocity)
            if setpoint.frame is SetpointFrame.BODY_FRD:
                v = quat_to_matrix(state.attitude_q) @ v
            ahead = target + v * self.settings.lookahead_s
            why = self.outside(ahead, home)
            if why is not None and self._excess(ahead, home) > self._excess(here, home):
                return f"setpoint heading out: in {self.settings.lookahead_s:g} s {why}"
        return None

    def check_state(self, state: VehicleState, home_ned: np.ndarray | None) -> str | None:
        """Why where the vehicle is, is outside (None: inside)."""
        if not self.settings.active:
            return None
        home = np.zeros(3) if home_ned is None else np.asarray(home_ned, dtype=float)
        return self.outside(np.asarray(state.position_ned_m, dtype=float), home)
