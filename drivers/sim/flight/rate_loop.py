"""The rate loop, at the rate-loop rate: attitude control, rate control and control allocation
(PX4's mc_att_control, mc_rate_control and control_allocator), from the attitude setpoint the
position loop leaves to the rotor thrusts."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.allocation import ControlAllocator
from drivers.sim.flight.attitude_control import AttitudeController
from drivers.sim.flight.position_control import AttitudeSetpoint
from drivers.sim.flight.rate_control import RateController

if TYPE_CHECKING:
    from drivers.sim.flight.flight_stack import Airframe


class RateLoop:
    def __init__(self, cfg: FlightStackConfig, airframe: Airframe,
                 motor_idle_fraction: float) -> None:
        self.cfg = cfg
        self.attitude_ctrl = AttitudeController(cfg.attitude)
        self.rate_ctrl = RateController(cfg.rates)
        self.allocator = ControlAllocator(airframe.rotor_positions_frd_m,
                                          airframe.yaw_coefficients_m, airframe.thrust_max_n)
        #: each motor's thrust at idle (armed, on the ground)
        self.idle_n = motor_idle_fraction * float(airframe.thrust_max_n.min())
        self._motors = len(airframe.thrust_max_n)
        self._thrust_total_max = float(airframe.thrust_max_n.sum())
        self._inertia_l = np.asarray(airframe.inertia_frd_kg_m2, dtype=float).tolist()
        self._sat_pos: tuple[bool, ...] = (False, False, False)
        self._sat_neg: tuple[bool, ...] = (False, False, False)
        self._prev_gyro: list[float] | None = None
        self._ang_acc = [0.0, 0.0, 0.0]
        self._d_alpha = 0.0

    def reset(self) -> None:
        self.rate_ctrl.reset()

    def update(self, dt: float, q: list[float], gyro: list[float], att_sp: AttitudeSetpoint,
               *, armed: bool, on_ground: bool) -> list[float]:
        """One tick: the rotor thrusts (N). ``q`` and ``gyro`` are the estimated attitude
        (w, x, y, z) and body rates (FRD) as plain floats; disarmed, the motors stop; armed on
        the ground, they idle."""
        prev = self._prev_gyro
        if prev is not None:
            if not self._d_alpha:
                rc = 1.0 / (2.0 * math.pi * self.cfg.rates.d_cutoff_hz)
                self._d_alpha = dt / (dt + rc)
            a = self._d_alpha
            acc = self._ang_acc
            for i in range(3):
                acc[i] += a * ((gyro[i] - prev[i]) / dt - acc[i])
        self._prev_gyro = gyro

        n = self._motors
        if not armed:
            self.rate_ctrl.reset()
            return [0.0] * n
        if on_ground:
            self.rate_ctrl.reset()
            return [self.idle_n] * n
        rate_sp = self.attitude_ctrl.update(q, att_sp.q_ned_frd, att_sp.yaw_rate_ff_rad_s)
        acc_cmd = self.rate_ctrl.update(dt, gyro, rate_sp, self._ang_acc,
                                        self._sat_pos, self._sat_neg)
        j = self._inertia_l
        torque = (j[0] * acc_cmd[0], j[1] * acc_cmd[1], j[2] * acc_cmd[2])
        alloc = self.allocator.allocate(torque, att_sp.thrust * self._thrust_total_max,
                                        self.idle_n)
        self._sat_pos, self._sat_neg = alloc.saturated_positive, alloc.saturated_negative
        return alloc.thrust_n
