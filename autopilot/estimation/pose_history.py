"""The vehicle's recent poses, to place a measurement where the vehicle was at capture time.

A frame captured at time t reaches the detector tens of milliseconds later; in between the
vehicle has moved and turned. Measurements are transformed with the pose at t, interpolated from
telemetry (position linearly, attitude by slerp), not with the newest pose.

Position and attitude are placed each at its own capture time (``time_s``,
``attitude_time_s``): over MAVLink they travel in separate messages at their own rates (an
ArduPilot vehicle's ATTITUDE and LOCAL_POSITION_NED are not sent together), so the attitude
in a sample can be a message older than its position; taken at the position's time, a
down camera 5 m up turning at 1 rad/s would misplace what it sees by 0.1 m per 20 ms.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from drivers.base import VehicleState
from drivers.geometry import quat_multiply


@dataclass(frozen=True, slots=True, eq=False)
class Pose:
    time_s: float
    position_ned_m: np.ndarray
    attitude_q: np.ndarray  # body FRD → NED


def slerp(q0: np.ndarray, q1: np.ndarray, f: float) -> np.ndarray:
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + f * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = math.acos(dot)
    return (math.sin((1 - f) * theta) * q0 + math.sin(f * theta) * q1) / math.sin(theta)


class PoseHistory:
    """Telemetry samples of the last ``span_s`` seconds, queried by time."""

    def __init__(self, span_s: float = 2.0, max_extrapolation_s: float = 0.1) -> None:
        self._span = span_s
        self._max_extrapolation = max_extrapolation_s
        self._times: deque[float] = deque()
        self._states: deque[VehicleState] = deque()
        #: attitude samples at their own capture times: (time, q, body rates)
        self._att_times: deque[float] = deque()
        self._attitudes: deque[tuple[np.ndarray, np.ndarray]] = deque()

    def add(self, state: VehicleState) -> None:
        if not self._att_times or state.attitude_time_s > self._att_times[-1]:
            self._att_times.append(state.attitude_time_s)
            self._attitudes.append((np.asarray(state.attitude_q, float),
                                    np.asarray(state.angular_velocity_frd_rad_s, float)))
            while self._att_times and self._att_times[0] < state.attitude_time_s - self._span:
                self._att_times.popleft()
                self._attitudes.popleft()
        if self._times and state.time_s <= self._times[-1]:
            return  # out of order or repeated
        self._times.append(state.time_s)
        self._states.append(state)
        while self._times and self._times[0] < state.time_s - self._span:
            self._times.popleft()
            self._states.popleft()

    @property
    def latest(self) -> VehicleState | None:
        return self._states[-1] if self._states else None

    def pose_at(self, time_s: float) -> Pose | None:
        """The pose at ``time_s``: interpolated inside the history, extrapolated a little past
        its end (position with the velocity, attitude with the body rates), None when the
        history cannot tell."""
        if not self._times:
            return None
        position = self._position_at(time_s)
        attitude = self._attitude_at(time_s)
        if position is None or attitude is None:
            return None
        return Pose(time_s, position, attitude)

    def _position_at(self, time_s: float) -> np.ndarray | None:
        times = self._times
        if time_s >= times[-1]:
            last = self._states[-1]
            dt = time_s - last.time_s
            if dt > self._max_extrapolation:
                return None
            return last.position_ned_m + last.velocity_ned_m_s * dt
        i = bisect.bisect_right(times, time_s)
        if i == 0:
            return None  # older than the history
        a, b = self._states[i - 1], self._states[i]
        f = (time_s - a.time_s) / (b.time_s - a.time_s)
        return a.position_ned_m + f * (b.position_ned_m - a.position_ned_m)

    def _attitude_at(self, time_s: float) -> np.ndarray | None:
        times = self._att_times
        if time_s >= times[-1]:
            q, rates = self._attitudes[-1]
            dt = time_s - times[-1]
            if dt > self._max_extrapolation:
                return None
            return rotate_by_body_rates(q, rates, dt)
        i = bisect.bisect_right(times, time_s)
        if i == 0:
            return None
        f = (time_s - times[i - 1]) / (times[i] - times[i - 1])
        return slerp(self._attitudes[i - 1][0], self._attitudes[i][0], f)


def rotate_by_body_rates(q: np.ndarray, rates_frd_rad_s: np.ndarray, dt_s: float) -> np.ndarray:
    """``q`` (body FRD → NED) turned on for ``dt_s`` at the body rates (constant)."""
    angle = float(np.linalg.norm(rates_frd_rad_s)) * dt_s
    if not math.isfinite(angle) or angle == 0.0:
        return np.array(q, float)
    axis = np.asarray(rates_frd_rad_s, float) / float(np.linalg.norm(rates_frd_rad_s))
    half = angle / 2.0
    turn = np.array([math.cos(half), *(axis * math.sin(half))])
    out = quat_multiply(np.asarray(q, float), turn)  # a body-frame turn: on the right
    return out / np.linalg.norm(out)
