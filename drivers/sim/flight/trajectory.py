"""Setpoint trajectories of the auto modes: what PX4's auto flight tasks feed the position
controller, in their simplest forms.

* :class:`Profile1D`: a velocity- and acceleration-limited approach to a target along one axis
  (the takeoff climb).
* :class:`LineTracker`: a reference point that travels a straight segment at a cruise speed,
  accelerating and braking within limits, so that the position controller tracks a moving
  point with its velocity and acceleration fed forward (PX4's line-following auto mode rather
  than a step to the next waypoint). It slows down when the vehicle falls behind (wind, a
  saturated climb), so the reference never runs away from the vehicle.
"""

from __future__ import annotations

import math

import numpy as np

#: The reference may lead the vehicle by at most this much before it waits (m).
MAX_LEAD_M = 2.5


class Profile1D:
    """1-D trapezoidal setpoint profile (velocity- and acceleration-limited)."""

    def __init__(self, position: float, velocity: float) -> None:
        self.position = position
        self.velocity = velocity
        self.acceleration = 0.0
        self.done = False

    def step(self, target: float, v_max: float, a_max: float, dt: float) -> None:
        err = target - self.position
        v_des = math.copysign(min(v_max, math.sqrt(2.0 * a_max * abs(err))), err)
        dv = min(max(v_des - self.velocity, -a_max * dt), a_max * dt)
        self.acceleration = dv / dt
        self.velocity += dv
        self.position += self.velocity * dt
        if abs(target - self.position) < 0.005 and abs(self.velocity) < 0.1:
            self.position, self.velocity, self.acceleration = target, 0.0, 0.0
            self.done = True


class LineTracker:
    """A reference moving from ``start`` to ``end`` (local NED), entering at ``speed_m_s``
    along the segment.

    :meth:`step` advances it by ``dt`` with the speed limit of the moment (so a speed change
    mid-segment applies at once) and returns the reference position, velocity and
    acceleration. The profile brakes to ``end_speed_m_s`` at the end (0: stop there)."""

    def __init__(self, start, end, speed_m_s: float = 0.0) -> None:
        self.start = np.asarray(start, dtype=float).copy()
        self.end = np.asarray(end, dtype=float).copy()
        delta = self.end - self.start
        self.length_m = float(np.linalg.norm(delta))
        self.direction = delta / self.length_m if self.length_m > 1e-6 else np.zeros(3)
        self.s = 0.0
        self.speed = max(0.0, speed_m_s)
        self.accel = 0.0

    @property
    def done(self) -> bool:
        return self.s >= self.length_m - 1e-6

    @property
    def position(self) -> np.ndarray:
        return self.start + self.direction * self.s

    @property
    def velocity(self) -> np.ndarray:
        return self.direction * self.speed

    def speed_limit(self, xy_m_s: float, up_m_s: float, down_m_s: float) -> float:
        """The fastest speed along this segment that keeps within the horizontal and vertical
        limits."""
        d = self.direction
        limit = xy_m_s / max(math.hypot(d[0], d[1]), 1e-9)
        if d[2] < -1e-9:
            limit = min(limit, up_m_s / -d[2])
        elif d[2] > 1e-9:
            limit = min(limit, down_m_s / d[2])
        return limit

    def step(self, dt: float, v_max: float, a_max: float, vehicle_position,
             end_speed_m_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.length_m <= 1e-6:
            self.speed = self.accel = 0.0
            return self.end.copy(), np.zeros(3), np.zeros(3)
        remaining = max(0.0, self.length_m - self.s)
        end_speed = min(max(0.0, end_speed_m_s), v_max)
        v_des = min(v_max, math.sqrt(end_speed * end_speed + 2.0 * a_max * remaining))
        lead = float(np.linalg.norm(self.position - np.asarray(vehicle_position, dtype=float)))
        if lead > MAX_LEAD_M:  # the vehicle is behind: wait for it instead of running away
            v_des = min(v_des, max(0.0, self.speed - a_max * dt))
        dv = min(max(v_des - self.speed, -a_max * dt), a_max * dt)
        self.accel = dv / dt if dt > 0 else 0.0
        self.speed = max(0.0, self.speed + dv)
        self.s = min(self.length_m, self.s + self.speed * dt)
        if self.done and end_speed <= 0.0:
            self.speed = self.accel = 0.0
        return self.position, self.velocity, self.direction * self.accel
