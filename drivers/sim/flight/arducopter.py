"""The simulated vehicle as ArduCopter (4.5): its modes, arming, GUIDED, takeoff, landing,
RTL, AUTO and failsafes as a ground station and a companion computer meet them, read from
ArduPilot's source (``docs/reference/ardupilot-mavlink.md``), flown on the PX4-like cascade
(:class:`~drivers.sim.flight.flight_stack.FlightStack`) underneath, whose parameters follow
ArduPilot's (:func:`internal_values`).

What is ArduCopter's here:

* **modes** by number (:mod:`~drivers.sim.flight.arducopter_modes`); the boot mode is
  STABILIZE; any mode can be chosen while disarmed, and "requires position" is checked when
  armed; the pilot modes only on the ground (no RC in the simulation). A mode change that
  fails says ``Mode change to X failed: why``.
* **arming** only in the modes that allow it from a ground station (GUIDED, LOITER, STABILIZE,
  …; AUTO with AUTO_OPTIONS bit 0), with the position for the modes that need it; the texts are
  ArduPilot's (``Arm: RTL mode not armable``, ``Arm: Need Position Estimate``) and "Arming
  motors". Disarming in the air needs force. Armed and not taking off, it disarms after
  DISARM_DELAY; a landing in LAND, RTL or AUTO disarms at touchdown.
* **GUIDED** (:mod:`~drivers.sim.flight.guided`): targets never take off; NAV_TAKEOFF does
  (GUIDED, LOITER), to the altitude above home, at WPNAV_SPEED_UP, then holds in GUIDED.
  Velocity targets stop after GUID_TIMEOUT; no target-loss failsafe.
* **AUTO** flies the mission (the MAVLink face keeps seq 0 as home); armed on the ground it
  needs a takeoff first (``Auto: Missing Takeoff Cmd``) and starts on MISSION_START (or at once
  with AUTO_OPTIONS bit 1); at the end it loiters in the air (LOITER) or disarms on the ground.
* **RTL** climbs to max(RTL_ALT, current + RTL_CLIMB_MIN) (within RTL_CONE_SLOPE × distance of
  home, but at least 2.5 m above the current height; never lower than now), returns at
  RTL_SPEED (or WPNAV_SPEED), loiters RTL_LOIT_TIME, then lands and disarms (RTL_ALT_FINAL > 0:
  descends to it and hovers).
* **LAND** descends at LAND_SPEED_HIGH (or WPNAV_SPEED_DN) to LAND_ALT_LOW, then LAND_SPEED;
  with PLND_ENABLED and PLND_TYPE 1 it lands on the LANDING_TARGET the companion reports.
* **CIRCLE** orbits a centre CIRCLE_RADIUS ahead of the vehicle at CIRCLE_RATE, facing it.
* **failsafes** change the mode, as ArduCopter's do (FS_GCS_ENABLE after FS_GCS_TIMEOUT of a
  ground station's silence — the face counts only SYSID_MYGCS's heartbeats; the fence's
  FENCE_ACTION on a breach of FENCE_RADIUS / FENCE_ALT_MAX); the user's next mode change
  ends them.

* **SMART_RTL** retraces the path flown (:mod:`.ac_smartrtl`); the failsafes' "SmartRTL or
  RTL" and "SmartRTL or Land" actions fly it when its path is there.
* the **battery failsafe** is ArduPilot's monitor (:mod:`.ac_battery`): BATT_LOW_VOLT /
  BATT_CRT_VOLT for BATT_LOW_TIMER, BATT_LOW_MAH / BATT_CRT_MAH, BATT_FS_LOW_ACT /
  BATT_FS_CRT_ACT (PX4's thresholds underneath are off).

Precision landing is AC_PrecLand's, with its retry state machine (:mod:`.ac_precland`).

Not ArduCopter's (yet): GUIDED_NOGPS and AVOID_ADSB are refused; the EKF failsafe is the loss
of position (land).
"""

from __future__ import annotations

import contextlib
import math
from collections import deque

import numpy as np

