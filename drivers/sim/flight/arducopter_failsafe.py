"""The simulated ArduCopter's failsafe actions (:mod:`drivers.sim.flight.arducopter`), as
ArduCopter's ``events.cpp`` takes them: the battery monitor's (:mod:`.ac_battery`), and the
"SmartRTL or RTL" / "SmartRTL or Land" actions of the GCS and fence failsafes (FS_GCS_ENABLE
3 and 4, FENCE_ACTION 3 and 5), which fly SMART_RTL (:mod:`.ac_smartrtl`) when its path is
there and otherwise say so ("SmartRTL Unavailable, Trying RTL Mode") and fly the other."""

from __future__ import annotations

import contextlib
from collections.abc import Callable

import numpy as np

from drivers.geometry import yaw_from_quat
from drivers.mavlink.ardupilot import CopterMode
from drivers.sim.flight.ac_battery import Action, BatteryFailsafe
from drivers.sim.flight.ac_smartrtl import SmartRtlFlight, SmartRtlPath
from drivers.sim.flight.arducopter_params import SiLimits
from drivers.sim.flight.commander import DATALINK_LOST, GEOFENCE, CommandRejected
from drivers.sim.flight.flight_stack import EstimatedState, FlightStack
from drivers.sim.flight.guided import GuidedInput
from drivers.sim.flight.params import Parameters

#: a cascade failsafe → (ArduCopter's parameter, its values that try SMART_RTL first)
_SMART_RTL_FIRST = {
    DATALINK_LOST: ("FS_GCS_ENABLE", {3: Action.SMARTRTL, 4: Action.SMARTRTL_LAND}),
    GEOFENCE: ("FENCE_ACTION", {3: Action.SMARTRTL, 5: Action.SMARTRTL_LAND})}
#: the battery failsafe's actions → the mode flown (SMART_RTL tried first where it says)
_BATTERY_MODES = {Action.LAND: CopterMode.LAND, Action.RTL: CopterMode.RTL,
                  Action.SMARTRTL: CopterMode.RTL, Action.SMARTRTL_LAND: CopterMode.LAND,
                  Action.AUTO_DO_LAND_START: CopterMode.RTL, Action.BRAKE_LAND: CopterMode.BRAKE}


class Failsafes:
    """The failsafe actions of the simulated ArduCopter, and SMART_RTL's flight."""

    stack: FlightStack
    params: Parameters
    guided: GuidedInput
    si: SiLimits
    smart_rtl: SmartRtlPath
    _srtl: SmartRtlFlight | None
    _failsafe_seen: str | None
    _now: float
    _say: Callable[[str], None]

    def set_copter_mode(self, number: int) -> None:
        raise NotImplementedError

    def _fly_smart_rtl(self, est: EstimatedState) -> None:
        sp = self._srtl.setpoint(est.position_ned_m, self.params["WPNAV_RADIUS"] / 100.0)
        if sp is not None:
            self.stack.push_setpoint(sp, self._now)
            return
        self._srtl = None  # 2 m above home: land, or descend to RTL_ALT_FINAL and hover there
        home, final_m = self.stack.navigator.home, self.si.rtl_final_altitude_m
        if final_m > 0 and home is not None:
            target = np.array([est.position_ned_m[0], est.position_ned_m[1], home[2] - final_m])
            self.guided.hold(target, yaw_from_quat(est.q_ned_frd), self._now)
        else:
            self.stack.land()

    def _try_smart_rtl(self, otherwise: CopterMode) -> None:
        """A failsafe's "SmartRTL or …": SMART_RTL when it can fly, else ``otherwise``."""
        if self.smart_rtl.active:
            with contextlib.suppress(CommandRejected):
                self.set_copter_mode(int(CopterMode.SMART_RTL))
                return
        self._say(_unavailable(otherwise))
        try:
            self.set_copter_mode(int(otherwise))
        except CommandRejected:
            self.set_copter_mode(int(CopterMode.LAND))  # ("… or land with pause")

    def _smart_rtl_failsafe(self) -> None:
        """The cascade's GCS or fence failsafe, when its action tries SMART_RTL first."""
        name = self.stack.failsafe
        if name == self._failsafe_seen:
            return
        self._failsafe_seen = name
        param, actions = _SMART_RTL_FIRST.get(name, ("", {}))
        action = actions.get(int(self.params[param])) if param else None
        if action is not None and self.smart_rtl.active:
            self._try_smart_rtl(_BATTERY_MODES[action])
        elif action is not None:  # the cascade flies the "or"
            self._say(_unavailable(_BATTERY_MODES[action]))

    def _battery_failsafe(self, fs: BatteryFailsafe) -> None:
        self._say(fs.text)
        if fs.disarm or fs.action is Action.TERMINATE:
            self.stack.disarm(force=not fs.disarm)
        elif fs.action in (Action.SMARTRTL, Action.SMARTRTL_LAND):
            self._try_smart_rtl(_BATTERY_MODES[fs.action])
        elif fs.action is not Action.NONE:
            with contextlib.suppress(CommandRejected):
                self.set_copter_mode(int(_BATTERY_MODES[fs.action]))
                return
            self.set_copter_mode(int(CopterMode.LAND))


def _unavailable(otherwise: CopterMode) -> str:
    return "SmartRTL Unavailable, " + ("Trying RTL Mode" if otherwise is CopterMode.RTL
                                       else "Using Land Mode")
