"""PX4's precision landing (AUTO.PRECLAND; PX4 ``navigator/precland.cpp``), as the simulator
flies it on the landing target a companion computer reports (MAVLink LANDING_TARGET in
MAV_FRAME_LOCAL_NED, PX4's ``landing_target_pose``).

States, as PX4's:

``start``
    Hold where the mode began. A fresh target: ``horizontal approach``. None, once there for
    2 s: ``search`` (or, with ``PLD_SRCH_TOUT`` 0, ``fallback``).
``horizontal approach``
    Fly to over the target at the height the approach began, the setpoint slewed at
    MPC_XY_CRUISE and MPC_ACC_HOR. Within ``PLD_HACC_RAD`` (each axis) of a fresh target for
    2 s: ``descend above target``. Over the last known position and the target not seen
    (older than ``PLD_BTOUT``): lost, back to ``start`` (at most ``PLD_MAX_SRCH`` times, then
    ``fallback``); 10 s in this state: ``fallback``.
``descend above target``
    Land (MPC_LAND_SPEED below MPC_LAND_ALT2) over the newest target. Lost: below
    ``PLD_FAPPR_ALT`` above the target (a target older than 0.5 s there) ``final approach``,
    else back to ``start``.
``final approach``
    Land over the last target seen, whatever happens.
``search``
    Climb to ``PLD_SRCH_ALT`` above the local origin; a target seen: stop climbing (1 m above
    where it was seen), settle 1 s, ``horizontal approach``; ``PLD_SRCH_TOUT``: ``fallback``.
``fallback``
    A normal landing where the vehicle is.

The texts PX4 prints at the transitions go out as the vehicle's status texts.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.sim.flight.params import Parameters

#: PX4's fixed times: the longest horizontal approach, and the dwell before descending /
#: searching
STATE_TIMEOUT_S = 10.0
DWELL_S = 2.0
#: below PLD_FAPPR_ALT, a target older than this is lost (PX4's 0.5 s)
FINAL_TARGET_AGE_S = 0.5


class PrecLandState(enum.Enum):
    START = "start"
    HORIZONTAL_APPROACH = "horizontal approach"
    DESCEND_ABOVE_TARGET = "descend above target"
    FINAL_APPROACH = "final approach"
    SEARCH = "search"
    FALLBACK = "fallback"
    DONE = "done"


@dataclass(frozen=True, slots=True)
class PrecLandSetpoint:
    """What precision landing asks for: hold ``position_ned_m`` or land over its x, y."""

    position_ned_m: np.ndarray
    land: bool


class PrecLand:
    def __init__(self, params: Parameters, event: Callable[[str], None]) -> None:
        self.params = params
        self._event = event
        self.state = PrecLandState.DONE
        self._target_s = -math.inf
        self._target = np.zeros(3)
        self._updated = False
        self._sp = np.zeros(3)
        self._search_cnt = 0
        self._state_start = 0.0
        self._point_reached: float | None = None
        self._acquired: float | None = None
        self._approach_z = 0.0
        self._slew: tuple[np.ndarray, np.ndarray] | None = None
        self._last_slew_s = 0.0

    # -- input ----------------------------------------------------------------------------

    def landing_target(self, time_s: float, position_ned_m) -> None:
        """A LANDING_TARGET arrived: the target at ``position_ned_m`` (local NED) at
        ``time_s``."""
        self._target_s = float(time_s)
        self._target = np.asarray(position_ned_m, dtype=float).copy()
        self._updated = True

    # -- mode -------------------------------------------------------------------------------

    def activate(self, now: float, position_ned_m: np.ndarray) -> None:
        self._search_cnt = 0
        self._sp = np.asarray(position_ned_m, dtype=float).copy()
        self._slew = None
        self.state = PrecLandState.START
        self._switch_start(now)

    def tick(self, now: float, position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray,
             landed: bool, origin_down_m: float, height_agl_m: float = math.nan
             ) -> PrecLandSetpoint:
        self._pos = np.asarray(position_ned_m, dtype=float)
        self._vel = np.asarray(velocity_ned_m_s, dtype=float)
        self._origin_down = origin_down_m
        self._valid = now - self._target_s <= self.params["PLD_BTOUT"]
        if landed:
            self.state = PrecLandState.DONE
        handler = {
            PrecLandState.START: self._run_start,
            PrecLandState.HORIZONTAL_APPROACH: self._run_horizontal_approach,
            PrecLandState.DESCEND_ABOVE_TARGET: self._run_descend,
            PrecLandState.SEARCH: self._run_search,
        }.get(self.state)
        out = handler(now) if handler is not None else None
        self._updated = False
        if out is None:  # final approach, fallback, done: land where the setpoint is
            out = PrecLandSetpoint(self._sp.copy(), land=True)
        return out

    # -- states ---------------------------------------------------------------------------

    def _hold(self) -> PrecLandSetpoint:
        return PrecLandSetpoint(self._sp.copy(), land=False)

    def _run_start(self, now: float) -> PrecLandSetpoint | None:
        if self._switch_horizontal_approach(now):
            return self._run_horizontal_approach(now)
        if float(np.hypot(*(self._sp[:2] - self._pos[:2]))) < self.params["NAV_ACC_RAD"]:
            if self._point_reached is None:
                self._point_reached = now
            if self.params["PLD_SRCH_TOUT"] > 0:
                if now - self._point_reached > DWELL_S:
                    self._switch_search(now)
            else:
                self._switch_fallback(now)
                return None
        return self._hold()

    def _run_horizontal_approach(self, now: float) -> PrecLandSetpoint | None:
        if not self._check_horizontal_approach():
            self._event("Lost landing target while landing (horizontal approach).")
            self._sp = self._pos.copy()
            if not self._switch_start(now):
                self._switch_fallback(now)
                return None
            return self._hold()
        if self._over_fresh_target():
            if self._point_reached is None:
                self._point_reached = now
            if now - self._point_reached > DWELL_S:
                self._switch(PrecLandState.DESCEND_ABOVE_TARGET, now)
                return self._run_descend(now)
        if now - self._state_start > STATE_TIMEOUT_S:
            self._event("Precision landing took too long during horizontal approach phase.")
            self._switch_fallback(now)
            return None
        xy = self._slewrate(now, self._target[:2])
        self._sp = np.array([xy[0], xy[1], self._approach_z])
        return self._hold()

    def _run_descend(self, now: float) -> PrecLandSetpoint | None:
        if self._final_approach_condition():
            ok = now - self._target_s < FINAL_TARGET_AGE_S
        else:
            ok = self._valid
        if not ok:
            if self._final_approach_condition():
                self._switch(PrecLandState.FINAL_APPROACH, now)
                return None
            self._event("Lost landing target while landing (descending).")
            self._sp = self._pos.copy()
            if not self._switch_start(now):
                self._switch_fallback(now)
                return None
            return self._hold()
        self._sp = np.array([self._target[0], self._target[1], self._pos[2]])
        return PrecLandSetpoint(self._sp.copy(), land=True)

    def _run_search(self, now: float) -> PrecLandSetpoint | None:
        if self._updated and self._valid and self._acquired is None:
            # seen: stop climbing, with a margin so as not to stop abruptly
            self._acquired = now
            self._sp[2] = max(self._pos[2] - 1.0, self._sp[2])
        if self._acquired is not None and now - self._acquired > 1.0 and \
                self._switch_horizontal_approach(now):
            return self._run_horizontal_approach(now)
        if now - self._state_start > self.params["PLD_SRCH_TOUT"]:
            self._event("Search timed out")
            self._switch_fallback(now)
            return None
        return self._hold()

    # -- conditions and transitions -------------------------------------------------------

    def _within_hacc(self) -> bool:
        r = self.params["PLD_HACC_RAD"]
        return abs(self._target[0] - self._pos[0]) < r and abs(self._target[1] - self._pos[1]) < r

    def _over_fresh_target(self) -> bool:
        return self._updated and self._within_hacc()

    def _check_horizontal_approach(self) -> bool:
        # approaching: keep going to where it was last seen; there, it must be seen
        return self._valid if self._within_hacc() else True

    def _final_approach_condition(self) -> bool:
        return self._valid and (self._target[2] - self._pos[2]) < self.params["PLD_FAPPR_ALT"]

    def _switch(self, state: PrecLandState, now: float) -> None:
        self.state = state
        self._state_start = now

    def _switch_start(self, now: float) -> bool:
        if self._search_cnt > int(self.params["PLD_MAX_SRCH"]):
            return False
        self._search_cnt += 1
        self._point_reached = None
        self._switch(PrecLandState.START, now)
        return True

    def _switch_horizontal_approach(self, now: float) -> bool:
        if not (self._updated and self._valid):
            return False
        self._approach_z = float(self._pos[2])
        self._point_reached = None
        self._slew = None
        self._switch(PrecLandState.HORIZONTAL_APPROACH, now)
        return True

    def _switch_search(self, now: float) -> None:
        self._event("Climbing to search altitude.")
        self._sp[2] = self._origin_down - self.params["PLD_SRCH_ALT"]
        self._acquired = None
        self._switch(PrecLandState.SEARCH, now)

    def _switch_fallback(self, now: float) -> None:
        self._event("Falling back to normal land.")
        self._sp = self._pos.copy()
        self._switch(PrecLandState.FALLBACK, now)

    def _slewrate(self, now: float, goal) -> np.ndarray:
        """The setpoint moved towards ``goal`` within MPC_XY_CRUISE and MPC_ACC_HOR, slowing
        so that it can stop there (PX4's slewrate)."""
        goal = np.asarray(goal, dtype=float)
        v_max, a_max = self.params["MPC_XY_CRUISE"], self.params["MPC_ACC_HOR"]
        if self._slew is None:
            dt = 0.05
            prev = self._sp[:2].copy()
            self._slew = (prev, prev - self._vel[:2] * dt)
        else:
            dt = now - self._last_slew_s
            if dt <= 1e-6:
                return self._slew[0]
        self._last_slew_s = now
        sp, sp_prev = self._slew
        cur = goal.copy()
        vel = (cur - sp) / dt
        if np.linalg.norm(vel) > v_max:
            cur = sp + vel / np.linalg.norm(vel) * v_max * dt
        acc = (cur - 2.0 * sp + sp_prev) / (dt * dt)
        if np.linalg.norm(acc) > a_max:
            cur = 2.0 * sp - sp_prev + acc / np.linalg.norm(acc) * a_max * dt * dt
        stop_speed = math.sqrt(a_max * float(np.linalg.norm(sp - goal)))
        vel = (cur - sp) / dt
        if np.linalg.norm(vel) > stop_speed:
            cur = sp + vel / np.linalg.norm(vel) * stop_speed * dt
        self._slew = (cur, sp)
        return cur
