"""The position loop's phases, at the position-loop rate: on the ground (controllers reset,
level, motors idling), the takeoff ramp (PX4's MPC_TKO_RAMP_T: the climb-rate limit rises from
where the thrust would be zero, and nothing integrates before the vehicle flies), flying
(position P → velocity PID → the attitude setpoint the rate loop flies), touching down (level,
thrust spooled down so that the land detector sees the landing), and landed again."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.land_detector import LandDetector
from drivers.sim.flight.position_control import (
    GRAVITY_M_S2,
    LEVEL_DOWN,
    AttitudeSetpoint,
    ControlSetpoint,
    PositionController,
    body_z_to_attitude,
)
from drivers.sim.flight.rate_loop import RateLoop

_LAND_THRUST_RAMP_S = 0.5  # thrust ramps to zero this fast once the ground is felt


class PositionLoop:
    def __init__(self, cfg: FlightStackConfig, hover_thrust: float, rate_loop: RateLoop,
                 event: Callable[[str], None]) -> None:
        self.cfg = cfg
        self.position_ctrl = PositionController(cfg.position, hover_thrust)
        self.land_detector = LandDetector(cfg.land_detector, cfg.position.thrust_min,
                                          hover_thrust)
        self.rate_loop = rate_loop
        self._event = event
        self.phase = "ground"  # ground | ramp | flight
        #: a landing is being flown (the navigator's LAND, an RTL's or a mission's)
        self.landing = False
        self.att_sp = AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), 0.0, 0.0)
        self._ramp_start = 0.0
        self._land_thrust_scale = 1.0

    def reset_controllers(self) -> None:
        self.position_ctrl.reset()
        self.rate_loop.reset()

    def disarmed(self, now: float, est, yaw_rad: float, relative_velocity: np.ndarray,
                 height_agl: float) -> None:
        """A tick while disarmed: on the ground, level, the land detector told."""
        self.phase = "ground"
        self.landing = False
        self.reset_controllers()
        self.att_sp = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, yaw_rad), 0.0, 0.0)
        self.land_detector.update(now, False, relative_velocity, est.rates_frd_rad_s, 0.0,
                                  False, height_agl)

    def update(self, now: float, dt: float, est, yaw_rad: float, csp: ControlSetpoint,
               wants_takeoff: bool, landing: bool, relative_velocity: np.ndarray,
               height_agl: float) -> None:
        """A tick while armed, flying ``csp``: the attitude setpoint (:attr:`att_sp`)."""
        self.landing = landing
        if self.phase == "ground" and wants_takeoff:
            self.phase = "ramp" if self.cfg.commander.takeoff_ramp_s > 0 else "flight"
            self._ramp_start = now
            self.reset_controllers()
        if self.phase == "ramp":
            progress = (now - self._ramp_start) / self.cfg.commander.takeoff_ramp_s
            if progress >= 1.0:
                self.phase = "flight"
            else:
                # PX4's takeoff ramp: the climb-rate limit starts where thrust would be zero
                start = -GRAVITY_M_S2 / self.cfg.position.z_vel_p
                up = csp.z_vel_max_up_m_s
                if not math.isfinite(up):
                    up = self.position_ctrl.z_vel_max_up_m_s
                csp.z_vel_max_up_m_s = start + (up - start) * progress
                csp.z_vel_max_down_m_s = max(self.position_ctrl.z_vel_max_down_m_s,
                                             -csp.z_vel_max_up_m_s)

        if self.phase == "ground":
            self.reset_controllers()
            self.att_sp = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, yaw_rad), 0.0, 0.0)
        else:
            if self.phase == "ramp":
                # as PX4: no integration before the vehicle is flying (on the ground the ramp's
                # velocity error would wind the integrators up)
                self.position_ctrl.reset_integral()
            att = self.position_ctrl.update(dt, est.position_ned_m.tolist(),
                                            est.velocity_ned_m_s.tolist(), csp)
            if landing and self.land_detector.ground_contact:
                # touching down: level out and spool the thrust down so that landing is detected
                self._land_thrust_scale = max(0.0, self._land_thrust_scale
                                              - dt / _LAND_THRUST_RAMP_S)
                self.position_ctrl.reset_xy_integral()
                att = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, csp.yaw_rad),
                                       att.thrust * self._land_thrust_scale, 0.0)
            else:
                self._land_thrust_scale = 1.0
            self.att_sp = att

        descent_commanded = self.position_ctrl.velocity_setpoint[2] > 0.1 and \
            self.phase != "ground"
        self.land_detector.update(now, True, relative_velocity, est.rates_frd_rad_s,
                                  self.att_sp.thrust, descent_commanded, height_agl)
        if self.phase == "flight" and self.land_detector.landed:
            self.phase = "ground"
            self._event("landed")
