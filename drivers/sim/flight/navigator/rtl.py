"""RETURN (PX4's ``RTL``): climb to RTL_RETURN_ALT (less inside the RTL_CONE_ANG cone above
home), fly home at MPC_XY_CRUISE, descend to RTL_DESCEND_ALT, wait RTL_LAND_DELAY (−1: stay),
land."""

from __future__ import annotations

import math

import numpy as np

from drivers.sim.flight.navigator.context import (
    NAN,
    Estimate,
    NavContext,
    NavSetpoint,
    heading_to,
)
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.trajectory import LineTracker


class ReturnToLaunch:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        self._stage = "climb"  # climb | return | descend | loiter | land
        self._alt_down = 0.0
        self._line: LineTracker | None = None
        self._wait_until = math.inf

    def return_altitude_m(self, est: Estimate) -> float:
        """Height above home to return at (PX4's RTL with RTL_CONE_ANG): RTL_RETURN_ALT, but
        within RTL_MIN_DIST of home only as high as the cone of half-angle RTL_CONE_ANG above
        it (at least twice NAV_ACC_RAD, and twice the distance inside NAV_ACC_RAD); never
        below the current height (RTL does not descend before it returns)."""
        p = self.ctx.params
        home = self.ctx.home_or(est.position_ned_m)
        height = float(home[2] - est.position_ned_m[2])
        ret = p["RTL_RETURN_ALT"]
        cone = p["RTL_CONE_ANG"]
        if cone > 0:
            distance = float(np.hypot(*(est.position_ned_m[:2] - home[:2])))
            acc_rad = p["NAV_ACC_RAD"]
            if distance <= acc_rad:
                ret = 2.0 * distance
            else:
                if distance <= p["RTL_MIN_DIST"]:
                    half_angle = math.radians(min(max(cone, 1.0), 89.0))
                    ret = min(distance / math.tan(half_angle), ret)
                ret = max(ret, 2.0 * acc_rad)
        return max(min(ret, p["RTL_RETURN_ALT"]), height)

    def activate(self, est: Estimate) -> None:
        ctx = self.ctx
        home = ctx.home_or(est.position_ned_m)
        self._alt_down = float(home[2] - self.return_altitude_m(est))
        start = ctx.stopping_point(est, landed=False)
        self._line = LineTracker(est.position_ned_m, [start[0], start[1], self._alt_down])
        self._stage = "climb"
        ctx.hold_yaw = est.yaw_rad
        ctx.speed_override = NAN  # PX4 resets the cruise speed on RTL
        ctx.event(f"RTL: start return at {ctx.origin.alt_amsl_m - self._alt_down:.0f} m "
                  f"({home[2] - self._alt_down:.0f} m above destination)")

    def tick(self, dt: float, est: Estimate, height_agl_m: float) -> NavSetpoint:
        ctx = self.ctx
        p = ctx.params
        home = ctx.home_or(est.position_ned_m)
        if self._stage == "land":
            return ctx.descend(est, height_agl_m, home[:2])
        if self._stage == "loiter":
            delay = p["RTL_LAND_DELAY"]
            if delay >= 0 and ctx.now >= self._wait_until:
                self._stage = "land"
                ctx.event("RTL: land at destination")
                return ctx.descend(est, height_agl_m, home[:2])
            return NavSetpoint(ControlSetpoint(ctx.hold_pos.tolist(), [NAN, NAN, NAN],
                                               ctx.slew_yaw(ctx.hold_yaw, dt)))
        line = self._line
        v_max = line.speed_limit(ctx.cruise_m_s(), p["MPC_Z_V_AUTO_UP"], p["MPC_Z_V_AUTO_DN"])
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m)
        if self._stage == "return" and math.isfinite(heading := heading_to(home, est)):
            ctx.hold_yaw = heading
        yaw = ctx.slew_yaw(ctx.hold_yaw, dt)
        near = float(np.linalg.norm(est.position_ned_m - line.end)) < p["NAV_ACC_RAD"]
        if line.done and near:
            self._next_stage(home)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))

    def _next_stage(self, home: np.ndarray) -> None:
        ctx = self.ctx
        p = ctx.params
        end = self._line.end
        if self._stage == "climb":
            self._stage = "return"
            self._line = LineTracker(end, [home[0], home[1], end[2]])
            ctx.event("RTL: returning home")
            return
        delay = p["RTL_LAND_DELAY"]
        if delay == 0:  # PX4: straight from the return altitude into the landing
            self._stage = "land"
            ctx.hold_yaw = ctx.yaw_sp
            ctx.event("RTL: land at destination")
            return
        loiter_down = float(home[2] - min(p["RTL_DESCEND_ALT"], home[2] - end[2]))
        if self._stage == "return" and end[2] < loiter_down - 0.1:
            self._stage = "descend"
            self._line = LineTracker(end, [home[0], home[1], loiter_down])
            return
        ctx.hold_pos = np.array(end, dtype=float)
        self._wait_until = ctx.now + max(0.0, delay)
        self._stage = "loiter"
        if delay < 0:
            ctx.event("RTL: completed, loitering")
