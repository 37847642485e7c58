"""TAKEOFF (PX4's ``Takeoff`` navigator mode), and the climb a mission starts with: straight
up to the target altitude along a speed profile (MPC_TKO_SPEED, MPC_ACC_UP_MAX)."""

from __future__ import annotations

import numpy as np

from drivers.sim.flight.navigator.context import Estimate, NavContext, NavSetpoint
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.trajectory import Profile1D

_TAKEOFF_DONE_M = 0.1  # TAKEOFF hands over to HOLD this close to its altitude (profile done)


class Takeoff:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        self.target = np.zeros(3)
        self.profile: Profile1D | None = None
        #: the altitude a takeoff command asked for (None: MIS_TAKEOFF_ALT)
        self.altitude_override_m: float | None = None

    def altitude_m(self) -> float:
        alt = self.altitude_override_m
        return alt if alt is not None else self.ctx.params["MIS_TAKEOFF_ALT"]

    def start(self, est: Estimate, altitude_m: float) -> None:
        ctx = self.ctx
        home_z = ctx.home[2] if ctx.home is not None else est.position_ned_m[2]
        target = est.position_ned_m.astype(float).copy()
        target[2] = min(target[2], home_z - altitude_m)
        self.target = target
        self.profile = None  # starts from the vehicle's state once it flies
        ctx.hold_yaw = est.yaw_rad

    def tick(self, dt: float, est: Estimate) -> NavSetpoint | None:
        """The climb's setpoint; None once there (the hold point is then the target: the
        caller hands over and holds)."""
        ctx = self.ctx
        p = ctx.params
        target = self.target
        if self.profile is None:
            if not ctx.flying:
                # still on the ground / ramping up: aim at the target, the ramp limits the climb
                return NavSetpoint(ControlSetpoint(target.tolist(), [0.0, 0.0, 0.0],
                                                   ctx.hold_yaw,
                                                   xy_vel_max_m_s=p["MPC_XY_CRUISE"],
                                                   z_vel_max_up_m_s=p["MPC_TKO_SPEED"]),
                                   takeoff=True)
            self.profile = Profile1D(float(est.position_ned_m[2]),
                                     float(est.velocity_ned_m_s[2]))
        prof = self.profile
        prof.step(float(target[2]), p["MPC_TKO_SPEED"], p["MPC_ACC_UP_MAX"], dt)
        if prof.done and abs(est.position_ned_m[2] - target[2]) < _TAKEOFF_DONE_M:
            ctx.hold_pos = target.copy()
            return None
        return NavSetpoint(ControlSetpoint([target[0], target[1], prof.position],
                                           [0.0, 0.0, prof.velocity], ctx.hold_yaw,
                                           acceleration_ned_m_s2=[0.0, 0.0, prof.acceleration],
                                           xy_vel_max_m_s=p["MPC_XY_CRUISE"]), takeoff=True)
