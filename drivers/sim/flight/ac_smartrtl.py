"""ArduCopter's SMART_RTL (``AP_SmartRTL`` and ``mode_smart_rtl.cpp``) for the simulated
ArduCopter (:mod:`drivers.sim.flight.arducopter`): the way home retraced along the path flown.

The path (:class:`SmartRtlPath`, AP_SmartRTL):

* armed with a position, the vehicle's position is its first point ("home"); armed without
  one, SMART_RTL is off for the flight;
* while armed and not in SMART_RTL a point is added (at 3 Hz or faster) whenever the vehicle is
  SRTL_ACCURACY (2 m) from the last one, up to SRTL_POINTS (300; 0 turns SMART_RTL off);
* cleanup: Ramer–Douglas–Peucker simplification (points within SRTL_ACCURACY/2 of a straight
  line go) and loop pruning (two segments closer than 0.99 × SRTL_ACCURACY: what lies between
  them is cut, the midpoint of their closest points kept). ArduPilot runs both in the
  background, a few hundred microseconds at a time, when 50 new points came or the buffer is
  within 10 points of full, and thoroughly when the mode starts; here each runs to completion
  at those same moments (loops are cut greedily from the newest segment back, each at the
  oldest segment it comes close to — the longest loop, as ArduPilot keeps);
* deactivated for the flight, saying ``SmartRTL deactivated: bad position`` after 15 s without
  a position, or ``SmartRTL deactivated: buffer full`` after 15 s with no point saved because
  the buffer stayed full.

The mode (:class:`SmartRtlFlight`): refused when the path is off (``init failed``); it pops the
points back home, the next one the target as soon as the vehicle is within WPNAV_RADIUS of the
current, the last one (where it armed) 2 m higher (PRELAND_POSITION), reached within 0.3 m;
there it lands, or with RTL_ALT_FINAL > 0
descends to that height and hovers. Leaving the mode before a point is reached puts that point
back on the path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.base import Setpoint
from drivers.sim.flight.params import Parameters

#: AP_SmartRTL's fixed values
TIMEOUT_S = 15.0
CLEANUP_POINT_TRIGGER = 50
CLEANUP_START_MARGIN = 10
POINTS_MAX = 500
#: the last point is approached this much higher (mode_smart_rtl.cpp)
PRELAND_CLIMB_M = 2.0
#: the last point counts as reached this close (AC_WPNav: when its moving target has arrived
#: and the vehicle is within WPNAV_RADIUS; the breadcrumbs before it switch at WPNAV_RADIUS)
LAST_POINT_REACHED_M = 0.3


class SmartRtlPath:
    """The breadcrumbs (NED, metres from the origin) of one armed flight."""

    def __init__(self, params: Parameters, say: Callable[[str], None]) -> None:
        self._params = params
        self._say = say
        self.points: list[np.ndarray] = []
        self.active = False
        self._max = 0
        self._accuracy_m = 0.0
        self._simplified = 0  # points already simplified (routine cleanup)
        self._changed = False  # points added since the routine cleanup last ran
        self._last_good_s = 0.0
        self._last_saved_s = 0.0

    # --- recording --------------------------------------------------------------------

    def set_home(self, now_s: float, position_ok: bool, position_ned_m: np.ndarray) -> None:
        """Arming: a new path from here (none without a position or with SRTL_POINTS 0)."""
        self._max = min(max(int(self._params["SRTL_POINTS"]), 0), POINTS_MAX)
        self._accuracy_m = float(self._params["SRTL_ACCURACY"])
        self.points = []
        self._simplified = 0
        self.active = False
        if self._max == 0 or not self._accuracy_m > 0 or not position_ok:
            return
        self.points.append(np.array(position_ned_m, float))
        self.active = True
        self._last_good_s = self._last_saved_s = now_s

    def update(self, now_s: float, position_ok: bool, position_ned_m: np.ndarray) -> None:
        """A position sample while armed and not in SMART_RTL."""
        if not self.active:
            return
        if not position_ok:
            if now_s - self._last_good_s > TIMEOUT_S:
                self._deactivate("bad position")
            return
        self._last_good_s = now_s
        if self._add(np.asarray(position_ned_m, float)):
            self._last_saved_s = now_s
        elif now_s - self._last_saved_s > TIMEOUT_S:
            self._deactivate("buffer full")
        if self._changed:  # (a full buffer that nothing could shorten stays as it is)
            self._changed = False
            self._routine_cleanup()

    def _add(self, point: np.ndarray) -> bool:
        if self.points and np.linalg.norm(point - self.points[-1]) < self._accuracy_m:
            return True
        if len(self.points) >= self._max:
            return False
        self.points.append(point.copy())
        self._changed = True
        return True

    def _deactivate(self, why: str) -> None:
        self.active = False
        self._say(f"SmartRTL deactivated: {why}")

    # --- cleanup ----------------------------------------------------------------------

    def _routine_cleanup(self) -> None:
        n = len(self.points)
        low_on_space = self._max - n <= CLEANUP_START_MARGIN
        new = n - self._simplified
        if new >= CLEANUP_POINT_TRIGGER or (low_on_space and new >= 10):
            self._simplify()
        if self._max - len(self.points) <= CLEANUP_START_MARGIN:
            self._prune()

    def thorough_cleanup(self) -> None:
        """What the mode waits for before it starts home: every simplification and loop."""
        self._simplify()
        self._prune()

    def _simplify(self) -> None:
        self.points = simplify(self.points, self._accuracy_m * 0.5)
        self._simplified = len(self.points)

    def _prune(self) -> None:
        self.points = prune_loops(self.points, self._accuracy_m * 0.99)
        self._simplified = min(self._simplified, len(self.points))

    # --- flying home ------------------------------------------------------------------

    def pop(self) -> np.ndarray | None:
        return self.points.pop() if self.active and self.points else None

    def put_back(self, point: np.ndarray) -> None:
        if self.active and len(self.points) < self._max:
            self.points.append(point)
        else:
            self._say("SmartRTL: lost one point")


def simplify(points: list[np.ndarray], epsilon_m: float) -> list[np.ndarray]:
    """Ramer–Douglas–Peucker: the points more than ``epsilon_m`` off the line kept."""
    n = len(points)
    if n < 3:
        return list(points)
    keep = [False] * n
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        start, end = stack.pop()
        far, far_d = start, 0.0
        for i in range(start + 1, end):
            d = point_segment_distance(points[i], points[start], points[end])
            if d > far_d:
                far, far_d = i, d
        if far_d > epsilon_m:
            keep[far] = True
            stack += [(start, far), (far, end)]
    return [p for p, k in zip(points, keep, strict=True) if k]


def prune_loops(points: list[np.ndarray], delta_m: float) -> list[np.ndarray]:
    """Cut every loop: segment (i-1, i) passing within ``delta_m`` of an older segment
    (j-1, j), never its neighbours: the points j … i-1 give way to the midpoint of the two
    segments' closest points."""
    pts = list(points)
    i = len(pts) - 1
    while i >= 3:
        for j in range(1, i - 1):
            gap, midpoint = segment_segment_distance(pts[i], pts[i - 1], pts[j - 1], pts[j])
            if gap < delta_m:
                pts[j:i] = [midpoint]
                i = j + 1
                break
        i -= 1
    return pts


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    length2 = float(ab @ ab)
    t = 0.0 if length2 == 0.0 else min(max(float((p - a) @ ab) / length2, 0.0), 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


def segment_segment_distance(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray,
                             p4: np.ndarray) -> tuple[float, np.ndarray]:
    """AP_SmartRTL's closest distance of segments p1–p2 and p3–p4 (each line's parameter
    clamped to its segment) and the point halfway between; parallel lines: infinite."""
    d1, d2, r = p2 - p1, p4 - p3, p1 - p3
    a, b, c = float(d1 @ d1), float(d1 @ d2), float(d2 @ d2)
    d, e = float(d1 @ r), float(d2 @ r)
    det = a * c - b * b
    if abs(det) < 1e-9:
        return math.inf, np.zeros(3)
    t1 = min(max((b * e - c * d) / det, 0.0), 1.0)
    t2 = min(max((a * e - b * d) / det, 0.0), 1.0)
    q1, q2 = p1 + d1 * t1, p3 + d2 * t2
    return float(np.linalg.norm(q1 - q2)), (q1 + q2) / 2.0


@dataclass
class SmartRtlFlight:
    """SMART_RTL in flight: the breadcrumbs popped back home (:meth:`setpoint` each tick)."""

    path: SmartRtlPath
    target: np.ndarray
    #: the popped point not yet reached (put back on the path when the mode ends early)
    backup: np.ndarray | None = None
    preland: bool = False
    done: bool = False

    @classmethod
    def start(cls, path: SmartRtlPath, position_ned_m: np.ndarray) -> SmartRtlFlight:
        path.thorough_cleanup()
        return cls(path, np.array(position_ned_m, float))

    def setpoint(self, position_ned_m: np.ndarray, radius_m: float) -> Setpoint | None:
        """The target now; None once the last point is reached (land or descend there)."""
        if self.done:
            return None
        if self.preland:  # (the target itself arrives there: AC_WPNav's reached)
            radius_m = min(radius_m, LAST_POINT_REACHED_M)
        if np.linalg.norm(np.asarray(position_ned_m, float) - self.target) <= radius_m:
            self.backup = None
            if self.preland:
                self.done = True
                return None
            point = self.path.pop()
            if point is None:
                self.preland = True  # (no point at all: ArduPilot lands where it is)
            else:
                self.backup = point
                if not self.path.points:
                    point = point + np.array([0.0, 0.0, -PRELAND_CLIMB_M])
                    self.preland = True
                self.target = point
        return Setpoint(position_ned_m=self.target.copy())

    def end(self) -> None:
        """The mode ends (another mode chosen): an unreached point goes back on the path."""
        if self.backup is not None and not self.preland:
            self.path.put_back(self.backup)
        self.backup = None
