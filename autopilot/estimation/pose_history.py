"""The vehicle's recent poses, to place a measurement where the vehicle was at capture time.

A frame captured at time t reaches the detector tens of milliseconds later; in between the
vehicle has moved and turned. Measurements are transformed with the pose at t, interpolated from
telemetry (position linearly, attitude by slerp), not with the newest pose.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from drivers.base import VehicleState


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

    def add(self, state: VehicleState) -> None:
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
        """The pose at ``time_s``: interpolated inside the history, extrapolated with the
        velocity a little past its end, None when the history cannot tell."""
        if not self._times:
            return None
        times = self._times
        if time_s >= times[-1]:
            last = self._states[-1]
            dt = time_s - last.time_s
            if dt > self._max_extrapolation:
                return None
            return Pose(time_s, last.position_ned_m + last.velocity_ned_m_s * dt,
                        np.array(last.attitude_q))
        i = bisect.bisect_right(times, time_s)
        if i == 0:
            return None  # older than the history
        a, b = self._states[i - 1], self._states[i]
        f = (time_s - a.time_s) / (b.time_s - a.time_s)
        return Pose(time_s, a.position_ned_m + f * (b.position_ned_m - a.position_ned_m),
                    slerp(np.asarray(a.attitude_q), np.asarray(b.attitude_q), f))
