"""The search for a target on the ground that a down-camera step has not seen yet (or has lost),
shared by those steps (land_pad, hover_image).

Climb (or descend) to ``altitude_m`` over where the search began, for a wider view; then fly an
expanding square out from there: rings ``radius_m / n`` apart (n the fewest rings no further
apart than ``spacing_m``), the outermost ring's half side ``radius_m`` (every corner within
``radius_m`` north and east of the start), each ring closed before the next; then wait over the
start. After ``timeout_s`` from the start of the search it has timed out: the step decides what
that means. The step ends the search when its target is seen; the search only flies.

The rings' spacing comes from what the camera sees: :func:`ring_spacing_m` puts a target
wholly in view on one ring or the next wherever it lies between them. Altitudes are above the
local origin (PX4's take-off point), as PX4's ``PLD_SRCH_ALT``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: a corner (or the search altitude) counts as reached within this
ARRIVE_M = 0.3
#: the setpoint leads the vehicle by this long at the search speed, towards the next corner:
#: the vehicle then flies at about its position gain × that lead (PX4's default MPC_XY_P 0.95:
#: about the search speed; the simulated vehicle's 1.8: about 3 m/s at 2 m/s, measured)
LEAD_S = 1.0
#: the rings are never closer than this, whatever the camera and the target
MIN_SPACING_M = 0.5


@dataclass(frozen=True, slots=True)
class SearchSettings:
    altitude_m: float  # above the local origin
    radius_m: float  # the outermost ring's half side; 0: climb and look only
    spacing_m: float  # rings at most this far apart (see ring_spacing_m)
    speed_m_s: float
    timeout_s: float


@dataclass(frozen=True, slots=True)
class SearchCommand:
    position_ned_m: tuple[float, float, float]  # the position setpoint
    stage: str  # "climbing", "sweeping" or "waiting" (over the start)
    timed_out: bool = False


def ring_spacing_m(footprint_per_m: float, altitude_m: float, target_size_m: float,
                   overlap: float = 0.8) -> float:
    """How far apart the rings may be: the width of ground the camera sees from ``altitude_m``
    (``footprint_per_m`` × altitude, see
    :func:`~autopilot.planning.footprint.footprint_width_per_m`) less the target's size — a
    target within half that of a ring's side is wholly in view from it — times ``overlap``
    (a margin for tilt and for the frames the detector needs)."""
    return max(overlap * (footprint_per_m * altitude_m - target_size_m), MIN_SPACING_M)


def expanding_square(centre_ne, spacing_m: float, radius_m: float) -> list[np.ndarray]:
    """Corners (north, east) of an expanding square out from ``centre_ne``: legs north, east,
    south, west of 1, 1, 2, 2, 3, 3, … ring spacings, the rings ``radius_m / n`` apart (n the
    fewest with a spacing ≤ ``spacing_m``), the last ring closed with two more legs; ending
    back at the centre. ``radius_m`` 0: the centre alone."""
    centre = np.asarray(centre_ne, dtype=float)
    if radius_m <= 0.0:
        return [centre]
    rings = max(1, math.ceil(radius_m / max(spacing_m, 1e-6) - 1e-9))
    step = radius_m / rings
    dirs = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
    legs = [(dirs[(j - 1) % 4], math.ceil(j / 2) * step) for j in range(1, 4 * rings + 1)]
    # the spiral reaches ring n on its south and west sides last: up the west side and back
    # along the north side to where ring n's north side began
    legs += [(dirs[0], 2 * rings * step), (dirs[1], step)]
    points, here = [centre], centre.copy()
    for (dn, de), length in legs:
        here = here + length * np.array([dn, de])
        points.append(here)
    points.append(centre)
    return points


class Search:
    """One search at a time: :meth:`start` it over a point, then :meth:`update` at every tick
    with the vehicle's position for the setpoint to fly."""

    def __init__(self, settings: SearchSettings) -> None:
        self.settings = settings
        self.stage = "climbing"
        self.started_s = 0.0
        self.waypoints: list[np.ndarray] = []
        self._next = 0

    def start(self, now_s: float, centre_ne) -> None:
        s = self.settings
        self.started_s = now_s
        self.waypoints = expanding_square(centre_ne, s.spacing_m, s.radius_m)
        self._next = 0
        self.stage = "climbing"

    def elapsed_s(self, now_s: float) -> float:
        return now_s - self.started_s

    def update(self, now_s: float, position_ned_m) -> SearchCommand:
        s = self.settings
        here = np.asarray(position_ned_m, dtype=float)
        z = -s.altitude_m
        timed_out = now_s - self.started_s > s.timeout_s
        if self.stage == "climbing":
            if abs(here[2] - z) > ARRIVE_M:
                centre = self.waypoints[0]
                return SearchCommand((float(centre[0]), float(centre[1]), z), self.stage,
                                     timed_out)
            self.stage = "sweeping"
        while self._next < len(self.waypoints) - 1 and np.linalg.norm(
                here[:2] - self.waypoints[self._next]) < ARRIVE_M:
            self._next += 1
        if self._next == len(self.waypoints) - 1:
            self.stage = "waiting"
        goal = self.waypoints[self._next]
        # towards the next corner at the search speed: a setpoint that leads the vehicle
        to_goal = goal - here[:2]
        dist = float(np.linalg.norm(to_goal))
        lead = min(dist, s.speed_m_s * LEAD_S)
        target = here[:2] + (to_goal / dist * lead if dist > 1e-6 else 0.0)
        return SearchCommand((float(target[0]), float(target[1]), z), self.stage, timed_out)