from drivers.base import Battery, FlightMode, Health
from drivers.geo import GlobalOrigin
from drivers.geometry import yaw_from_quat
from drivers.mavlink.ardupilot import CopterMode, flight_mode
from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.ac_battery import AcBatteryMonitor
from drivers.sim.flight.ac_precland import AcPrecLand
from drivers.sim.flight.ac_smartrtl import SmartRtlFlight, SmartRtlPath
from drivers.sim.flight.arducopter_failsafe import Failsafes
from drivers.sim.flight.arducopter_modes import MODES, Flown
from drivers.sim.flight.arducopter_nav import (
    Circle,
    FlightModeCommands,
    GuidedCommands,
    OnCascade,
    arducopter_text,
    rtl_return_altitude_m,
    starts_with_takeoff,
)
from drivers.sim.flight.arducopter_params import SiLimits, si_limits
from drivers.sim.flight.commander import CommandRejected
from drivers.sim.flight.flight_stack import Airframe, EstimatedState, FlightStack
from drivers.sim.flight.guided import GuidedInput
from drivers.sim.flight.navigator.context import MissionState
from drivers.sim.flight.params import ParamError, Parameters

MAV_CMD_NAV_TAKEOFF = 22
#: AUTO_OPTIONS bits
_AUTO_ARM, _AUTO_NO_THROTTLE = 1, 2
#: FS_GCS_ENABLE → PX4's NAV_DLL_ACT underneath (1 RTL, 3/6 SmartRTL or Auto-RTL → RTL,
#: 4 SmartRTL or Land, 5 Land, 7 Brake or Land → land)
_GCS_ACTIONS = {0: 0, 1: 2, 3: 2, 4: 3, 5: 3, 6: 2, 7: 3}
#: FENCE_ACTION → PX4's GF_ACTION (0 report → warn, 1 RTL, 2 land, 3 SmartRTL → RTL,
#: 4 brake → hold, 5 SmartRTL or land → land)
_FENCE_ACTIONS = {0: 1, 1: 3, 2: 5, 3: 3, 4: 2, 5: 5}
#: the mode a failsafe's action flies, as ArduCopter reports it
_FAILSAFE_MODES = {FlightMode.RETURN: CopterMode.RTL, FlightMode.LAND: CopterMode.LAND,
                   FlightMode.HOLD: CopterMode.BRAKE}
#: what the cascade underneath is handed as its battery: ArduCopter's own monitor acts
_CASCADE_BATTERY = Battery(voltage_v=0.0, current_a=0.0, remaining_fraction=1.0)


def internal_values(values: dict[str, float], si: SiLimits) -> dict[str, float]:
    """The PX4 parameters underneath that carry ArduCopter's ``values`` (by name)."""
    fence_type = int(values["FENCE_TYPE"])
    fence_on = int(values["FENCE_ENABLE"]) != 0
    return {
        "MPC_XY_CRUISE": si.wp_speed_m_s,
        "MPC_XY_VEL_MAX": max(si.wp_speed_m_s, values["LOIT_SPEED"] / 100.0),
        "MPC_Z_V_AUTO_UP": si.wp_climb_m_s, "MPC_TKO_SPEED": si.wp_climb_m_s,
        "MPC_Z_V_AUTO_DN": si.land_speed_high_m_s,
        "MPC_Z_VEL_MAX_UP": max(si.wp_climb_m_s, values["PILOT_SPEED_UP"] / 100.0),
        "MPC_Z_VEL_MAX_DN": max(si.wp_descent_m_s, si.land_speed_high_m_s),
        "MPC_LAND_SPEED": si.land_speed_m_s,
        "MPC_LAND_ALT1": si.land_alt_low_m, "MPC_LAND_ALT2": si.land_alt_low_m,
        "MPC_TILTMAX_AIR": si.max_tilt_deg,
        "MPC_ACC_HOR": values["WPNAV_ACCEL"] / 100.0,
        "NAV_ACC_RAD": values["WPNAV_RADIUS"] / 100.0,
        "RTL_RETURN_ALT": si.rtl_altitude_m, "RTL_CONE_ANG": 0,
        "RTL_DESCEND_ALT": si.rtl_final_altitude_m or si.rtl_altitude_m,
        "RTL_LAND_DELAY": -1.0 if si.rtl_final_altitude_m > 0 else si.rtl_loiter_s,
        "COM_DISARM_LAND": si.disarm_delay_s or -1.0,
        "COM_DISARM_PRFLT": si.disarm_delay_s or -1.0,
        "COM_FAIL_ACT_T": 0.0,  # ArduCopter's failsafes act at once
        "NAV_DLL_ACT": _GCS_ACTIONS.get(int(values["FS_GCS_ENABLE"]), 0),
        "COM_DL_LOSS_T": values["FS_GCS_TIMEOUT"],
        "GF_ACTION": _FENCE_ACTIONS.get(int(values["FENCE_ACTION"]), 3) if fence_on else 0,
        "GF_MAX_HOR_DIST": values["FENCE_RADIUS"] if fence_on and fence_type & 2 else 0.0,
        "GF_MAX_VER_DIST": values["FENCE_ALT_MAX"] if fence_on and fence_type & 1 else 0.0,
    }


