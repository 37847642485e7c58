"""A heading (an angle on the circle) and its rate, tracked by a two-state Kalman filter: the
direction a marker's face points. Measurements are wrapped onto the prediction before they are
used; an innovation beyond the χ² gate (1 degree of freedom) is rejected."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.geometry import wrap_pi


@dataclass(frozen=True, slots=True)
class HeadingSettings:
    accel_noise_rad_s2: float  # how hard the heading may turn (white angular acceleration)
    initial_rate_std_rad_s: float
    gate_chi2: float  # 1 dof: 10.8 ≈ 99.9 %
    stale_after_s: float


@dataclass(frozen=True, slots=True)
class HeadingEstimate:
    heading_rad: float
    rate_rad_s: float
    std_rad: float
    age_s: float


class HeadingFilter:
    def __init__(self, settings: HeadingSettings) -> None:
        self.settings = settings
        self._x: np.ndarray | None = None  # heading, rate
        self._p = np.zeros((2, 2))
        self._time = -math.inf
        self._last_update = -math.inf

    def reset(self) -> None:
        self._x = None

    def innovation2(self, time_s: float, heading_rad: float, std_rad: float) -> float:
        """Mahalanobis² of a measurement against the prediction (0 with no track)."""
        if self._stale(time_s):
            return 0.0
        x, p = self._predicted(time_s)
        return wrap_pi(heading_rad - x[0]) ** 2 / (p[0, 0] + std_rad ** 2)

    def update(self, time_s: float, heading_rad: float, std_rad: float) -> bool:
        """Fuse a measured heading; False if it was gated out."""
        if self._stale(time_s):
            self._x = np.array([wrap_pi(heading_rad), 0.0])
            self._p = np.diag([std_rad ** 2, self.settings.initial_rate_std_rad_s ** 2])
            self._time = self._last_update = time_s
            return True
        if time_s < self._time:
            return False
        x, p = self._predicted(time_s)
        y = wrap_pi(heading_rad - x[0])
        s = p[0, 0] + std_rad ** 2
        if y * y / s > self.settings.gate_chi2:
            return False
        k = p[:, 0] / s
        x = x + k * y
        p = p - np.outer(k, p[0, :])
        x[0] = wrap_pi(x[0])
        self._x, self._p = x, 0.5 * (p + p.T)
        self._time = self._last_update = time_s
        return True

    def estimate(self, time_s: float, max_extrapolation_s: float) -> HeadingEstimate | None:
        if self._x is None:
            return None
        horizon = max(self._time, min(time_s, self._last_update + max_extrapolation_s))
        x, p = self._predicted(horizon)
        return HeadingEstimate(wrap_pi(float(x[0])), float(x[1]), math.sqrt(p[0, 0]),
                               time_s - self._last_update)

    def _stale(self, time_s: float) -> bool:
        return self._x is None or time_s - self._last_update > self.settings.stale_after_s

    def _predicted(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        dt = max(0.0, time_s - self._time)
        f = np.array([[1.0, dt], [0.0, 1.0]])
        var = self.settings.accel_noise_rad_s2 ** 2
        q = var * np.array([[0.25 * dt ** 4, 0.5 * dt ** 3], [0.5 * dt ** 3, dt * dt]])
        return f @ self._x, f @ self._p @ f.T + q
