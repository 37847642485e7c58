"""HOLD (PX4's ``Loiter``: AUTO.LOITER): stay at the stopping point, or fly to a
DO_REPOSITION target."""

from __future__ import annotations

import math

import numpy as np

from drivers.base import FlightMode
from drivers.sim.flight.navigator.context import (
    NAN,
    Estimate,
    NavContext,
    NavSetpoint,
    heading_to,
)
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.trajectory import LineTracker


class Loiter:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        self._line: LineTracker | None = None  # a DO_REPOSITION being flown
        self._speed = NAN

    def activate(self, est: Estimate, landed: bool) -> None:
        self._line = None
        self.ctx.hold_pos = self.ctx.stopping_point(est, landed)
        self.ctx.hold_yaw = est.yaw_rad

    def reposition(self, target_ned_m, yaw_rad: float, speed_m_s: float, est: Estimate) -> None:
        """DO_REPOSITION: fly to ``target_ned_m`` in HOLD (NaN components: keep current)."""
        ctx = self.ctx
        target = np.where(np.isfinite(target_ned_m), target_ned_m, est.position_ned_m)
        self._line = LineTracker(ctx.hold_pos if ctx.mode is FlightMode.HOLD
                                 else est.position_ned_m, target)
        self._speed = speed_m_s
        ctx.hold_pos = target.astype(float)
        if math.isfinite(yaw_rad):
            ctx.hold_yaw = yaw_rad
        elif math.isfinite(heading := heading_to(target, est)):
            ctx.hold_yaw = heading

    def tick(self, dt: float, est: Estimate) -> NavSetpoint:
        ctx = self.ctx
        line = self._line
        if line is None:
            return NavSetpoint(ctx.hold_setpoint())
        p = ctx.params
        cruise = self._speed if self._speed > 0 else p["MPC_XY_CRUISE"]
        v_max = line.speed_limit(cruise, p["MPC_Z_V_AUTO_UP"], p["MPC_Z_V_AUTO_DN"])
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m)
        if line.done:
            self._line = None
        yaw = ctx.slew_yaw(ctx.hold_yaw, dt)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))