class ArduCopterFirmware(OnCascade, GuidedCommands, FlightModeCommands, Failsafes):
    """ArduCopter on the simulated airframe. ``params`` are ArduPilot's (what a ground station
    reads and sets); ``internal`` the PX4 parameters of the cascade underneath, kept in step."""

    def __init__(self, cfg: FlightStackConfig, airframe: Airframe, motor_idle_fraction: float,
                 params: Parameters, internal: Parameters,
                 origin: GlobalOrigin | None = None, *,
                 battery_resistance_ohm: float = 0.0) -> None:
        self.params = params
        self.internal = internal
        self.stack = FlightStack(cfg, airframe, motor_idle_fraction, internal, origin)
        #: a ground station (SYSID_MYGCS) was heard: the GCS failsafe is armed from then on
        self.gcs_heard = False
        self.guided = GuidedInput()
        self.stack.offboard = self.guided
        self.navigator = self.stack.navigator
        self.navigator.precland = AcPrecLand(params, self._say)  # LAND with PLND
        self.nav_events = self.stack.nav_events
        self.hover_thrust = self.stack.hover_thrust
        #: (time_s, text) in ArduCopter's words, drained by the simulator
        self.events: deque[tuple[float, str]] = deque(maxlen=256)
        self.copter_mode = CopterMode.STABILIZE
        self._now = 0.0
        self._airborne = False
        self._was_armed = False
        self._auto_started = False
        self._circle: Circle | None = None
        self.smart_rtl = SmartRtlPath(params, self._say)
        self._srtl: SmartRtlFlight | None = None
        self.battery = AcBatteryMonitor(params, self._say, battery_resistance_ohm)
        self._failsafe_seen: str | None = None
        self.si = si_limits(params.snapshot())
        params.on_change(lambda name, value: self._apply_params())
        self._apply_params()

    # ------------------------------------------------------------------------------------
    # Reported state
    # ------------------------------------------------------------------------------------

    @property
    def mode(self) -> FlightMode:
        """The mode as a MAVLink driver reads an ArduCopter's (GUIDED is OFFBOARD, …)."""
        return flight_mode(int(self.copter_mode))

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT custom_mode: the Copter mode number."""
        return int(self.copter_mode)

    @property
    def failsafe(self) -> str | None:
        """The failsafe acting (the cascade's, or the battery monitor's level)."""
        level = self.battery.level
        return self.stack.failsafe or (f"battery {level.name.lower()}" if level else None)

    @property
    def position_controlled(self) -> bool:
        """The horizontal position controller runs (HEARTBEAT's GUIDED_ENABLED flag)."""
        return self.armed and MODES[self.copter_mode].flown not in (Flown.PILOT,)

    # ------------------------------------------------------------------------------------
    # Commands (raise CommandRejected with ArduCopter's words to refuse)
    # ------------------------------------------------------------------------------------

    def set_copter_mode(self, number: int) -> None:
        """DO_SET_MODE / SET_MODE with custom mode ``number``."""
        try:
            mode = CopterMode(number)
            spec = MODES[mode]
        except (ValueError, KeyError):
            raise CommandRejected(f"No such mode {number}") from None
        name = spec.name
        if mode is self.copter_mode:
            return
        armed = self.armed
        if spec.flown is Flown.UNSUPPORTED:
            raise CommandRejected(f"Mode change to {name} failed: not modelled by the "
                                  "simulator")
        if armed and spec.flown is Flown.PILOT and not self.landed:
            raise CommandRejected(f"Mode change to {name} failed: needs a pilot (no RC in "
                                  "the simulation)")
        if armed and spec.requires_gps and not self.stack.health.local_position_ok:
            raise CommandRejected(f"Mode change to {name} failed: requires position")
        try:
            self._enter(mode, spec.flown)
        except CommandRejected as exc:
            raise CommandRejected(f"Mode change to {name} failed: init failed ({exc.reason})"
                                  ) from None
        self.copter_mode = mode

    def _enter(self, mode: CopterMode, flown: Flown) -> None:
        s = self.stack
        self._circle = None
        if self._srtl is not None:
            self._srtl.end()
            self._srtl = None
        if flown is Flown.GUIDED:
            est = s.require_estimate()
            self.guided.now_s = self._now
            self.guided.hold(est.position_ned_m, yaw_from_quat(est.q_ned_frd), self._now)
            s.start_offboard()
        elif flown is Flown.AUTO:
            self._enter_auto()
        elif flown is Flown.RTL:
            if self.armed:
                self._set_return_altitude()
            s.return_to_launch()
        elif flown is Flown.LAND:
            if self.armed and not self.landed and _precision_landing(self.params):
                s.precision_land()
            else:
                s.land()
        elif flown is Flown.SMART_RTL:
            if not self.smart_rtl.active:
                raise CommandRejected("no path home (SmartRTL is off for this flight)")
            if self.armed and not self.landed:
                est = s.require_estimate()
                self._srtl = SmartRtlFlight.start(self.smart_rtl, est.position_ned_m)
                self.guided.hold(est.position_ned_m, yaw_from_quat(est.q_ned_frd), self._now)
                s.start_offboard()
            else:
                s.hold()
        elif flown is Flown.CIRCLE:
            if self.armed and not self.landed:
                self._start_circle()
            else:
                s.hold()
        else:  # HOLD, and the pilot modes on the ground
            s.hold()

    def _enter_auto(self) -> None:
        s, nav = self.stack, self.stack.navigator
        self._auto_started = False
        if not self.armed:
            s.hold()
            return
        items = nav.items()
        if not items:
            raise CommandRejected("no mission")
        if self.landed and not starts_with_takeoff([i.command for i in items]):
            self._say("Auto: Missing Takeoff Cmd")
            raise CommandRejected("missing takeoff command")
        if self.landed and not int(self.params["AUTO_OPTIONS"]) & _AUTO_NO_THROTTLE:
            s.hold()  # waits on the ground for MISSION_START (a pilot would raise the throttle)
            return
        self._start_auto()

    def _start_auto(self) -> None:
        self.stack.start_mission()
        self._auto_started = True

    def mission_start(self) -> None:
        """MAV_CMD_MISSION_START (armed): AUTO, and the mission flies, from the ground too."""
        if not self.armed:
            raise CommandRejected("mission start: not armed")
        self.set_copter_mode(int(CopterMode.AUTO))
        if self.armed and not self._auto_started:
            self._start_auto()

    def arm(self) -> None:
        if self.armed:
            return
        spec = MODES[self.copter_mode]
        allowed = spec.gcs_arm or (self.copter_mode is CopterMode.AUTO and
                                   int(self.params["AUTO_OPTIONS"]) & _AUTO_ARM)
        if not allowed:
            raise CommandRejected(f"Arm: {spec.name} mode not armable")
        health = self.stack.health
        if spec.requires_gps and not health.local_position_ok:
            raise CommandRejected("Arm: Need Position Estimate")
        battery = self.battery.arming_problem()
        if battery is not None:
            raise CommandRejected(f"PreArm: {battery}")
        try:
            self.stack.arm()
        except CommandRejected as exc:
            raise CommandRejected(f"Arm: {exc.reason}") from None
        self._airborne = False
        est = self.stack.require_estimate()
        self.smart_rtl.set_home(self._now, health.local_position_ok, est.position_ned_m)
        if spec.flown is Flown.GUIDED:
            self.guided.hold(est.position_ned_m, yaw_from_quat(est.q_ned_frd), self._now)
        if self.copter_mode is CopterMode.AUTO:
            self._enter_auto()
        self._say("Arming motors")
        self._was_armed = True

    # ------------------------------------------------------------------------------------
    # The loop
    # ------------------------------------------------------------------------------------

    def observe(self, now_s: float, est: EstimatedState, health: Health) -> None:
        self._now = now_s
        self.guided.now_s = now_s
        self.guided.position_ned_m = est.position_ned_m
        self.stack.observe(now_s, est, health)

    def update_outer(self, now_s: float, dt_s: float, est: EstimatedState, health: Health,
                     height_agl_m: float, battery: Battery,
                     surface_velocity_ned_m_s: np.ndarray | None = None) -> None:
        self.observe(now_s, est, health)
        landing = MODES[self.copter_mode].flown is Flown.LAND or self.stack.position_loop.landing
        fs = self.battery.update(now_s, dt_s, battery, self.armed, self.landed, landing)
        if fs is not None:
            self._battery_failsafe(fs)
        self.guided.timeout_s = self.si.guided_timeout_s
        self.guided.auto_yaw = int(self.params["WP_YAW_BEHAVIOR"])
        if self._circle is not None:
            self.stack.push_setpoint(self._circle.setpoint(
                dt_s, math.radians(float(self.params["CIRCLE_RATE"]))), now_s)
        if self._srtl is not None:
            self._fly_smart_rtl(est)
        self.stack.update_outer(now_s, dt_s, est, health, height_agl_m, _CASCADE_BATTERY,
                                surface_velocity_ned_m_s)
        self._after_tick(est)

    def _after_tick(self, est: EstimatedState) -> None:
        s = self.stack
        self._translate_events()
        if not self.armed:
            if self._was_armed:
                self._was_armed = False
                self._auto_started = False
                self.battery.disarmed()
            return
        if not self.landed:
            self._airborne = True
        if self.copter_mode is not CopterMode.SMART_RTL:
            self.smart_rtl.update(self._now, s.health.local_position_ok, est.position_ned_m)
        self._smart_rtl_failsafe()
        failsafe_mode = _FAILSAFE_MODES.get(s.mode) if s.failsafe is not None else None
        if failsafe_mode is not None and failsafe_mode is not self.copter_mode:
            self.copter_mode = failsafe_mode  # ArduCopter's failsafes change the mode
            self._circle = None
        mode = self.copter_mode
        flown = MODES[mode].flown
        if flown is Flown.GUIDED and s.commander.user_mode is FlightMode.HOLD:
            # the takeoff reached its altitude: GUIDED holds there
            self.guided.hold(est.position_ned_m, yaw_from_quat(est.q_ned_frd), self._now)
            s.start_offboard()
        if flown is Flown.AUTO and self._auto_started and \
                s.navigator.status.state is MissionState.COMPLETE and s.mode is FlightMode.HOLD:
            if self.landed:
                s.disarm()
            else:
                self.copter_mode = CopterMode.LOITER  # ArduCopter's exit_mission
        if self.landed and self._airborne and (
                flown in (Flown.LAND, Flown.RTL, Flown.SMART_RTL) or s.position_loop.landing):
            s.disarm()  # LAND, RTL and AUTO's landing disarm at touchdown

    def _translate_events(self) -> None:
        """The cascade's events in ArduCopter's words (mode changes are not announced)."""
        while self.stack.events:
            when, text = self.stack.events.popleft()
            text = arducopter_text(text, self.stack.geofence_breach)
            if text is not None:
                self.events.append((when, text))

    def _say(self, text: str) -> None:
        self.events.append((self._now, text))

    # ------------------------------------------------------------------------------------
    # Mode details
    # ------------------------------------------------------------------------------------

    def _set_return_altitude(self) -> None:
        s = self.stack
        est = s.require_estimate()
        home = s.navigator.home if s.navigator.home is not None else est.position_ned_m
        target = rtl_return_altitude_m(self.params, self.si, est.position_ned_m, home)
        _set(self.internal, "RTL_RETURN_ALT", target)
        if self.si.rtl_final_altitude_m <= 0:
            _set(self.internal, "RTL_DESCEND_ALT", target)

    def _start_circle(self) -> None:
        est = self.stack.require_estimate()
        yaw = yaw_from_quat(est.q_ned_frd)
        self._circle = Circle(est.position_ned_m, yaw, self.params["CIRCLE_RADIUS"] / 100.0)
        self.guided.hold(est.position_ned_m, yaw, self._now)
        self.stack.start_offboard()

    def gcs_heartbeat(self) -> None:
        self.stack.gcs_heartbeat()
        if not self.gcs_heard:
            self.gcs_heard = True
            self._apply_params()

    def _apply_params(self) -> None:
        self.si = si_limits(self.params.snapshot())
        values = internal_values(self.params.snapshot(), self.si)
        if not self.gcs_heard:  # (PX4 would refuse to arm with NAV_DLL_ACT and no GCS)
            values["NAV_DLL_ACT"] = 0
        for name, value in values.items():
            _set(self.internal, name, value)


def _precision_landing(params: Parameters) -> bool:
    """LAND lands on the companion's target (PLND_ENABLED, PLND_TYPE 1: companion)."""
    return int(params["PLND_ENABLED"]) == 1 and int(params["PLND_TYPE"]) == 1


def _set(params: Parameters, name: str, value: float) -> None:
    """Set a parameter underneath, within its range."""
    spec = params.spec(name)
    value = min(max(float(value), spec.min), spec.max)
    with contextlib.suppress(ParamError):  # a value the cascade cannot take: it keeps its own
        params.set(name, round(value) if spec.type.integer else value)
