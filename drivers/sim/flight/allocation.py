"""Control allocation (the mixer): torques and collective thrust → rotor thrusts.

The effectiveness matrix comes from the airframe (rotor positions and yaw coefficients read from
the MJCF model). Saturation is handled with PX4's priorities: roll and pitch first (scaled down
only if they alone exceed the thrust range), then collective thrust (shifted to make room), and
yaw last with whatever headroom remains. Which axes were cut is reported so that the rate
controller's integrator stops winding up against the limits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class Allocation:
    thrust_n: list[float]  # per rotor
    saturated_positive: tuple[bool, bool, bool]  # per axis roll, pitch, yaw
    saturated_negative: tuple[bool, bool, bool]


class ControlAllocator:
    def __init__(self, rotor_positions_frd_m: np.ndarray, yaw_coefficients_m: np.ndarray,
                 thrust_max_n: np.ndarray) -> None:
        pos = np.asarray(rotor_positions_frd_m, dtype=float)
        # rows: roll torque, pitch torque, yaw torque (FRD), total thrust (N, upwards)
        effectiveness = np.vstack((-pos[:, 1], pos[:, 0], np.asarray(yaw_coefficients_m),
                                   np.ones(len(pos))))
        mix = np.linalg.pinv(effectiveness)  # n × 4
        self._roll, self._pitch, self._yaw, self._thrust = (mix[:, k].tolist() for k in range(4))
        self._hi = float(np.min(thrust_max_n))
        self._n = len(pos)

    def allocate(self, torque_frd_nm: Sequence[float], thrust_n: float,
                 thrust_min_n: float) -> Allocation:
        lo, hi = thrust_min_n, self._hi
        tx, ty, tz = torque_frd_nm
        n = range(self._n)
        u_rp = [self._roll[i] * tx + self._pitch[i] * ty for i in n]
        sat_roll = sat_pitch = sat_yaw = False

        rp_range = max(u_rp) - min(u_rp)
        if rp_range > hi - lo:
            k = (hi - lo) / rp_range
            u_rp = [v * k for v in u_rp]
            sat_roll, sat_pitch = abs(tx) > 1e-9, abs(ty) > 1e-9
        u = [self._thrust[i] * thrust_n + u_rp[i] for i in n]
        over = max(u) - hi
        under = lo - min(u)
        if over > 0.0:
            u = [v - over for v in u]
        elif under > 0.0:
            u = [v + under for v in u]

        # yaw with the remaining headroom
        scale = 1.0
        for i in n:
            y = self._yaw[i] * tz
            if y > 1e-12:
                scale = min(scale, (hi - u[i]) / y)
            elif y < -1e-12:
                scale = min(scale, (lo - u[i]) / y)
        scale = max(scale, 0.0)
        sat_yaw = scale < 1.0
        u = [min(max(u[i] + scale * self._yaw[i] * tz, lo), hi) for i in n]
        sat = (sat_roll, sat_pitch, sat_yaw)
        return Allocation(
            u,
            tuple(s and t > 0.0 for s, t in zip(sat, (tx, ty, tz), strict=True)),
            tuple(s and t < 0.0 for s, t in zip(sat, (tx, ty, tz), strict=True)),
        )
