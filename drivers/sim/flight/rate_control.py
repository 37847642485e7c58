"""Body-rate control, after PX4's ``mc_rate_control`` (RateControl.cpp).

PID on body rates (FRD) with the derivative on the measured angular acceleration, an integrator
that fades for large errors and freezes in the direction the mixer is saturated. The output is
an angular acceleration command (rad/s²); the flight stack multiplies by the inertia.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from drivers.sim.config import RateControlConfig

_I_FADE_RAD_S = math.radians(400.0)


class RateController:
    def __init__(self, cfg: RateControlConfig) -> None:
        self._p = [float(g) for g in cfg.p]
        self._i = [float(g) for g in cfg.i]
        self._d = [float(g) for g in cfg.d]
        self._i_limit = cfg.integrator_limit_rad_s2
        self.integral = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def update(self, dt: float, rate: Sequence[float], rate_sp: Sequence[float],
               angular_accel: Sequence[float], saturated_positive: Sequence[bool],
               saturated_negative: Sequence[bool]) -> list[float]:
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            err = rate_sp[i] - rate[i]
            out[i] = self._p[i] * err + self.integral[i] - self._d[i] * angular_accel[i]
            # integrate unless the error pushes further into a saturated direction
            if (saturated_positive[i] and err > 0.0) or (saturated_negative[i] and err < 0.0):
                continue
            fade = max(0.0, 1.0 - (err / _I_FADE_RAD_S) ** 2)
            candidate = self.integral[i] + fade * self._i[i] * err * dt
            if abs(candidate) < self._i_limit:
                self.integral[i] = candidate
        return out
