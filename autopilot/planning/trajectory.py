"""Time-parametrised trajectories: a smooth path, a speed law within the vehicle's limits, and
the position, velocity and acceleration references sampled from them.

A :class:`Path` is a cubic spline through points, parametrised by arc length (so its first
derivative is the unit tangent and its second the curvature vector). A :class:`Trajectory` puts
a speed law on it:

1. the speed each point allows: the cruise speed, ``√(a_lat / κ)`` on curves, and the vertical
   speed limits where the path climbs or descends;
2. a forward and a backward pass that keep the along-path acceleration within ``accel_m_s2``
   (a trapezoid on straight lines, slowing before curves and the end);
3. a box filter over time whose width is ``accel_m_s2 / jerk_m_s3``: the acceleration then
   ramps instead of jumping (bounded jerk), and the path length is kept.

The reference at time *t* is then ``p(s)``, ``p'(s)·ṡ`` and ``p''(s)·ṡ² + p'(s)·s̈``: what
PX4's position controller takes as setpoint and feed-forwards (SET_POSITION_TARGET_LOCAL_NED's
position, velocity and acceleration). A heading law gives the yaw and its rate at each point.

Everything here is synchronous numpy/scipy; a trajectory is computed once, when its step
starts, and then only sampled.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.spatial import cKDTree

#: heading law: (arc length s, position NED) of each point → yaw (rad)
YawLaw = Callable[[np.ndarray, np.ndarray], np.ndarray]

_DS_M = 0.05  # speed-law resolution along the path
_DT_S = 0.02  # reference resolution in time


@dataclass(frozen=True, slots=True)
class Limits:
    """What the trajectory may ask of the vehicle."""

    speed_m_s: float  # cruise speed along the path
    accel_m_s2: float = 1.5  # along the path
    lateral_accel_m_s2: float = 1.5  # v²κ on curves
    jerk_m_s3: float = 4.0
    climb_speed_m_s: float = 1.5
    descent_speed_m_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("speed_m_s", "accel_m_s2", "lateral_accel_m_s2", "jerk_m_s3",
                     "climb_speed_m_s", "descent_speed_m_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")


@dataclass(frozen=True, slots=True, eq=False)
class Reference:
    """The trajectory at one moment: what the vehicle should be doing then."""

    time_s: float  # since the trajectory's start
    s_m: float  # arc length reached
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    acceleration_ned_m_s2: np.ndarray
    yaw_rad: float
    yaw_rate_rad_s: float


def dedupe(points: np.ndarray, min_step_m: float = 1e-3) -> np.ndarray:
    """``points`` without points closer than ``min_step_m`` to the last one kept."""
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return points
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    tiny = np.flatnonzero(step <= min_step_m)  # step k: from point k to point k + 1
    if not len(tiny):
        return points
    keep = np.ones(len(points), dtype=bool)
    last, i, k = 0, 1, 0
    while i < len(points):  # (only the tiny steps and what follows them are looked at)
        if float(np.linalg.norm(points[i] - points[last])) > min_step_m:
            # kept: so is every point up to the next tiny step (each is more than
            # min_step_m from the one before it, which is kept)
            while k < len(tiny) and tiny[k] < i:
                k += 1
            last = int(tiny[k]) if k < len(tiny) else len(points) - 1
            i = last + 1
        else:
            keep[i] = False
            i += 1
    return points[keep]


def resample(points: np.ndarray, step_m: float) -> np.ndarray:
    """A polyline with points at most ``step_m`` apart along each of its segments; its own
    points (its corners) kept."""
    points = dedupe(points)
    out = [points[:1]]
    for a, b in itertools.pairwise(points):
        n = max(math.ceil(float(np.linalg.norm(b - a)) / step_m), 1)
        f = np.arange(1, n + 1)[:, None] / n
        out.append(a + (b - a) * f)
    return np.vstack(out)


def resample_evenly(points: np.ndarray, step_m: float) -> np.ndarray:
    """A polyline resampled at one even spacing (about ``step_m``) along its whole length,
    ends kept (corners are not: for smoothing filters that need even spacing)."""
    points = dedupe(points)
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    n = max(math.ceil(s[-1] / step_m), 1) + 1
    grid = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(grid, s, points[:, i]) for i in range(points.shape[1])])


_STOP_ANGLE_RAD = math.radians(30.0)  # a turn this sharp at one point: stop there, then go on
_MIN_PIECE_M = 0.1  # stops closer together than this are one


class Path:
    """A smooth 3D path (NED) through ``points``, parametrised by arc length.

    The points should be dense where the shape matters (:mod:`autopilot.planning`'s planners
    resample them every 5 cm and round what should be round). Where the polyline turns sharply
    at one point (more than 30°: a corner not rounded, or a reversal) the path has a *stop*:
    it is a chain of cubic splines, one per stretch between stops, and a trajectory comes to
    rest at each stop (a multicopter can turn on the spot; it cannot turn a corner at speed).
    """

    def __init__(self, points: np.ndarray) -> None:
        pts = dedupe(np.asarray(points, dtype=float).reshape(-1, 3))
        if len(pts) < 2:
            raise ValueError("a path needs at least two distinct points")
        seg = np.diff(pts, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        s = np.concatenate(([0.0], np.cumsum(lengths)))
        unit = seg / lengths[:, None]
        cos = np.einsum("ij,ij->i", unit[:-1], unit[1:])
        corners = []  # point indices; stops closer than 10 cm (a cusp's two bends) are one
        for i in (np.flatnonzero(cos < math.cos(_STOP_ANGLE_RAD)) + 1).tolist():
            if s[i] - s[corners[-1] if corners else 0] >= _MIN_PIECE_M and \
                    s[-1] - s[i] >= _MIN_PIECE_M:
                corners.append(i)
        corners = np.array(corners, dtype=int)
        bounds = [0, *corners.tolist(), len(pts) - 1]
        self._pieces = []
        for a, b in itertools.pairwise(bounds):
            k = min(3, b - a)
            spline = make_interp_spline(s[a:b + 1], pts[a:b + 1], k=k)
            d2 = spline.derivative(2) if k >= 2 else None
            self._pieces.append((s[a], s[b], spline, spline.derivative(1), d2))
        self._starts = np.array([p[0] for p in self._pieces])
        self.stops_m = s[corners]
        self.length_m = float(s[-1])
        self.points = pts

    def _eval(self, s, which: int) -> np.ndarray:
        s_arr = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length_m)
        idx = np.clip(np.searchsorted(self._starts, s_arr, side="right") - 1, 0,
                      len(self._pieces) - 1)
        out = np.zeros((len(s_arr), 3))
        for i in np.unique(idx):
            piece = self._pieces[i]
            f = piece[2 + which]
            mask = idx == i
            out[mask] = 0.0 if f is None else f(s_arr[mask])
        return out if np.ndim(s) else out[0]

    def position(self, s: np.ndarray | float) -> np.ndarray:
        return self._eval(s, 0)

    def tangent(self, s: np.ndarray | float) -> np.ndarray:
        return self._eval(s, 1)

    def curvature_vector(self, s: np.ndarray | float) -> np.ndarray:
        return self._eval(s, 2)

    def polyline(self, step_m: float = 0.1) -> np.ndarray:
        n = max(math.ceil(self.length_m / step_m), 1) + 1
        grid = np.union1d(np.linspace(0.0, self.length_m, n), self.stops_m)
        return self.position(grid)


def hold_heading(yaw_rad: float) -> YawLaw:
    return lambda s, p: np.full(len(s), float(yaw_rad))


def face_point(north_m: float, east_m: float) -> YawLaw:
    """Heading towards a point (an orbit's centre) from wherever the path is."""
    return lambda s, p: np.arctan2(east_m - p[:, 1], north_m - p[:, 0])


class Trajectory:
    """A path with a speed law from rest to rest, sampled every 20 ms."""

    def __init__(self, path: Path, limits: Limits, yaw: YawLaw) -> None:
        self.path = path
        self.limits = limits
        bounds = [0.0, *path.stops_m.tolist(), path.length_m]
        arcs, speeds = [], []
        for a, b in itertools.pairwise(bounds):
            arc, speed = self._piece(a, b)
            if arcs:  # rest at the stop for one sample, then go on
                arc, speed = arc[1:], speed[1:]
            arcs.append(arc)
            speeds.append(speed)
        arc, speed = np.concatenate(arcs), np.concatenate(speeds)
        self.times_s = np.arange(len(arc)) * _DT_S
        self.s_m = arc
        self.speed_m_s = speed
        s_acc = np.gradient(speed, _DT_S) if len(speed) > 1 else np.zeros(1)
        d1 = path.tangent(arc)
        d2 = path.curvature_vector(arc)
        self.positions = path.position(arc)
        self.velocities = d1 * speed[:, None]
        self.accelerations = d2 * (speed ** 2)[:, None] + d1 * s_acc[:, None]
        yaw = np.unwrap(yaw(arc, self.positions))
        self.yaw_rad = yaw
        self.yaw_rate_rad_s = np.gradient(yaw, _DT_S) if len(yaw) > 1 else np.zeros(1)

    def _piece(self, s0: float, s1: float) -> tuple[np.ndarray, np.ndarray]:
        """(arc length, speed) every 20 ms from rest at ``s0`` to rest at ``s1``."""
        limits = self.limits
        n = max(math.ceil((s1 - s0) / _DS_M), 1) + 1
        s = np.linspace(s0, s1, n)
        # (just inside the ends: the spline of this stretch, not the next one's)
        v = self._speed_law(np.clip(s, s0 + 1e-6, max(s1 - 1e-6, s0 + 1e-6)))
        t = self._times(s, v)
        grid = np.arange(0.0, t[-1] + _DT_S, _DT_S)
        speed = np.interp(grid, t, v)
        width = max(round(limits.accel_m_s2 / limits.jerk_m_s3 / _DT_S), 1)
        if width > 1:  # the jerk filter: a box of width a/j over the speed
            pad = np.zeros(width)
            speed = np.convolve(np.concatenate((pad, speed, pad)), np.ones(width) / width,
                                mode="same")
            nz = np.flatnonzero(speed > 1e-9)
            if len(nz):
                speed = speed[max(nz[0] - 1, 0):min(nz[-1] + 2, len(speed))]
        if len(speed) < 2:
            speed = np.zeros(2)
        arc = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * _DT_S)))
        if arc[-1] > 0:  # (the filter keeps the length; this removes the rounding)
            scale = (s1 - s0) / arc[-1]
            arc, speed = arc * scale, speed * scale
        return s0 + arc, speed

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @property
    def length_m(self) -> float:
        return self.path.length_m

    @property
    def end(self) -> np.ndarray:
        return self.positions[-1]

    def at(self, time_s: float) -> Reference:
        """The reference at ``time_s`` after the start (held at the end afterwards)."""
        t = min(max(time_s, 0.0), self.duration_s)
        f = t / _DT_S
        i = min(int(f), len(self.times_s) - 1)
        j = min(i + 1, len(self.times_s) - 1)
        w = f - i if j > i else 0.0

        def lerp(a):
            return a[i] + (a[j] - a[i]) * w

        after = time_s >= self.duration_s
        zero = np.zeros(3)
        return Reference(t, float(lerp(self.s_m)), lerp(self.positions),
                         zero if after else lerp(self.velocities),
                         zero if after else lerp(self.accelerations),
                         float(lerp(self.yaw_rad)),
                         0.0 if after else float(lerp(self.yaw_rate_rad_s)))

    def time_at(self, s_m: float) -> float:
        """When the reference reaches arc length ``s_m``."""
        return float(np.interp(s_m, self.s_m, self.times_s))

    def nearest_time(self, position: np.ndarray, near_s: float, window_m: float = 5.0
                     ) -> tuple[float, float]:
        """(time, distance) of the reference point nearest ``position`` within ``window_m`` of
        arc length around ``near_s`` (a path may cross itself: look near where it should be)."""
        lo = np.searchsorted(self.s_m, near_s - window_m)
        hi = max(np.searchsorted(self.s_m, near_s + window_m, side="right"), lo + 1)
        d = np.linalg.norm(self.positions[lo:hi] - position, axis=1)
        k = int(np.argmin(d))
        return float(self.times_s[lo + k]), float(d[k])

    # -- the speed law ----------------------------------------------------------------------

    def _speed_law(self, s: np.ndarray) -> np.ndarray:
        lim = self.limits
        kappa = np.linalg.norm(self.path.curvature_vector(s), axis=1)
        v = np.full(len(s), lim.speed_m_s)
        with np.errstate(divide="ignore"):
            v = np.minimum(v, np.sqrt(lim.lateral_accel_m_s2 / np.maximum(kappa, 1e-9)))
        dz = self.path.tangent(s)[:, 2]  # down per metre along the path
        with np.errstate(divide="ignore"):
            v = np.where(dz < -1e-6, np.minimum(v, lim.climb_speed_m_s / np.abs(dz)), v)
            v = np.where(dz > 1e-6, np.minimum(v, lim.descent_speed_m_s / np.abs(dz)), v)
        v[0] = v[-1] = 0.0
        # the forward pass v_i² ≤ v_{i-1}² + 2a·Δs and the backward one, in closed form: with
        # S_i = Σ 2a·Δs up to i, the forward pass is v_i² = S_i + min over j ≤ i of (v_j² − S_j)
        # (a running minimum), the backward one the same from the end (vectorised: a 10 km
        # path is 200,000 points)
        w = v * v
        reach = np.concatenate(([0.0], np.cumsum(2.0 * lim.accel_m_s2 * np.diff(s))))
        w = reach + np.minimum.accumulate(w - reach)
        w = np.minimum.accumulate((w + reach)[::-1])[::-1] - reach
        return np.minimum(np.sqrt(np.maximum(w, 0.0)), v)  # (never above a cap by rounding)

    def _times(self, s: np.ndarray, v: np.ndarray) -> np.ndarray:
        ds = np.diff(s)
        # (a stretch between two rests shorter than a sample: accelerate and brake over it)
        floor = 0.5 * np.sqrt(self.limits.accel_m_s2 * np.maximum(ds, 1e-9))
        mean = np.maximum(0.5 * (v[1:] + v[:-1]), floor)
        return np.concatenate(([0.0], np.cumsum(ds / mean)))


def cross_track_m(path_points: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Each position's distance from a polyline path (to its nearest segment; for scoring)."""
    path = np.asarray(path_points, dtype=float)
    pos = np.asarray(positions, dtype=float)
    if len(path) < 2:
        return np.linalg.norm(pos - path[0], axis=1)
    _, idx = cKDTree(path).query(pos)
    best = np.full(len(pos), np.inf)
    for lo in (idx - 1, idx):  # the segments on either side of the nearest point
        lo = np.clip(lo, 0, len(path) - 2)
        a, b = path[lo], path[lo + 1]
        ab = b - a
        f = np.clip(np.einsum("ij,ij->i", pos - a, ab) /
                    np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(a + ab * f[:, None] - pos, axis=1))
    return best
