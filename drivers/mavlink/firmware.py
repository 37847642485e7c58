"""What differs between the flight stacks a MAVLink driver meets, one profile per firmware,
chosen from the vehicle's HEARTBEAT ``autopilot`` and registered in :data:`FIRMWARE_PROFILES`
(here and nowhere else): how its modes are read and asked for, how it takes off, lands and
lands on a target, which frame its LANDING_TARGET takes, the force magic numbers of
COMPONENT_ARM_DISARM, and which attitude message it sends.

* **PX4** (``MAV_AUTOPILOT_PX4``; also any autopilot without a profile of its own): custom
  modes as (main, sub) pairs with the armed flag in base mode; takeoff to MIS_TAKEOFF_ALT with
  NAV_TAKEOFF; NAV_LAND; the PRECLAND mode; LANDING_TARGET in LOCAL_NED; 21196 forces both ways;
  ATTITUDE_QUATERNION.
* **ArduCopter** (``MAV_AUTOPILOT_ARDUPILOTMEGA``): Copter mode numbers (DO_SET_MODE param1 = the
  custom-mode flag, param2 = the number); offboard is GUIDED and hold BRAKE or LOITER; takeoff
  is GUIDED then NAV_TAKEOFF with the altitude above home in param7; landing is the LAND mode,
  which with PLND_ENABLED and PLND_TYPE 1 lands on the target (a precision landing is refused
  otherwise, naming them); LANDING_TARGET only in BODY_FRD or LOCAL_FRD, the
  target as a position relative to the vehicle (``position_valid``, its distance > 0); 2989
  forces an arming, 21196 a disarm; ATTITUDE (Euler angles). (ArduPilot's GCS_Common.cpp,
  mode.cpp, AC_PrecLand: ``docs/reference/ardupilot-mavlink.md``.)
"""

from __future__ import annotations

import math
import struct
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from drivers.base import CommandDenied, FlightMode, LandingTarget, VehicleError, VehicleState
from drivers.mavlink import ardupilot, px4

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_NAV_LAND = 21
MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20
#: MAV_PARAM_TYPE values carried as integers
_INT_TYPES = frozenset({1, 2, 3, 4, 5, 6})  # UINT8 … INT32


@dataclass(frozen=True, slots=True)
class ParamCheck:
    """A parameter a companion computer depends on: ``judge(value)`` gives (status, what it
    means) with status PASS, WARN or FAIL."""

    name: str
    judge: Callable[[float], tuple[str, str]]

#: (name, MAV_CMD, *params) → the command sent and its answer awaited
Command = Callable[..., Awaitable[None]]
SetMode = Callable[[FlightMode], Awaitable[None]]
SetParam = Callable[[str, float], Awaitable[object]]
#: a parameter's value as the vehicle reports it (KeyError: it did not answer)
GetParam = Callable[[str], Awaitable[float]]
#: ArduPilot's PLND_TYPE for a target a companion computer reports (LANDING_TARGET)
PLND_TYPE_COMPANION = 1


@dataclass(frozen=True, slots=True)
class TargetReport:
    """LANDING_TARGET's frame and fields as a firmware takes them."""

    frame: int
    position_m: tuple[float, float, float]
    distance_m: float


