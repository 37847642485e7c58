"""The battery reserve for the way home (an autopilot-side failsafe, before PX4's own).

Each tick it estimates what getting home and down would cost: the time to climb to the
vehicle's return altitude (``return_altitude_m`` − height, ÷ ``climb_m_s``: PX4's RTL climbs to
RTL_RETURN_ALT before it turns home), to fly home (horizontal distance ÷ ``speed_m_s``, the
vehicle's return speed) and to descend from there (PX4's landing: ``fast_descent_m_s``,
MPC_Z_V_AUTO_DN, down to ``slow_below_m``, MPC_LAND_ALT1, then ``descent_m_s``, MPC_LAND_SPEED:
its gradual slow-down between MPC_LAND_ALT1 and ALT2 counted at the slow speed), times the rate
the battery has been draining (its remaining fraction over the last ``window_s``), times
``margin``. When what is left after that falls to ``reserve_fraction``, the mission stops and
the vehicle goes home: its return to launch, or a landing where it is when it is already within
``home_radius_m`` of home. With ``land_here`` (``action: land``) it always lands where it is,
and the estimate is the descent alone.
A battery the vehicle reports as below ``reserve_fraction`` outright (a sag) triggers it too.
Plain class, no event loop: the runtime calls :meth:`check` on every tick.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class ReserveSettings:
    reserve_fraction: float  # 0: off
    speed_m_s: float
    descent_m_s: float
    margin: float
    window_s: float = 20.0
    home_radius_m: float = 3.0
    return_altitude_m: float = 0.0  # the vehicle's RTL_RETURN_ALT (0: returns at its height)
    climb_m_s: float = 3.0
    fast_descent_m_s: float = 0.0  # above slow_below_m (0: descent_m_s all the way)
    slow_below_m: float = 10.0
    land_here: bool = False  # action: land (no way home to pay for)

    def descent_s(self, height_m: float) -> float:
        """Seconds to land from ``height_m`` above home."""
        fast = max(height_m - self.slow_below_m, 0.0) if self.fast_descent_m_s > 0 else 0.0
        return fast / max(self.fast_descent_m_s, 1e-9) + (height_m - fast) / self.descent_m_s


@dataclass(frozen=True, slots=True)
class ReserveCall:
    """Time to go home: why, and whether home is far enough to fly there (else land)."""

    reason: str
    go_home: bool


class BatteryReserve:
    def __init__(self, settings: ReserveSettings) -> None:
        self.settings = settings
        self._history: deque[tuple[float, float]] = deque()
        self.needed_fraction = math.nan
        self.drain_per_s = math.nan

    @property
    def active(self) -> bool:
        return self.settings.reserve_fraction > 0.0

    def check(self, now_s: float, remaining: float, position_ned_m, home_ned_m,
              in_air: bool) -> ReserveCall | None:
        s = self.settings
        if not self.active or not in_air or remaining is None or not math.isfinite(remaining):
            return None
        self._history.append((now_s, remaining))
        while len(self._history) > 2 and now_s - self._history[0][0] > s.window_s:
            self._history.popleft()
        t0, r0 = self._history[0]
        self.drain_per_s = max((r0 - remaining) / (now_s - t0), 0.0) if now_s - t0 >= 2.0 \
            else math.nan
        home = np.zeros(3) if home_ned_m is None else np.asarray(home_ned_m, dtype=float)
        pos = np.asarray(position_ned_m, dtype=float)
        distance = float(np.linalg.norm(pos[:2] - home[:2]))
        height = max(float(home[2] - pos[2]), 0.0)
        go_home = distance > s.home_radius_m and not s.land_here
        if remaining <= s.reserve_fraction:
            return ReserveCall(f"battery {remaining:.0%} at or below the reserve "
                               f"{s.reserve_fraction:.0%}", go_home)
        if not math.isfinite(self.drain_per_s):
            return None
        climb = max(s.return_altitude_m - height, 0.0) if go_home else 0.0
        seconds = climb / s.climb_m_s + (distance / s.speed_m_s if go_home else 0.0) + \
            s.descent_s(height + climb)
        self.needed_fraction = s.margin * self.drain_per_s * seconds
        if remaining - self.needed_fraction <= s.reserve_fraction:
            return ReserveCall(
                f"battery {remaining:.0%}: "
                + (f"getting home ({distance:.0f} m, {height:.0f} m up" if go_home
                   else f"landing ({height:.0f} m up")
                + (f", {climb:.0f} m climb" if climb else "")
                + f", about {seconds:.0f} s) takes ~{self.needed_fraction:.0%}, leaving less "
                f"than the reserve {s.reserve_fraction:.0%}", go_home)
        return None
