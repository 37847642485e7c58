"""How a simulated flight ended, judged on the simulator's ground truth (scoring only: the
autopilot never sees it): did the vehicle crash, fly away or leave its fence, and in what state
was it left — the figures ``autopilot bench faults`` sorts runs by.

* **crash**: the airframe tilted beyond :data:`CRASH_TILT_DEG`, or met the ground (or a deck)
  faster than :data:`CRASH_SPEED_M_S` downwards within :data:`NEAR_GROUND_M` of it;
* **flyaway**: farther than ``flyaway_m`` horizontally from where it started;
* **fence breach**: outside the configured ``failsafe.geofence`` (the truth, not the estimate)
  by more than :data:`FENCE_MARGIN_M`;
* **ended safe**: at the end of the log disarmed, on the ground (the flight stack's land detector:
  on a raised deck or pad too), or in the air in a mode the
  vehicle flies by itself to a safe end (hold, land, return, precision landing) — as the
  simulated flight stack had it, not as the last telemetry said.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.flightlog import records as ch
from autopilot.flightlog.truth import truth_table

CRASH_TILT_DEG = 70.0
CRASH_SPEED_M_S = 3.0
NEAR_GROUND_M = 0.8
FENCE_MARGIN_M = 2.0
FLYAWAY_M = 150.0
SAFE_MODES_IN_AIR = ("hold", "land", "return", "precland")


def safety_metrics(records: Mapping[str, Sequence[Mapping]], fence=None,
                   flyaway_m: float = FLYAWAY_M) -> dict:
    """The ``safety`` metric group (empty without ground truth)."""
    table = truth_table(records)
    have = table.has_vehicle
    if not have.any():
        return {}
    pos, vel, q = table.p[have], table.v[have], table.q[have]
    home = pos[0]
    horizontal = np.linalg.norm(pos[:, :2] - home[:2], axis=1)
    height = home[2] - pos[:, 2]
    # the body z axis's vertical component: 1 - 2(x² + y²) for a (w, x, y, z) quaternion
    cos_tilt = np.clip(1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1.0, 1.0)
    tilt_deg = np.degrees(np.arccos(cos_tilt))
    near = height < NEAR_GROUND_M
    impact = float(np.max(vel[near, 2])) if near.any() else 0.0
    crashed = bool(tilt_deg.max() > CRASH_TILT_DEG or impact > CRASH_SPEED_M_S)
    breached = _fence_breached(pos, home, fence)
    # the end state from the simulator's own flight stack where the log has it; else (older
    # logs) from the last telemetry, which a dropout or a lost link may have left behind
    end = table.last
    states = records.get(ch.VEHICLE_STATE, [])
    last = end if end.get("armed") is not None else (states[-1] if states else {})
    armed = bool(last.get("armed", False))
    # the land detector's verdict (on a raised deck or pad too), or within 0.3 m of the
    # ground it started from
    on_ground = last.get("landed_state") == "on_ground" or height[-1] < 0.3
    mode = str(last.get("mode") or "")
    ended_safe = (not armed) or on_ground or mode in SAFE_MODES_IN_AIR
    return {
        "crashed": crashed,
        "flyaway": bool(horizontal.max() > flyaway_m),
        "fence_breached": breached,
        "ended_safe": bool(ended_safe),
        "ended_disarmed": not armed,
        "max_tilt_deg": float(tilt_deg.max()),
        "max_impact_m_s": max(impact, 0.0),
        "max_distance_m": float(horizontal.max()),
        "max_height_m": float(height.max()),
    }


def _fence_breached(pos: np.ndarray, home: np.ndarray, fence) -> bool:
    if fence is None:
        return False
    if fence.max_distance_m and np.linalg.norm(pos[:, :2] - home[:2], axis=1).max() > \
            fence.max_distance_m + FENCE_MARGIN_M:
        return True
    if fence.max_altitude_m and (home[2] - pos[:, 2]).max() > \
            fence.max_altitude_m + FENCE_MARGIN_M:
        return True
    if fence.polygon_m:
        from shapely.geometry import Point, Polygon

        shape = Polygon(fence.polygon_m).buffer(FENCE_MARGIN_M)
        for n, e in pos[:: max(1, len(pos) // 2000), :2]:
            if not shape.contains(Point(float(n), float(e))):
                return True
    return False


def outcome(status: str, safety: Mapping) -> tuple[str, str]:
    """A run's outcome: ``completed``, ``safe`` or ``unsafe``, and why (unsafe or not
    completed). ``status`` is the summary's (``error``: the run raised)."""
    problems = [name for name in ("crashed", "flyaway", "fence_breached")
                if safety.get(f"safety.{name}", safety.get(name))]
    ended_safe = safety.get("safety.ended_safe", safety.get("ended_safe"))
    if status == "error":
        problems.append("error (traceback)")
    elif ended_safe is None:
        problems.append("no ground truth")
    elif not ended_safe:
        problems.append("left flying")
    if problems:
        return "unsafe", ", ".join(problems)
    if status == "completed":
        return "completed", ""
    return "safe", status