class Px4Profile:
    name = "px4"
    force_arm_magic = px4.FORCE_DISARM_MAGIC
    force_disarm_magic = px4.FORCE_DISARM_MAGIC
    #: it sends ATTITUDE_QUATERNION (ATTITUDE is derived from it: ignored)
    attitude_from_euler = False

    title = "PX4"
    #: the firmware's own messages the drivers ask for (id → Hz) beyond the common telemetry
    streams_hz: Mapping[int, float] = MappingProxyType({})

    def flight_mode(self, custom_mode: int) -> FlightMode:
        return px4.px4_flight_mode(custom_mode)

    def param_value(self, raw: float, param_type: int) -> float:
        """A PARAM_VALUE's value: PX4 sends integer parameters bytewise (the int's bits)."""
        if param_type in _INT_TYPES:
            return float(struct.unpack("<i", struct.pack("<f", raw))[0])
        return float(raw)

    def companion_params(self) -> tuple[ParamCheck, ...]:
        """What ``autopilot doctor`` reads: how the vehicle reacts when the companion's
        setpoints or the ground station stop."""
        return (
            ParamCheck("COM_OF_LOSS_T", lambda v: (
                ("PASS" if v <= 1.0 else "WARN"),
                f"offboard setpoints lost for {v:g} s: the failsafe acts (the autopilot streams "
                "at 20 Hz or more; ≤ 1 s keeps a stopped companion's vehicle short)")),
            ParamCheck("NAV_DLL_ACT", lambda v: (
                "PASS", "data-link loss: " + {0: "no action (the ground station may go)",
                                              1: "hold", 2: "return", 3: "land"}.get(
                    int(v), f"action {int(v)}"))),
        )

    def arming_mode(self, custom_mode: int | None) -> FlightMode | None:
        """The mode to enter before arming from the HEARTBEAT's ``custom_mode`` (None: arm as
        it is; PX4 arms in any mode a ground station may ask)."""
        return None

    def estimator_check(self, ekf_flags: int | None) -> tuple[str, str] | None:
        """``autopilot doctor``'s judgement of the estimator's own report (PX4's health bits
        are read with the rest of SYS_STATUS: None)."""
        return None

    def mode_params(self, mode: FlightMode, armed: bool) -> tuple[float, ...]:
        """DO_SET_MODE's params for ``mode``."""
        main, sub = px4.PX4_MODES[mode]
        base = px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (px4.MAV_MODE_FLAG_SAFETY_ARMED
                                                        if armed else 0)
        return (base, main, sub)

    async def takeoff(self, command: Command, set_mode: SetMode, set_param: SetParam,
                      altitude_m: float | None) -> None:
        if altitude_m is not None:
            await set_param("MIS_TAKEOFF_ALT", altitude_m)
        await command("takeoff", MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)

    async def land(self, command: Command, set_mode: SetMode) -> None:
        await command("land", MAV_CMD_NAV_LAND, *[math.nan] * 7)

    async def precision_landing_problem(self, get_param: GetParam) -> str | None:
        """What in the vehicle's parameters keeps its precision landing from landing on the
        companion's target, None if nothing does. (PX4's AUTO.PRECLAND always takes
        LANDING_TARGET: its PLD_* parameters only shape the search and the fallback.)"""
        return None

    async def precision_land(self, command: Command, set_mode: SetMode,
                             get_param: GetParam) -> None:
        await set_mode(FlightMode.PRECLAND)

    def landing_target(self, target: LandingTarget,
                       state: VehicleState | None) -> TargetReport | None:
        p = tuple(float(v) for v in target.position_ned_m)
        return TargetReport(px4.MAV_FRAME_LOCAL_NED, p, 0.0)


