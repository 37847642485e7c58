"""Land detection, after PX4's ``MulticopterLandDetector``.

Three stages, each implying the one before: *ground contact* (not moving vertically or
horizontally, close to the ground, and either thrust is low or a descent is commanded but not
happening), *maybe landed* (ground contact, low thrust, not rotating) and *landed* (maybe landed
for ``trigger_time_s``). Leaving "maybe landed" leaves "landed" at once.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.sim.config import LandDetectorConfig

#: The range sensor sits at the body centre, 0.1 m above the skids' contact points.
_NEAR_GROUND_M = 0.4


class LandDetector:
    def __init__(self, cfg: LandDetectorConfig, thrust_min: float, hover_thrust: float) -> None:
        self.cfg = cfg
        self._low_thrust = thrust_min + (hover_thrust - thrust_min) * cfg.low_thrust_ratio
        self._rot_max = math.radians(cfg.rot_max_deg_s)
        self.ground_contact = True
        self.maybe_landed = True
        self.landed = True
        self._maybe_since: float | None = None

    def update(self, now_s: float, armed: bool, velocity_ned: np.ndarray,
               body_rates: np.ndarray, thrust: float, descent_commanded: bool,
               height_agl_m: float) -> None:
        if not armed:
            self.ground_contact = self.maybe_landed = self.landed = True
            self._maybe_since = None
            return
        cfg = self.cfg
        near_ground = not math.isfinite(height_agl_m) or height_agl_m < _NEAR_GROUND_M
        still = (abs(velocity_ned[2]) < cfg.z_vel_max_m_s
                 and math.hypot(velocity_ned[0], velocity_ned[1]) < cfg.xy_vel_max_m_s)
        low_thrust = thrust <= self._low_thrust
        self.ground_contact = still and near_ground and (low_thrust or descent_commanded)
        rotating = float(np.max(np.abs(body_rates))) > self._rot_max
        self.maybe_landed = self.ground_contact and low_thrust and not rotating
        if self.maybe_landed:
            if self._maybe_since is None:
                self._maybe_since = now_s
            if now_s - self._maybe_since >= cfg.trigger_time_s:
                self.landed = True
        else:
            self._maybe_since = None
            self.landed = False
