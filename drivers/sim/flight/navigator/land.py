"""LAND (PX4's ``Land``: descend where it stopped) and PRECLAND (PX4's ``PrecLand``: over the
landing target a companion reports, :mod:`drivers.sim.flight.precland`)."""

from __future__ import annotations

import numpy as np

from drivers.sim.flight.navigator.context import NAN, Estimate, NavContext, NavSetpoint
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.precland import PrecLand


class Land:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        self._xy = np.zeros(2)

    def activate(self, est: Estimate, landed: bool) -> None:
        self._xy = self.ctx.stopping_point(est, landed)[:2]
        self.ctx.hold_yaw = est.yaw_rad

    def tick(self, est: Estimate, height_agl_m: float) -> NavSetpoint:
        return self.ctx.descend(est, height_agl_m, self._xy)


class PrecisionLand:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        #: the landing target a companion reports, and the search and approach over it
        self.precland = PrecLand(ctx.params, ctx.event)

    def activate(self, est: Estimate, landed: bool) -> None:
        self.ctx.hold_yaw = est.yaw_rad
        self.precland.activate(self.ctx.now, self.ctx.stopping_point(est, landed))

    def tick(self, dt: float, est: Estimate, height_agl_m: float, landed: bool) -> NavSetpoint:
        ctx = self.ctx
        origin_down = ctx.home[2] if ctx.home is not None else 0.0
        out = self.precland.tick(ctx.now, est.position_ned_m, est.velocity_ned_m_s, landed,
                                 origin_down, height_agl_m)
        if out.land:
            return ctx.descend(est, height_agl_m, out.position_ned_m[:2])
        yaw = ctx.slew_yaw(ctx.hold_yaw, dt)
        return NavSetpoint(ControlSetpoint(out.position_ned_m.tolist(), [NAN, NAN, NAN], yaw,
                                           xy_vel_max_m_s=ctx.params["MPC_XY_CRUISE"]))