class ArduCopterProfile(Px4Profile):
    name = "ardupilot"
    force_arm_magic = 2989
    force_disarm_magic = 21196
    attitude_from_euler = True
    #: NAV_TAKEOFF's altitude when none is asked (MAVSDK's default)
    default_takeoff_m = 2.5

    def __init__(self, hold: ardupilot.CopterMode = ardupilot.CopterMode.BRAKE) -> None:
        self.hold = hold
        ardupilot.copter_mode(FlightMode.HOLD, hold)  # (BRAKE or LOITER, else ValueError)

    title = "ArduPilot"
    #: EKF_STATUS_REPORT, for ``autopilot doctor``'s estimator check
    streams_hz = MappingProxyType({193: 1.0})

    def flight_mode(self, custom_mode: int) -> FlightMode:
        return ardupilot.flight_mode(custom_mode)

    def param_value(self, raw: float, param_type: int) -> float:
        return float(raw)  # ArduPilot casts every parameter to float

    def companion_params(self) -> tuple[ParamCheck, ...]:
        return (
            ParamCheck("GUID_TIMEOUT", lambda v: (
                "PASS" if v <= 3.0 else "WARN",
                f"GUIDED velocity targets kept {v:g} s without news, then the vehicle stops "
                "(the autopilot streams at 20 Hz or more)")),
            ParamCheck("FS_GCS_ENABLE", lambda v: (
                "PASS" if int(v) != 0 else "WARN",
                "ground station loss: " + {0: "no action — a lost companion leaves the vehicle "
                                              "in GUIDED until GUID_TIMEOUT stops it; consider 1 "
                                              "(RTL) or 5 (Land)", 1: "RTL",
                                           3: "SmartRTL or RTL", 4: "SmartRTL or Land",
                                           5: "Land", 6: "Auto DO_LAND_START or RTL",
                                           7: "Brake or Land"}.get(int(v), f"action {int(v)}"))),
            ParamCheck("FS_GCS_TIMEOUT", lambda v: (
                "PASS" if v <= 5.0 else "WARN", f"counts as lost after {v:g} s of silence")),
            *(ParamCheck(f"SERIAL{n}_PROTOCOL", lambda v, n=n: _serial_protocol(n, v))
              for n in (1, 2)),
            ParamCheck("SYSID_MYGCS", lambda v: (
                "PASS", f"the failsafe listens to system {int(v)}'s heartbeats (the autopilot "
                "sends its own; a companion meant to count must use this id)")),
        )

    def arming_mode(self, custom_mode: int | None) -> FlightMode | None:
        """GUIDED when the vehicle sits in a mode ArduCopter refuses to arm in (LAND, RTL, BRAKE
        … after a landing: "Arm: LAND mode not armable"), else None. (MAVSDK's action asks for
        BRAKE there, which ArduCopter refuses too.)"""
        if custom_mode is None or ardupilot.gcs_armable(custom_mode):
            return None
        return FlightMode.OFFBOARD

    def estimator_check(self, ekf_flags: int | None) -> tuple[str, str] | None:
        """EKF_STATUS_REPORT's flags, as a companion flying on position needs them."""
        if ekf_flags is None:
            return ("WARN", "no EKF_STATUS_REPORT heard (its stream asked for at 1 Hz)")
        return ardupilot.ekf_judgement(ekf_flags)

    def mode_params(self, mode: FlightMode, armed: bool) -> tuple[float, ...]:
        return (px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(ardupilot.copter_mode(mode, self.hold)))

    async def takeoff(self, command: Command, set_mode: SetMode, set_param: SetParam,
                      altitude_m: float | None) -> None:
        await set_mode(FlightMode.TAKEOFF)  # GUIDED
        alt = self.default_takeoff_m if altitude_m is None else altitude_m
        await command("takeoff", MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, alt)

    async def land(self, command: Command, set_mode: SetMode) -> None:
        await set_mode(FlightMode.LAND)

    async def precision_landing_problem(self, get_param: GetParam) -> str | None:
        """ArduCopter has no precision landing mode: its LAND lands on the target only with
        PLND_ENABLED set (1; 2 in older firmware: strict) and PLND_TYPE 1, companion computer;
        otherwise LAND lands where the vehicle is. Both as the vehicle reports them (one it does
        not answer for is a problem too: a firmware built without AC_PrecLand has none)."""
        values = {}
        for name in ("PLND_ENABLED", "PLND_TYPE"):
            try:
                values[name] = int(await get_param(name))
            except (KeyError, OSError, VehicleError) as exc:
                return (f"{name} not read ({exc}): the vehicle may have no precision landing "
                        "(ArduCopter built without AC_PrecLand)")
        fix = ("set PLND_ENABLED 1 and PLND_TYPE 1 (companion computer) and reboot the "
               "vehicle, or land with method: ours")
        if values["PLND_ENABLED"] == 0:
            return ("PLND_ENABLED is 0: ArduCopter's LAND would land where the vehicle is, not "
                    f"on the target ({fix})")
        if values["PLND_TYPE"] != PLND_TYPE_COMPANION:
            return (f"PLND_TYPE is {values['PLND_TYPE']}, not 1 (companion computer): "
                    f"ArduCopter would ignore the LANDING_TARGET the autopilot sends ({fix})")
        return None

    async def precision_land(self, command: Command, set_mode: SetMode,
                             get_param: GetParam) -> None:
        """LAND, once the parameters say it will land on the target (else CommandDenied
        naming them: the step goes to its fallback rather than landing anywhere)."""
        problem = await self.precision_landing_problem(get_param)
        if problem is not None:
            raise CommandDenied("precision land", problem)
        await set_mode(FlightMode.LAND)

    def landing_target(self, target: LandingTarget,
                       state: VehicleState | None) -> TargetReport | None:
        """The target relative to the vehicle in LOCAL_FRD (forward and right along its
        heading, down): ArduPilot takes no world frame here. None before any telemetry."""
        if state is None:
            return None
        rel = np.asarray(target.position_ned_m, float) - np.asarray(state.position_ned_m, float)
        c, s = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
        frd = (c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], float(rel[2]))
        distance = float(np.linalg.norm(frd))
        return TargetReport(MAV_FRAME_LOCAL_FRD, frd, distance) if distance > 0 else None


def _serial_protocol(port: int, value: float) -> tuple[str, str]:
    """A telemetry port's SERIALn_PROTOCOL, for a companion that may be wired to it (TELEM1 is
    SERIAL1, TELEM2 SERIAL2). Its SRn rates do not matter: the drivers ask for their own
    streams."""
    v = int(value)
    if v == 2:
        return ("PASS", f"MAVLink 2 on SERIAL{port} (TELEM{port}): a companion may use it")
    if v == 1:
        return ("WARN", f"MAVLink 1 on SERIAL{port}: no signing, and messages beyond MAVLink 1 "
                "(e.g. LANDING_TARGET's position) are lost; set 2 for a companion")
    return ("WARN", f"SERIAL{port} is protocol {v}, not MAVLink: the companion is on another "
            "port, or set 2")


#: HEARTBEAT autopilot → its profile (the hold mode is ArduCopter's choice of BRAKE or LOITER)
FIRMWARE_PROFILES: dict[int, Callable[[ardupilot.CopterMode], Px4Profile]] = {
    px4.MAV_AUTOPILOT_PX4: lambda hold: Px4Profile(),
    MAV_AUTOPILOT_ARDUPILOTMEGA: ArduCopterProfile,
}


def firmware_profile(autopilot: int | None,
                     hold: ardupilot.CopterMode = ardupilot.CopterMode.BRAKE) -> Px4Profile:
    """The profile of a vehicle whose HEARTBEAT says ``autopilot`` (PX4's when it has none)."""
    make = FIRMWARE_PROFILES.get(autopilot, FIRMWARE_PROFILES[px4.MAV_AUTOPILOT_PX4])
    return make(hold)
