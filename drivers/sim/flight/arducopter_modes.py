"""ArduCopter's flight modes as the simulated vehicle offers them: what each needs and allows
(ArduCopter's ``mode.h``: ``requires_GPS``, ``allows_arming``, ``has_user_takeoff``; the
notes in ``docs/reference/ardupilot-mavlink.md`` §1.3), and how the simulator flies it.

Every mode of a quadrotor build is known and reported; the ones that need a pilot's sticks
(STABILIZE, ALT_HOLD, ACRO, POSHOLD, DRIFT, FLIP, AUTOTUNE, THROW, …) can be chosen on the
ground, as on ArduCopter, but not in the air: there is no RC in the simulation, and a
manual-throttle mode without a pilot falls (ArduCopter would let it). Modes ArduCopter's
quadrotor SITL does not build (SPORT, AUTOROTATE, TURTLE) answer "No such mode".
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from drivers.mavlink.ardupilot import CopterMode


class Flown(enum.Enum):
    """How the simulator flies a mode (on the PX4-like cascade underneath)."""

    PILOT = "pilot"        # needs sticks: chosen on the ground only
    GUIDED = "guided"      # the companion's targets (OFFBOARD underneath, ArduPilot's rules)
    HOLD = "hold"          # LOITER, BRAKE: hold position
    AUTO = "auto"          # the mission (items from seq 1; seq 0 is home)
    RTL = "rtl"
    LAND = "land"
    CIRCLE = "circle"      # orbit a centre CIRCLE_RADIUS ahead
    SMART_RTL = "smart_rtl"  # back along the path flown (:mod:`.ac_smartrtl`)
    UNSUPPORTED = "unsupported"  # known, not modelled by the simulator: refused


@dataclass(frozen=True, slots=True)
class ModeSpec:
    #: as ArduCopter names it (HEARTBEAT custom_mode → ``name()``)
    name: str
    flown: Flown
    requires_gps: bool
    #: arming allowed from a ground station in this mode (AUTO: with AUTO_OPTIONS bit 0)
    gcs_arm: bool
    #: NAV_TAKEOFF accepted in this mode
    user_takeoff: bool


_M = ModeSpec
MODES: dict[CopterMode, ModeSpec] = {
    CopterMode.STABILIZE: _M("STABILIZE", Flown.PILOT, False, True, False),
    CopterMode.ACRO: _M("ACRO", Flown.PILOT, False, True, False),
    CopterMode.ALT_HOLD: _M("ALT_HOLD", Flown.PILOT, False, True, False),
    CopterMode.AUTO: _M("AUTO", Flown.AUTO, True, False, False),
    CopterMode.GUIDED: _M("GUIDED", Flown.GUIDED, True, True, True),
    CopterMode.LOITER: _M("LOITER", Flown.HOLD, True, True, True),
    CopterMode.RTL: _M("RTL", Flown.RTL, True, False, False),
    CopterMode.CIRCLE: _M("CIRCLE", Flown.CIRCLE, True, False, False),
    CopterMode.LAND: _M("LAND", Flown.LAND, False, False, False),
    CopterMode.DRIFT: _M("DRIFT", Flown.PILOT, True, True, False),
    CopterMode.FLIP: _M("FLIP", Flown.PILOT, False, False, False),
    CopterMode.AUTOTUNE: _M("AUTOTUNE", Flown.PILOT, False, False, False),
    CopterMode.POSHOLD: _M("POSHOLD", Flown.PILOT, True, True, True),
    CopterMode.BRAKE: _M("BRAKE", Flown.HOLD, True, False, False),
    CopterMode.THROW: _M("THROW", Flown.PILOT, True, True, False),
    CopterMode.AVOID_ADSB: _M("AVOID_ADSB", Flown.UNSUPPORTED, True, False, False),
    CopterMode.GUIDED_NOGPS: _M("GUIDED_NOGPS", Flown.UNSUPPORTED, False, True, True),
    CopterMode.SMART_RTL: _M("SMARTRTL", Flown.SMART_RTL, True, False, False),
}
#: the numbers of modes outside :class:`CopterMode` that a quad build has (FLOWHOLD needs
#: optical flow, FOLLOW a lead vehicle, ZIGZAG and SYSTEMID a pilot): known by name, refused
OTHER_MODES = {22: "FLOWHOLD", 23: "FOLLOW", 24: "ZIGZAG", 25: "SYSTEMID"}


def mode_name(number: int) -> str:
    """ArduCopter's name for mode ``number`` (``Mode(N)`` for one it does not have)."""
    try:
        return MODES[CopterMode(number)].name
    except (ValueError, KeyError):
        return OTHER_MODES.get(number, f"Mode({number})")
