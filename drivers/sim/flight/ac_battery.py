"""ArduPilot's battery monitor and failsafe (``AP_BattMonitor``, ``AP_BattMonitor_Backend``,
ArduCopter's ``events.cpp``) for the simulated ArduCopter (:mod:`drivers.sim.flight.arducopter`).

* The monitor measures the pack's voltage and current (BATT_MONITOR 4: analog voltage and
  current) and integrates the consumed mAh; remaining = BATT_CAPACITY less consumed.
* Low: the voltage under BATT_LOW_VOLT for longer than BATT_LOW_TIMER (10 s), or fewer than
  BATT_LOW_MAH left; critical: under BATT_CRT_VOLT for that long, or fewer than BATT_CRT_MAH
  left (a threshold of 0 is off; ArduCopter's defaults: low 10.5 V, the others off). With
  BATT_FS_VOLTSRC 1 the voltage is the sag-compensated resting voltage (the measured voltage
  plus current × the pack's resistance, which the monitor estimates; here: the pack's own).
* Checked while armed; a level is acted on once, when first reached ("Battery 1 is low 14.02V
  used 3915 mAh"), with BATT_FS_LOW_ACT or BATT_FS_CRT_ACT: 0 none, 1 land, 2 RTL, 3 SmartRTL
  or RTL, 4 SmartRTL or land, 5 terminate, 6 the mission's DO_LAND_START or RTL (RTL here:
  no DO_LAND_START), 7 brake or land. On the ground it disarms instead ("Battery Failsafe -
  Disarming"); while landing with FS_OPTIONS bit 3 the landing goes on ("Battery Failsafe -
  Continuing Landing"); else "Battery Failsafe".
* Arming is refused while a level is reached, or with the thresholds inverted ("PreArm:
  Battery 1 low voltage failsafe", "… voltage failsafe critical > low").
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass

from drivers.base import Battery
from drivers.sim.flight.params import Parameters

#: FS_OPTIONS bit: a battery failsafe lets a landing go on
CONTINUE_IF_LANDING = 1 << 3


class Level(enum.IntEnum):
    NONE = 0
    LOW = 1
    CRITICAL = 2


class Action(enum.IntEnum):
    """BATT_FS_LOW_ACT / BATT_FS_CRT_ACT (ArduCopter's FailsafeAction)."""

    NONE = 0
    LAND = 1
    RTL = 2
    SMARTRTL = 3
    SMARTRTL_LAND = 4
    TERMINATE = 5
    AUTO_DO_LAND_START = 6
    BRAKE_LAND = 7


@dataclass(frozen=True, slots=True)
class BatteryFailsafe:
    """A level first reached in flight: what ArduCopter does about it."""

    level: Level
    action: Action
    #: on the ground: disarm instead of the action
    disarm: bool
    #: ArduCopter's announcement
    text: str


class AcBatteryMonitor:
    """Battery 1, as ArduCopter's monitor sees it. ``say`` takes ArduPilot's texts."""

    def __init__(self, params: Parameters, say: Callable[[str], None],
                 internal_resistance_ohm: float = 0.0) -> None:
        self._params = params
        self._say = say
        self._resistance_ohm = internal_resistance_ohm
        self.consumed_mah = 0.0
        self.voltage_v = 0.0
        self.current_a = 0.0
        self.level = Level.NONE  # the level acted on (it never goes back down in a flight)
        self._low_since: float | None = None
        self._critical_since: float | None = None

    def update(self, now_s: float, dt_s: float, battery: Battery, armed: bool, landed: bool,
               landing: bool) -> BatteryFailsafe | None:
        """One monitor sample; the failsafe to act on when a level is first reached."""
        self.voltage_v, self.current_a = battery.voltage_v, battery.current_a
        self.consumed_mah += max(battery.current_a, 0.0) * dt_s / 3.6
        reached = self._reached(now_s)
        if not armed or reached <= self.level:
            return None
        self.level = reached
        word = "low" if reached is Level.LOW else "critical"
        self._say(f"Battery 1 is {word} {self.voltage_v:.2f}V used {self.consumed_mah:.0f} mAh")
        p = self._params
        action = _action(p["BATT_FS_LOW_ACT" if reached is Level.LOW else "BATT_FS_CRT_ACT"])
        if landed:
            return BatteryFailsafe(reached, Action.NONE, True, "Battery Failsafe - Disarming")
        if landing and action is not Action.NONE and int(p["FS_OPTIONS"]) & CONTINUE_IF_LANDING:
            return BatteryFailsafe(reached, Action.LAND, False,
                                   "Battery Failsafe - Continuing Landing")
        return BatteryFailsafe(reached, action, False, "Battery Failsafe")

    def disarmed(self) -> None:
        """A new flight acts on each level again (ArduPilot keeps the failsafe until a reboot
        or a new pack; disarmed on the ground, the simulator counts a flight as a pack)."""
        self.level = Level.NONE

    # --- the checks -------------------------------------------------------------------

    def _voltage_used(self) -> float:
        if int(self._params["BATT_FS_VOLTSRC"]) == 1:
            return self.voltage_v + self.current_a * self._resistance_ohm
        return self.voltage_v

    def _below(self) -> tuple[bool, bool, bool, bool]:
        """(low voltage, low capacity, critical voltage, critical capacity) now."""
        p, v = self._params, self._voltage_used()
        left = p["BATT_CAPACITY"] - self.consumed_mah
        return (v > 0 and p["BATT_LOW_VOLT"] > 0 and v < p["BATT_LOW_VOLT"],
                p["BATT_LOW_MAH"] > 0 and left < p["BATT_LOW_MAH"],
                v > 0 and p["BATT_CRT_VOLT"] > 0 and v < p["BATT_CRT_VOLT"],
                p["BATT_CRT_MAH"] > 0 and left < p["BATT_CRT_MAH"])

    def _reached(self, now_s: float) -> Level:
        low_v, low_c, crit_v, crit_c = self._below()
        timer_s = float(self._params["BATT_LOW_TIMER"])
        self._critical_since = (self._critical_since if self._critical_since is not None
                                else now_s) if crit_v else None
        self._low_since = (self._low_since if self._low_since is not None
                           else now_s) if low_v else None
        if (crit_v and timer_s > 0 and now_s - self._critical_since > timer_s) or crit_c:
            return Level.CRITICAL
        if (low_v and timer_s > 0 and now_s - self._low_since > timer_s) or low_c:
            return Level.LOW
        return Level.NONE

    def arming_problem(self) -> str | None:
        """Why ArduCopter's battery pre-arm check fails (None: it passes)."""
        p = self._params
        low_v, low_c, crit_v, crit_c = self._below()
        for failed, what in (
                (low_v, "low voltage failsafe"), (low_c, "low capacity failsafe"),
                (crit_v, "critical voltage failsafe"), (crit_c, "critical capacity failsafe"),
                (p["BATT_CRT_MAH"] > 0 and p["BATT_LOW_MAH"] > 0 and
                 p["BATT_LOW_MAH"] < p["BATT_CRT_MAH"], "capacity failsafe critical > low"),
                (p["BATT_CRT_VOLT"] > 0 and p["BATT_LOW_VOLT"] > 0 and
                 p["BATT_LOW_VOLT"] < p["BATT_CRT_VOLT"], "voltage failsafe critical > low")):
            if failed:
                return f"Battery 1 {what}"
        return None

    @property
    def remaining_fraction(self) -> float:
        capacity = float(self._params["BATT_CAPACITY"])
        return max(0.0, 1.0 - self.consumed_mah / capacity) if capacity > 0 else 1.0


def _action(value: float) -> Action:
    try:
        return Action(int(value))
    except ValueError:
        return Action.NONE
