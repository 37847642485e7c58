"""The simulated vehicle's commander: arming, modes and failsafes, after PX4's ``commander``.

PX4 separates the mode the user asked for (``user_intended_mode``) from the mode the vehicle
flies (``nav_state``): a failsafe overrides the second without forgetting the first, and when
a failsafe whose condition clears by itself is over (offboard setpoints came back), the vehicle
returns to what the user asked for. The same here:

* :meth:`Commander.request_mode` is a user's mode change (DO_SET_MODE, takeoff, land, RTL, …):
  refused with :class:`CommandRejected` when the mode cannot run (PX4's mode requirements:
  local position for the position modes, a fresh setpoint for OFFBOARD, a valid mission for
  MISSION, a home position for RTL). A user's mode change ends the failsafes that allow it.
* :meth:`Commander.update` runs at the position-loop rate: auto-disarm (COM_DISARM_LAND,
  COM_DISARM_PRFLT), and the failsafe checks — offboard loss (COM_OF_LOSS_T → COM_OBL_RC_ACT),
  data-link loss (COM_DL_LOSS_T → NAV_DLL_ACT), geofence (GF_ACTION), battery (BAT_*_THR →
  COM_LOW_BAT_ACT), loss of the local position in the air (land).
* A failsafe that returns or lands holds first for COM_FAIL_ACT_T seconds (PX4's "failsafe
  action delay": the user may take over), then acts; offboard loss and a lost position act
  at once, as in PX4.
* Failsafes trigger on the rising edge of their condition, as PX4's ``CHECK_FAILSAFE``. Those
  that do not end by themselves (data link, geofence, battery, position loss) end on a mode
  change or disarm once their condition is gone (PX4's ``OnModeChangeOrDisarm``). A user's
  mode change while the condition persists takes over: the failsafe stops deciding the mode
  and does not act again until its condition has cleared and comes back (a vehicle outside
  its geofence can be flown back in). A warning warns again at each new breach.

There is no RC in the simulation: actions that need a pilot (COM_OBL_RC_ACT 0–2: position,
altitude, manual mode) fall back to HOLD as on PX4 without manual control, and the RC-loss
failsafe (NAV_RCL_ACT) never triggers.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass

from drivers.base import FlightMode, Health
from drivers.sim.flight.params import Parameters


class CommandRejected(Exception):
    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Action(enum.IntEnum):
    """Failsafe actions, mildest first (the most severe active one wins)."""

    NONE = 0
    WARN = 1
    HOLD = 2
    RTL = 3
    LAND = 4
    DISARM = 5
    TERMINATE = 6


ACTION_MODES = {Action.HOLD: FlightMode.HOLD, Action.RTL: FlightMode.RETURN,
                Action.LAND: FlightMode.LAND}

#: COM_OBL_RC_ACT → action (0–2 need a pilot's sticks: without RC, HOLD as on PX4).
OFFBOARD_LOSS_ACTIONS = {0: Action.HOLD, 1: Action.HOLD, 2: Action.HOLD, 3: Action.RTL,
                         4: Action.LAND, 5: Action.HOLD, 6: Action.TERMINATE, 7: Action.DISARM}
#: NAV_DLL_ACT → action.
DATALINK_LOSS_ACTIONS = {0: Action.NONE, 1: Action.HOLD, 2: Action.RTL, 3: Action.LAND,
                         5: Action.TERMINATE, 6: Action.DISARM}
#: GF_ACTION → action.
GEOFENCE_ACTIONS = {0: Action.NONE, 1: Action.WARN, 2: Action.HOLD, 3: Action.RTL,
                    4: Action.TERMINATE, 5: Action.LAND}

OFFBOARD_LOST = "offboard setpoints lost"
DATALINK_LOST = "data link lost"
GEOFENCE = "geofence breached"
BATTERY_CRITICAL = "battery critical"
BATTERY_EMERGENCY = "battery emergency"
POSITION_LOST = "local position lost"


@dataclass(slots=True)
class _Failsafe:
    name: str
    action: Action
    since_s: float
    #: ends by itself when its condition clears (else on a user's mode change or disarm)
    clears_with_condition: bool
    #: the action comes after COM_FAIL_ACT_T of HOLD
    delayed: bool
    #: the condition holds now (it was true at the last check)
    present: bool = True
    #: the user changed mode while it was present: it no longer decides the mode
    taken_over: bool = False


@dataclass(frozen=True, slots=True)
class Inputs:
    """What the commander looks at each position-loop tick."""

    now_s: float
    landed: bool
    health: Health
    battery_fraction: float
    #: age of the newest offboard setpoint (inf: none yet) and whether the vehicle can fly it
    setpoint_age_s: float
    setpoint_flyable: bool
    #: a ground station's heartbeat was heard and has now been missing this long (0: fine)
    gcs_silent_s: float
    geofence_breach: str | None
    has_home: bool


class Commander:
    def __init__(self, params: Parameters, event: Callable[[str], None]) -> None:
        self.params = params
        self._event = event
        self.armed = False
        self.user_mode = FlightMode.HOLD
        self.mode = FlightMode.HOLD
        self._failsafes: dict[str, _Failsafe] = {}
        self._armed_at = 0.0
        self._ever_airborne = False
        self._landed_since: float | None = None
        self.terminated = False
        self._now = 0.0
        self._failsafe_deciding = False  # a failsafe decided the mode at the last _apply
        #: called when the effective mode changes: (new mode, previous mode)
        self.on_mode_change: Callable[[FlightMode, FlightMode], None] = lambda new, old: None
        #: called when the vehicle disarms (the motors stop)
        self.on_disarm: Callable[[], None] = lambda: None

    # ------------------------------------------------------------------------------------
    # State
    # ------------------------------------------------------------------------------------

    @property
    def failsafe(self) -> str | None:
        """The failsafe that decides the mode now (None: the user's mode is flown)."""
        active = self._deciding()
        return active.name if active is not None else None

    def _deciding(self) -> _Failsafe | None:
        acting = [f for f in self._failsafes.values()
                  if f.action > Action.WARN and not f.taken_over]
        return max(acting, key=lambda f: (f.action, -f.since_s)) if acting else None

    # ------------------------------------------------------------------------------------
    # User commands
    # ------------------------------------------------------------------------------------

    def arming_problem(self, health: Health, landed: bool,
                       battery_fraction: float) -> str | None:
        """Why the vehicle may not arm now (None: it may)."""
        if not health.armable:
            return "preflight checks failed: " + ", ".join(health.problems())
        if battery_fraction <= self.params["BAT_CRIT_THR"]:
            return "preflight checks failed: battery critical"
        if not landed:
            return "not landed"
        return None

    def arm(self, now_s: float) -> None:
        """Arm (the caller has checked :meth:`arming_problem`)."""
        self._now = now_s
        if self.armed:
            return
        self.armed = True
        self.terminated = False
        self._armed_at = now_s
        self._ever_airborne = False
        self._landed_since = now_s
        self._failsafes.clear()
        self._event("armed")

    def disarm(self, why: str) -> None:
        if not self.armed:
            return
        self.armed = False
        self._failsafes.clear()
        if self.user_mode in (FlightMode.TAKEOFF, FlightMode.LAND, FlightMode.RETURN,
                              FlightMode.PRECLAND):
            self.user_mode = FlightMode.HOLD  # done: the next flight starts from HOLD
        self._event(why)
        self.on_disarm()
        self._apply()

    def request_mode(self, mode: FlightMode, *, can_run: str | None = None) -> None:
        """A user's mode change. ``can_run`` is why the mode cannot run now (None: it can)."""
        if can_run is not None:
            raise CommandRejected(can_run)
        # a user's choice ends the failsafes that a mode change may end (PX4: the user takes
        # over): those that end with their condition are checked again at the next tick
        # (offboard loss comes back while OFFBOARD is asked for without setpoints); the others
        # end if their condition is gone, else stop deciding until it clears
        for name, f in list(self._failsafes.items()):
            if f.action <= Action.WARN:
                continue
            if f.clears_with_condition or not f.present:
                del self._failsafes[name]
            elif not f.taken_over:
                f.taken_over = True
                self._event(f"{name}: user took over")
        self.user_mode = mode
        self._apply()

    # ------------------------------------------------------------------------------------
    # The tick
    # ------------------------------------------------------------------------------------

    def update(self, inp: Inputs) -> None:
        p = self.params
        now = self._now = inp.now_s
        if self.armed:
            if inp.landed:
                if self._landed_since is None:
                    self._landed_since = now
                landed_for = now - self._landed_since
                disarm_land, disarm_preflight = p["COM_DISARM_LAND"], p["COM_DISARM_PRFLT"]
                if self._ever_airborne and disarm_land > 0 and landed_for >= disarm_land:
                    self.disarm("auto-disarmed after landing")
                elif (not self._ever_airborne and disarm_preflight > 0
                      and now - self._armed_at >= disarm_preflight):
                    self.disarm("auto-disarmed: no takeoff")
            else:
                self._landed_since = None
                self._ever_airborne = True
        if not self.armed:
            self._failsafes.clear()
            self._apply()
            return

        in_air = not inp.landed
        self._check(now, OFFBOARD_LOST,
                    self.user_mode is FlightMode.OFFBOARD and
                    (inp.setpoint_age_s > p["COM_OF_LOSS_T"] or not inp.setpoint_flyable),
                    OFFBOARD_LOSS_ACTIONS.get(int(p["COM_OBL_RC_ACT"]), Action.HOLD),
                    clears=True, delayed=False)
        dl_loss_s = p["COM_DL_LOSS_T"]
        # PX4: the data-link loss action ends on a mode change or disarm, not when the link
        # comes back (an RTL flies on)
        self._check(now, DATALINK_LOST, in_air and inp.gcs_silent_s > dl_loss_s,
                    DATALINK_LOSS_ACTIONS.get(int(p["NAV_DLL_ACT"]), Action.NONE), clears=False)
        self._check(now, GEOFENCE, in_air and inp.geofence_breach is not None,
                    GEOFENCE_ACTIONS.get(int(p["GF_ACTION"]), Action.NONE), clears=False,
                    detail=inp.geofence_breach)
        low_bat_act = int(p["COM_LOW_BAT_ACT"])
        critical = inp.battery_fraction <= p["BAT_CRIT_THR"]
        emergency = inp.battery_fraction <= p["BAT_EMERGEN_THR"]
        critical_action = {1: Action.RTL, 2: Action.LAND, 3: Action.RTL}.get(low_bat_act,
                                                                             Action.WARN)
        self._check(now, BATTERY_CRITICAL, in_air and critical, critical_action, clears=False)
        self._check(now, BATTERY_EMERGENCY, in_air and emergency,
                    {1: Action.RTL, 2: Action.LAND, 3: Action.LAND}.get(low_bat_act, Action.WARN),
                    clears=False)
        self._check(now, POSITION_LOST, in_air and not inp.health.local_position_ok,
                    Action.LAND, clears=False, delayed=False)
        if self.user_mode is FlightMode.RETURN and not inp.has_home:
            self.user_mode = FlightMode.HOLD
        self._apply()

    def _check(self, now: float, name: str, condition: bool, action: Action, *, clears: bool,
               delayed: bool = True, detail: str | None = None) -> None:
        active = self._failsafes.get(name)
        if condition and active is None and action is not Action.NONE:
            # a warning, a hold, or stopping the motors happen at once; the others after
            # COM_FAIL_ACT_T of HOLD (PX4's failsafe action delay)
            delay = delayed and action in (Action.RTL, Action.LAND) and \
                self.params["COM_FAIL_ACT_T"] > 0
            self._failsafes[name] = _Failsafe(name, action, now, clears, delay)
            text = f"failsafe: {name}" + (f" ({detail})" if detail else "")
            if action is Action.WARN:
                self._event(f"warning: {name}" + (f" ({detail})" if detail else ""))
            elif delay:
                self._event(f"{text}: holding, then {action.name.lower()} in "
                            f"{self.params['COM_FAIL_ACT_T']:g} s")
            else:
                self._event(f"{text} → {action.name.lower()}")
        elif not condition and active is not None:
            if active.clears_with_condition:
                del self._failsafes[name]
                self._event(f"{name}: cleared")
            elif active.taken_over or active.action is Action.WARN:
                del self._failsafes[name]  # a new breach acts (or warns) again
            else:
                active.present = False  # ends at the next mode change or disarm
        elif condition and active is not None:
            active.present = True

    def _apply(self) -> None:
        """Set the effective mode from the user's and the failsafes'."""
        mode = self.user_mode
        f = self._deciding()
        if f is not None and self.armed:
            if f.action in (Action.DISARM, Action.TERMINATE):
                self.terminated = f.action is Action.TERMINATE
                self._failsafes.clear()
                self.disarm(f"failsafe: {f.name} → "
                            f"{'flight termination' if self.terminated else 'disarm'}")
                return
            waiting = f.delayed and self._now - f.since_s < self.params["COM_FAIL_ACT_T"]
            mode = FlightMode.HOLD if waiting else ACTION_MODES[f.action]
        deciding_before, self._failsafe_deciding = self._failsafe_deciding, \
            f is not None and self.armed
        if mode is not self.mode:
            old, self.mode = self.mode, mode
            if f is not None and mode is ACTION_MODES.get(f.action):
                self._event(f"failsafe: {f.name} → {mode.value}")
            else:
                self._event(f"mode {old.value} → {mode.value}")
            self.on_mode_change(mode, old)
        elif self._failsafe_deciding and not deciding_before:
            # a failsafe takes over the mode the vehicle already flies (its HOLD during the
            # user's HOLD with a DO_REPOSITION under way): the mode starts again from here,
            # so the vehicle stops instead of flying on
            self._event(f"failsafe: {f.name} → {mode.value}")
            self.on_mode_change(mode, mode)

    def complete(self, mode: FlightMode, then: FlightMode) -> None:
        """An auto mode finished its job (takeoff reached its altitude): the user's mode
        becomes ``then`` (PX4 switches to HOLD after TAKEOFF)."""
        if self.user_mode is mode:
            self.user_mode = then
        if self.mode is mode:
            self._apply()
