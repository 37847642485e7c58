"""ArduPilot Copter's modes as our :class:`~drivers.base.FlightMode` and back.

ArduPilot reports its mode number in HEARTBEAT ``custom_mode`` and takes it in DO_SET_MODE
param2 (param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED). Offboard control is GUIDED: setpoints
(SET_POSITION_TARGET_LOCAL_NED) are flown in GUIDED, which is also where a takeoff command is
accepted. Position hold is BRAKE (stop now) or LOITER (hold, pilot may nudge).
"""

from __future__ import annotations

import enum

from drivers.base import FlightMode


class CopterMode(enum.IntEnum):
    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    AVOID_ADSB = 19
    GUIDED_NOGPS = 20
    SMART_RTL = 21


_TO_FLIGHT_MODE = {
    CopterMode.STABILIZE: FlightMode.MANUAL,
    CopterMode.ACRO: FlightMode.MANUAL,
    CopterMode.ALT_HOLD: FlightMode.ALTCTL,
    CopterMode.POSHOLD: FlightMode.POSCTL,
    CopterMode.AUTO: FlightMode.MISSION,
    CopterMode.GUIDED: FlightMode.OFFBOARD,
    CopterMode.LOITER: FlightMode.HOLD,
    CopterMode.BRAKE: FlightMode.HOLD,
    CopterMode.RTL: FlightMode.RETURN,
    CopterMode.SMART_RTL: FlightMode.RETURN,
    CopterMode.LAND: FlightMode.LAND,
}


#: the modes ArduCopter arms in when a ground station asks (each mode's allows_arming() in
#: ArduCopter/mode.h; AUTO only with AUTO_OPTIONS bit 0, not assumed)
GCS_ARMABLE = frozenset({CopterMode.STABILIZE, CopterMode.ACRO, CopterMode.ALT_HOLD,
                         CopterMode.GUIDED, CopterMode.LOITER, CopterMode.DRIFT,
                         CopterMode.SPORT, CopterMode.POSHOLD, CopterMode.THROW,
                         CopterMode.GUIDED_NOGPS})


def gcs_armable(custom_mode: int) -> bool:
    return custom_mode in GCS_ARMABLE


def flight_mode(custom_mode: int) -> FlightMode:
    """Our FlightMode for an ArduPilot Copter mode number (UNKNOWN for the others)."""
    try:
        return _TO_FLIGHT_MODE.get(CopterMode(custom_mode), FlightMode.UNKNOWN)
    except ValueError:
        return FlightMode.UNKNOWN


def copter_mode(mode: FlightMode, hold: CopterMode = CopterMode.BRAKE) -> CopterMode:
    """The Copter mode that does what ``mode`` asks: OFFBOARD and TAKEOFF are GUIDED, HOLD is
    ``hold`` (BRAKE or LOITER)."""
    if mode is FlightMode.HOLD:
        if hold not in (CopterMode.BRAKE, CopterMode.LOITER):
            raise ValueError(f"hold mode must be BRAKE or LOITER, not {hold.name}")
        return hold
    table = {FlightMode.OFFBOARD: CopterMode.GUIDED, FlightMode.TAKEOFF: CopterMode.GUIDED,
             FlightMode.LAND: CopterMode.LAND, FlightMode.RETURN: CopterMode.RTL,
             FlightMode.MISSION: CopterMode.AUTO, FlightMode.POSCTL: CopterMode.POSHOLD,
             FlightMode.ALTCTL: CopterMode.ALT_HOLD, FlightMode.MANUAL: CopterMode.STABILIZE}
    if mode not in table:
        raise ValueError(f"no ArduPilot Copter mode for {mode.name}")
    return table[mode]


#: EKF_STATUS_REPORT's flags (ArduPilot's EKF_STATUS_FLAGS), by name
EKF_FLAGS = {"attitude": 1, "horizontal velocity": 2, "vertical velocity": 4,
             "horizontal position (relative)": 8, "horizontal position (absolute)": 16,
             "vertical position (absolute)": 32, "vertical position (above ground)": 64,
             "constant position mode": 128, "predicted horizontal position (relative)": 256,
             "predicted horizontal position (absolute)": 512, "uninitialized": 1024,
             "GPS glitch": 32768}
#: what GUIDED flight on position needs of the EKF (AP_AHRS's checks before GUIDED and AUTO)
_NEEDED = ("attitude", "horizontal velocity", "vertical velocity",
           "horizontal position (absolute)", "vertical position (absolute)")


def ekf_judgement(flags: int) -> tuple[str, str]:
    """(PASS / WARN / FAIL, what the flags mean for a companion that flies on position)."""
    missing = [name for name in _NEEDED if not flags & EKF_FLAGS[name]]
    bad = [name for name in ("constant position mode", "uninitialized", "GPS glitch")
           if flags & EKF_FLAGS[name]]
    if flags & EKF_FLAGS["uninitialized"] or missing:
        return ("FAIL", f"EKF flags 0x{flags:04x}: no " + ", ".join(missing or ["estimate"])
                + (f"; {', '.join(bad)}" if bad else "") + " (GUIDED needs a position)")
    if bad:
        return ("WARN", f"EKF flags 0x{flags:04x}: {', '.join(bad)}")
    return ("PASS", f"EKF flags 0x{flags:04x}: attitude, velocity and absolute position good")
