"""Offboard setpoints as PX4 takes them: the newest one and when it came (the offboard signal
and its loss failsafe), body-frame velocities turned by the heading at reception, the yaw held
or integrated from a yaw rate, and a setpoint above a vehicle on the ground as a takeoff."""

from __future__ import annotations

import math

import numpy as np

from drivers.base import Setpoint, SetpointFrame
from drivers.geometry import rot_z, wrap_pi
from drivers.sim.flight.position_control import ControlSetpoint

NAN = float("nan")
_TAKEOFF_TRIGGER_M = 0.2  # a setpoint this far above the vehicle means "take off"
_TAKEOFF_TRIGGER_M_S = 0.3


class OffboardInput:
    def __init__(self) -> None:
        #: the newest setpoint (position, velocity, yaw, yaw rate, acceleration), or None
        self.setpoint: tuple[np.ndarray, np.ndarray, float, float, np.ndarray] | None = None
        self.received_s = -math.inf
        #: the yaw flown when a setpoint gives only a yaw rate (or none)
        self.yaw_rad = 0.0

    def push(self, sp: Setpoint, now_s: float, heading_rad: float) -> None:
        """A setpoint arrives at ``now_s``; ``heading_rad``: the vehicle's, for body-frame
        velocities (PX4 rotates them by the heading at reception)."""
        vel = np.array(sp.velocity_m_s)
        if sp.frame is SetpointFrame.BODY_FRD:
            vel = rot_z(heading_rad) @ vel
        self.setpoint = (np.array(sp.position_ned_m), vel, sp.yaw_rad, sp.yaw_rate_rad_s,
                         np.array(sp.acceleration_m_s2))
        self.received_s = now_s

    def control_setpoint(self, dt: float) -> ControlSetpoint:
        """The newest setpoint for the position controller (yaw held, with the yaw rate as
        feed-forward, as PX4; or integrated from the yaw rate alone)."""
        pos, vel, yaw, yaw_rate, acc = self.setpoint
        if math.isfinite(yaw):
            self.yaw_rad = yaw
            yaw_rate_ff = yaw_rate
        elif math.isfinite(yaw_rate):
            self.yaw_rad = wrap_pi(self.yaw_rad + yaw_rate * dt)
            yaw_rate_ff = yaw_rate
        else:
            yaw_rate_ff = NAN
        return ControlSetpoint(pos.tolist(), vel.tolist(), self.yaw_rad, yaw_rate_ff,
                               acc.tolist())

    @staticmethod
    def wants_takeoff(csp: ControlSetpoint, position_ned_m: np.ndarray) -> bool:
        """An offboard setpoint above the vehicle (or climbing) on the ground: take off."""
        z_sp = csp.position_ned_m[2]
        if math.isfinite(z_sp):
            return z_sp < position_ned_m[2] - _TAKEOFF_TRIGGER_M
        vz = csp.velocity_ned_m_s[2]
        return math.isfinite(vz) and vz < -_TAKEOFF_TRIGGER_M_S
