"""Attitude control, after PX4's ``mc_att_control`` (AttitudeControl.cpp).

Quaternion P control with tilt prioritised over yaw: the reduced attitude (thrust direction
only) is reached first, yaw is blended in with ``yaw_weight``. Output: body rate setpoint (FRD).
Quaternions are ``(w, x, y, z)`` sequences, body FRD → world NED.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from drivers.geometry import q_body_z, q_world_z_in_body, qbetween, qcanon, qconj, qmul
from drivers.sim.config import AttitudeControlConfig


class AttitudeController:
    def __init__(self, cfg: AttitudeControlConfig) -> None:
        self._yaw_w = min(max(cfg.yaw_weight, 0.0), 1.0)
        gains = [float(g) for g in cfg.p]
        if self._yaw_w > 1e-4:
            gains[2] /= self._yaw_w  # compensates the yaw blending below (as PX4)
        self._gains = gains
        self._rate_max = [math.radians(r) for r in cfg.rate_max_deg_s]

    def update(self, q: Sequence[float], q_sp: Sequence[float],
               yaw_rate_ff_rad_s: float) -> list[float]:
        qd_red = qbetween(q_body_z(q), q_body_z(q_sp))
        if abs(qd_red[1]) > 1 - 1e-5 or abs(qd_red[2]) > 1 - 1e-5:
            qd_red = tuple(q_sp)  # thrust directions opposite: use the full attitude
        else:
            qd_red = qmul(qd_red, q)

        q_mix = qcanon(qmul(qconj(qd_red), q_sp))
        w = min(max(q_mix[0], -1.0), 1.0)
        z = min(max(q_mix[3], -1.0), 1.0)
        qd = qmul(qd_red, (math.cos(self._yaw_w * math.acos(w)), 0.0, 0.0,
                           math.sin(self._yaw_w * math.asin(z))))

        qe = qcanon(qmul(qconj(q), qd))
        g = self._gains
        rate = [2.0 * qe[1] * g[0], 2.0 * qe[2] * g[1], 2.0 * qe[3] * g[2]]
        if yaw_rate_ff_rad_s:
            down = q_world_z_in_body(q)
            rate = [rate[i] + down[i] * yaw_rate_ff_rad_s for i in range(3)]
        lim = self._rate_max
        return [min(max(rate[i], -lim[i]), lim[i]) for i in range(3)]
