"""ArduCopter's precision landing (AC_PrecLand with AC_PrecLand_StateMachine, as ArduCopter 4.5
flies them in LAND with PLND_ENABLED and PLND_TYPE 1: the landing target a companion reports in
LANDING_TARGET), for the simulated ArduCopter (``sim.firmware: ardupilot``).

The target (``AC_PrecLand``):

* a measurement starts the estimator ("PrecLand: Target Found"); with PLND_EST_TYPE 1 (the
  Kalman filter) the target counts as acquired after 2 s of measurements no more than 0.5 s
  apart ("PrecLand: Init Complete"; a longer gap: "PrecLand: Init Failed"), with PLND_EST_TYPE
  0 at once;
* acquired, it is lost after 2 s without a measurement ("PrecLand: Target Lost");
* its state: *found*; *recently lost* (seen before, within 180 s and 30 m); *never seen*; *out
  of range* when the rangefinder height is outside PLND_ALT_MIN … PLND_ALT_MAX (or invalid,
  when either is set: no retry and no failsafe there, the vehicle just descends).

What LAND does with it (``Mode::precland_run`` and the state machine):

* target found: descend over it (not while it is more than PLND_XY_DIST_MAX away: the descent
  pauses while the vehicle closes in);
* recently lost: PLND_STRICT 0 lands vertically; 1 and 2 descend for PLND_TIMEOUT after the
  last measurement, then retry — "PrecLand: Retrying": fly to 1.5 m above where the vehicle
  was when it last saw the target (PLND_RET_BEHAVE 0) or above the target's last position (1),
  within 0.75 m, then descend back to that height ("PrecLand: Retry Completed"); at most
  PLND_RET_MAX retries per LAND (0: none);
* never seen, retries exhausted or a retry complete without the target: the failsafe
  ("PrecLand: Failsafe Measures"): PLND_STRICT 2 hovers for good, 1 hovers 7 s then lands
  vertically, 0 lands vertically.

Not modelled: the Kalman filter's own estimate (the target is where its newest measurement put
it), a moving target's velocity (PLND_OPTIONS bit 0), the slow final descent within 2 m.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable

import numpy as np

from drivers.sim.flight.params import Parameters
from drivers.sim.flight.precland import PrecLandSetpoint

EKF_INIT_TIME_S = 2.0
EKF_INIT_SENSOR_MIN_UPDATE_S = 0.5
LANDING_TARGET_TIMEOUT_S = 2.0
LANDING_TARGET_LOST_TIMEOUT_S = 180.0
LANDING_TARGET_LOST_DIST_THRESH_M = 30.0
MAX_POS_ERROR_M = 0.75
FAILSAFE_INIT_TIMEOUT_S = 7.0
RETRY_OFFSET_ALT_M = 1.5


class TargetState(enum.Enum):
    FOUND = "found"
    RECENTLY_LOST = "recently lost"
    NEVER_SEEN = "never seen"
    OUT_OF_RANGE = "out of range"


class Status(enum.Enum):
    DESCEND = "descend"
    RETRYING = "retrying"
    FAILSAFE = "failsafe"


class _Lost(enum.Enum):  # TargetLostAction
    INIT = 0
    DESCEND = 1
    RETRY_LANDING = 2
    LAND_VERTICALLY = 3


class _Retry(enum.Enum):  # RetryLanding
    INIT = 0
    IN_PROGRESS = 1
    DESCEND = 2
    COMPLETE = 3


class AcPrecLand:
    """The precision landing the navigator's PRECLAND runs (the PX4 :class:`PrecLand`'s
    interface: ``landing_target``, ``activate``, ``tick``)."""

    def __init__(self, params: Parameters, event: Callable[[str], None]) -> None:
        self.params = params
        self._event = event
        self.target_state = TargetState.NEVER_SEEN
        self.status = Status.DESCEND
        self.retry_count = 0
        self._meas_s = -math.inf         # the newest measurement's time
        self._target = np.zeros(3)       # and where it put the target (local NED)
        self._streak_start_s = math.nan  # the estimator's start (NaN: not running)
        self._acquired = False
        self._last_valid_s = -math.inf   # the last time the target was acquired
        self._last_target = np.zeros(3)
        self._last_vehicle = np.zeros(3)
        self._lost = _Lost.INIT
        self._retry = _Retry.INIT
        self._failsafe_s = math.nan
        self._hold: np.ndarray | None = None  # where a paused descent holds
        self._vertical_xy: np.ndarray | None = None  # where a landing without target goes down

    # -- input ----------------------------------------------------------------------------

    def landing_target(self, time_s: float, position_ned_m) -> None:
        """A LANDING_TARGET: the target at ``position_ned_m`` (local NED) at ``time_s``."""
        now = float(time_s)
        self._update_acquired(now)
        if math.isnan(self._streak_start_s):
            self._streak_start_s = now
            self._event("PrecLand: Target Found")
            if int(self.params["PLND_EST_TYPE"]) == 0:
                self._acquired = True
        elif not self._acquired and now - self._meas_s > EKF_INIT_SENSOR_MIN_UPDATE_S:
            self._event("PrecLand: Init Failed")
            self._streak_start_s = now
            self._event("PrecLand: Target Found")
        self._meas_s = now
        self._target = np.asarray(position_ned_m, dtype=float).copy()
        if not self._acquired and now - self._streak_start_s >= EKF_INIT_TIME_S:
            self._acquired = True
            self._event("PrecLand: Init Complete")

    # -- mode -------------------------------------------------------------------------------

    def activate(self, now: float, position_ned_m: np.ndarray) -> None:
        """LAND begins (AC_PrecLand_StateMachine::init: the retries counted per mode)."""
        self.retry_count = 0
        self._reset_machine()
        self._hold = None
        self._vertical_xy = np.asarray(position_ned_m, dtype=float)[:2].copy()

    def tick(self, now: float, position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray,
             landed: bool, origin_down_m: float, height_agl_m: float = math.nan
             ) -> PrecLandSetpoint:
        pos = np.asarray(position_ned_m, dtype=float)
        self._update_acquired(now)
        if self._acquired:
            self._last_valid_s = now
            self._last_target = self._target.copy()
            self._last_vehicle = pos.copy()
        self._check_target_status(now, pos, height_agl_m)
        if landed:
            return PrecLandSetpoint(pos.copy(), land=True)
        self.status, goal = self._update(now, pos)
        if self.status is Status.RETRYING:
            self._hold = None
            return PrecLandSetpoint(goal, land=False)
        if self.status is Status.FAILSAFE and self._failsafe_hold(now):
            return self._paused(pos)
        return self._descend(pos)

    # -- AC_PrecLand ------------------------------------------------------------------------

    def _update_acquired(self, now: float) -> None:
        if now - self._meas_s > LANDING_TARGET_TIMEOUT_S and not math.isnan(
                self._streak_start_s):
            if self._acquired:
                self._event("PrecLand: Target Lost")
            self._acquired = False
            self._streak_start_s = math.nan

    def _in_range(self, height_agl_m: float) -> bool:
        lo, hi = float(self.params["PLND_ALT_MIN"]), float(self.params["PLND_ALT_MAX"])
        if lo == 0.0 and hi == 0.0:
            return True
        if not math.isfinite(height_agl_m):
            return False
        return not ((hi != 0.0 and height_agl_m > hi) or (lo != 0.0 and height_agl_m < lo))

    def _check_target_status(self, now: float, pos: np.ndarray, height_agl_m: float) -> None:
        if self._acquired:
            self.target_state = TargetState.FOUND
            return
        self.target_state = (TargetState.RECENTLY_LOST if self.target_state in (
            TargetState.FOUND, TargetState.RECENTLY_LOST) else TargetState.NEVER_SEEN)
        if not self._in_range(height_agl_m):
            self.target_state = TargetState.OUT_OF_RANGE
            return
        if self.target_state is TargetState.RECENTLY_LOST:
            far = max(float(np.hypot(*(pos[:2] - self._last_target[:2]))),
                      float(np.hypot(*(pos[:2] - self._last_vehicle[:2]))))
            if now - self._last_valid_s > LANDING_TARGET_LOST_TIMEOUT_S or \
                    far > LANDING_TARGET_LOST_DIST_THRESH_M:
                self.target_state = TargetState.NEVER_SEEN

    # -- AC_PrecLand_StateMachine -----------------------------------------------------------

    def _reset_machine(self) -> None:
        self._lost = _Lost.INIT
        self._retry = _Retry.INIT
        self._failsafe_s = math.nan

    def _update(self, now: float, pos: np.ndarray) -> tuple[Status, np.ndarray | None]:
        state = self.target_state
        if state is TargetState.RECENTLY_LOST:
            return self._target_lost(now, pos)
        if state is TargetState.NEVER_SEEN:
            return Status.FAILSAFE, None
        self._reset_machine()  # found, or out of range: descend
        return Status.DESCEND, None

    def _target_lost(self, now: float, pos: np.ndarray) -> tuple[Status, np.ndarray | None]:
        if self._lost is _Lost.INIT:
            strict = int(self.params["PLND_STRICT"])
            self._lost = _Lost.LAND_VERTICALLY if strict == 0 else _Lost.DESCEND
            return Status.DESCEND, None
        if self._lost is _Lost.DESCEND:
            if now - self._last_valid_s >= float(self.params["PLND_TIMEOUT"]):
                self._lost = _Lost.RETRY_LANDING
                self._retry = _Retry.INIT
            return Status.DESCEND, None
        if self._lost is _Lost.RETRY_LANDING:
            return self._retry_landing(pos)
        return Status.DESCEND, None  # LAND_VERTICALLY

    def _retry_landing(self, pos: np.ndarray) -> tuple[Status, np.ndarray | None]:
        most = int(self.params["PLND_RET_MAX"])
        if most == 0 or self.retry_count > most:
            return Status.FAILSAFE, None
        goal = (self._last_target if int(self.params["PLND_RET_BEHAVE"]) == 1
                else self._last_vehicle).copy()
        goal[2] -= RETRY_OFFSET_ALT_M
        if self._retry is _Retry.INIT:
            self.retry_count += 1
            self._retry = _Retry.IN_PROGRESS
            if self.retry_count <= most:
                self._event("PrecLand: Retrying")
            return Status.RETRYING, goal
        if self._retry is _Retry.IN_PROGRESS:
            if float(np.linalg.norm(goal - pos)) < MAX_POS_ERROR_M:
                self._retry = _Retry.DESCEND
            return Status.RETRYING, goal
        if self._retry is _Retry.DESCEND:
            back = np.array([pos[0], pos[1], goal[2] + RETRY_OFFSET_ALT_M])
            if abs(pos[2] - back[2]) < MAX_POS_ERROR_M:
                self._retry = _Retry.COMPLETE
                self._event("PrecLand: Retry Completed")
            return Status.RETRYING, back
        return Status.FAILSAFE, None  # COMPLETE

    def _failsafe_hold(self, now: float) -> bool:
        """get_failsafe_actions: True to hold (the descent paused), False to land."""
        if math.isnan(self._failsafe_s):
            self._failsafe_s = now
            self._event("PrecLand: Failsafe Measures")
        strict = int(self.params["PLND_STRICT"])
        if strict == 2:
            return True
        return strict == 1 and now - self._failsafe_s < FAILSAFE_INIT_TIMEOUT_S

    # -- the land controller ----------------------------------------------------------------

    def _paused(self, pos: np.ndarray) -> PrecLandSetpoint:
        if self._hold is None:
            self._hold = pos.copy()
        if self._acquired:  # (over the target, at the height it paused)
            self._hold[:2] = self._target[:2]
        return PrecLandSetpoint(self._hold.copy(), land=False)

    def _descend(self, pos: np.ndarray) -> PrecLandSetpoint:
        if self._acquired:
            self._vertical_xy = None
            dist_max = float(self.params["PLND_XY_DIST_MAX"])
            if dist_max > 0 and float(np.hypot(*(self._target[:2] - pos[:2]))) > dist_max:
                return self._paused(pos)  # closing in before descending
            self._hold = None
            return PrecLandSetpoint(np.array([*self._target[:2], pos[2]]), land=True)
        self._hold = None
        if self._vertical_xy is None:  # the land controller brakes and holds where it is
            self._vertical_xy = pos[:2].copy()
        return PrecLandSetpoint(np.array([*self._vertical_xy, pos[2]]), land=True)
