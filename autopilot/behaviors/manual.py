"""Flying by keyboard from the console (seed 000's keys), as plain synchronous classes.

:class:`HeldKeys` is what the console's socket says is held. A key counts as held only while
the browser keeps renewing it (it re-sends the held keys several times a second): key up,
a lost focus, a closed tab or a dropped socket all end in the keys expiring within
``key_timeout_s``, on the wall clock (a person's keys, whatever the simulated clock does).

:class:`ManualFlight` turns the held keys into the runtime's setpoint intent, like any
behaviour's: W/S forward and back, A/D left and right, Q/E yaw, ``]``/``[`` up and down, all
in the body frame at fixed speeds. With no key held it brakes (zero velocity) and, once nearly
still, holds the position it stopped at, as PX4's Position mode does; it never descends below
``min_altitude_m`` (landing is the L key's job) and never climbs above ``max_altitude_m``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from drivers.base import Setpoint, VehicleState

AXES = ("forward", "back", "left", "right", "yaw_left", "yaw_right", "up", "down")
ACTIONS = ("takeoff", "land", "emergency", "autopilot", "follow_mode")


@dataclass(frozen=True, slots=True)
class ManualSettings:
    speed_m_s: float = 1.5
    vertical_speed_m_s: float = 0.8
    yaw_rate_rad_s: float = math.radians(45.0)
    key_timeout_s: float = 0.5  # wall clock: a key not renewed for this long is released
    min_altitude_m: float = 0.8
    max_altitude_m: float = 30.0  # ] stops here (a key stuck down climbs no further)
    hold_below_m_s: float = 0.25  # braking: below this speed the position is held
    takeoff_altitude_m: float = 3.0


class HeldKeys:
    """The movement keys held, each until ``timeout_s`` after it was last reported, per
    source (one page's socket): a key is held while any source holds it, and one page
    letting go does not release what another holds."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self._until: dict[object, dict[str, float]] = {}

    def report(self, axes: Iterable[str], now_s: float, source: object = None) -> None:
        """The keys ``source`` holds now (all of them: any not named is released)."""
        held = {a: now_s + self.timeout_s for a in axes if a in AXES}
        if held:
            self._until[source] = held
        else:
            self._until.pop(source, None)

    def release(self, source: object = None) -> None:
        self._until.pop(source, None)

    def release_all(self) -> None:
        self._until.clear()

    def held(self, now_s: float) -> frozenset[str]:
        return frozenset(a for keys in self._until.values()
                         for a, until in keys.items() if now_s < until)


class ManualFlight:
    """Held keys → a setpoint for the vehicle (see the module's docstring)."""

    def __init__(self, settings: ManualSettings) -> None:
        self.settings = settings
        self._hold_ned: np.ndarray | None = None
        self._hold_yaw = math.nan

    def reset(self) -> None:
        """Forget the hold point (when manual flight starts again)."""
        self._hold_ned = None

    def setpoint(self, held: frozenset[str], state: VehicleState, now_s: float) -> Setpoint:
        s = self.settings

        def axis(plus: str, minus: str) -> float:
            return float(plus in held) - float(minus in held)

        forward = s.speed_m_s * axis("forward", "back")
        right = s.speed_m_s * axis("right", "left")
        down = -s.vertical_speed_m_s * axis("up", "down")
        yaw_rate = s.yaw_rate_rad_s * axis("yaw_right", "yaw_left")
        if (down > 0 and state.altitude_m <= s.min_altitude_m) or \
                (down < 0 and state.altitude_m >= s.max_altitude_m):
            down = 0.0
        if forward or right or down or yaw_rate:
            self._hold_ned = None
            return Setpoint.velocity_body(forward, right, down, yaw_rate_rad_s=yaw_rate,
                                          time_s=now_s)
        if self._hold_ned is None:
            speed = float(np.linalg.norm(state.velocity_ned_m_s))
            if speed > s.hold_below_m_s:  # brake first, then hold where it stopped
                return Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rate_rad_s=0.0, time_s=now_s)
            self._hold_ned = np.array(state.position_ned_m, dtype=float)
            self._hold_ned[2] = min(self._hold_ned[2], -s.min_altitude_m)
            self._hold_yaw = state.yaw_rad
        return Setpoint.position(*self._hold_ned, yaw_rad=self._hold_yaw, time_s=now_s)
