"""GUIDED's targets as ArduCopter flies them (``mode_guided.cpp``), in the place of PX4's
offboard input under the simulated ArduCopter (:mod:`drivers.sim.flight.arducopter`):

* there is always a target: entering GUIDED holds where the vehicle is (ArduCopter starts in
  its velocity submode at zero, so the vehicle brakes and holds), and no target ever "goes
  missing" — no offboard-loss failsafe;
* velocity and acceleration targets time out after GUID_TIMEOUT (3 s): their velocity becomes
  zero and the vehicle stops and holds there (a yaw rate stops too); **position targets never
  time out**;
* a target never takes off: on the ground the motors stay at idle until NAV_TAKEOFF;
* a target without yaw or yaw rate gets ArduCopter's default auto-yaw (WP_YAW_BEHAVIOR 2 and
  1: a position target is faced while more than 2 m away, a velocity target's direction of
  travel is faced above 1 m/s; 0: the heading is held).
"""

from __future__ import annotations

import math

import numpy as np

from drivers.base import Setpoint
from drivers.sim.flight.offboard import OffboardInput
from drivers.sim.flight.position_control import ControlSetpoint

NAN = float("nan")
_NANS = np.full(3, NAN)
#: auto-yaw: a position target is faced while further than this (AC_WPNav's look-at-WP)
_FACE_TARGET_M = 2.0
#: auto-yaw: a velocity's direction is faced above this speed (YAW_LOOK_AHEAD_MIN_SPEED)
_LOOK_AHEAD_M_S = 1.0


class GuidedInput(OffboardInput):
    """GUIDED's target. The firmware sets :attr:`now_s`, :attr:`position_ned_m` and
    :attr:`timeout_s` before each tick."""

    def __init__(self) -> None:
        super().__init__()
        self.now_s = 0.0
        self.position_ned_m = np.zeros(3)
        self.timeout_s = 3.0
        #: WP_YAW_BEHAVIOR (0: hold the heading when a target gives none)
        self.auto_yaw = 2
        self._timed_out = False

    @property
    def received_s(self) -> float:
        """Always fresh: GUIDED has no target-loss failsafe (PX4's offboard loss never acts)."""
        return self.now_s

    @received_s.setter
    def received_s(self, value: float) -> None:
        self._received_s = value

    @property
    def age_s(self) -> float:
        return self.now_s - self._received_s

    @property
    def timed_out(self) -> bool:
        return self._timed_out

    def hold(self, position_ned_m, yaw_rad: float, now_s: float) -> None:
        """Hold ``position_ned_m`` facing ``yaw_rad`` (GUIDED's entry, a takeoff's end)."""
        self.setpoint = (np.array(position_ned_m, dtype=float), np.zeros(3), float(yaw_rad),
                         NAN, _NANS.copy())
        self.yaw_rad = float(yaw_rad)
        self._received_s = now_s
        self._timed_out = False

    def face(self, yaw_rad: float) -> None:
        """CONDITION_YAW: the target's heading becomes ``yaw_rad`` (its yaw rate stops)."""
        if self.setpoint is not None:
            pos, vel, _, _, acc = self.setpoint
            self.setpoint = (pos, vel, float(yaw_rad), NAN, acc)

    def push(self, sp: Setpoint, now_s: float, heading_rad: float) -> None:
        super().push(sp, now_s, heading_rad)
        self._timed_out = False
        pos, vel, yaw, rate, acc = self.setpoint
        if math.isnan(yaw) and math.isnan(rate):
            self.setpoint = (pos, vel, self._auto_yaw(pos, vel, heading_rad), rate, acc)

    def _auto_yaw(self, pos: np.ndarray, vel: np.ndarray, heading_rad: float) -> float:
        if self.auto_yaw == 0:
            return heading_rad
        if np.isfinite(pos[:2]).all():
            d = pos[:2] - self.position_ned_m[:2]
            if float(np.hypot(*d)) > _FACE_TARGET_M:
                return math.atan2(float(d[1]), float(d[0]))
            return heading_rad
        if np.isfinite(vel[:2]).all() and float(np.hypot(*vel[:2])) > _LOOK_AHEAD_M_S:
            return math.atan2(float(vel[1]), float(vel[0]))
        return heading_rad

    def control_setpoint(self, dt: float) -> ControlSetpoint:
        if self.setpoint is None:
            self.hold(self.position_ned_m, self.yaw_rad, self.now_s)
        pos, vel, yaw, rate, acc = self.setpoint
        if not self._timed_out and self.age_s > self.timeout_s and \
                (np.isfinite(vel).any() or np.isfinite(acc).any() or math.isfinite(rate)):
            # ArduCopter zeroes the velocity and acceleration targets (and a yaw rate): the
            # vehicle stops; a position target's part stays (it never times out)
            self._timed_out = True
            hold = np.where(np.isfinite(pos), pos, self.position_ned_m)
            self.setpoint = (hold, np.zeros(3), yaw if math.isfinite(yaw) else self.yaw_rad,
                             NAN, _NANS.copy())
        return super().control_setpoint(dt)

    @staticmethod
    def wants_takeoff(csp: ControlSetpoint, position_ned_m: np.ndarray) -> bool:
        return False  # only NAV_TAKEOFF takes off in GUIDED
