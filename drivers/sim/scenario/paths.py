"""Scripted motions (local NED): static, closed curves (circle, figure eight, Lissajous),
a random walk that moves as a body can, delays; :func:`named_path` by a scenario's name."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np


class Trajectory(Protocol):
    """A scripted motion: pose and velocity at a time (local NED)."""

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        """Return ``(position_ned_m, velocity_ned_m_s, yaw_rad)``."""
        ...


@dataclass(frozen=True, slots=True)
class Static:
    position_ned_m: tuple[float, float, float]
    yaw_rad: float = 0.0

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        return np.array(self.position_ned_m, dtype=float), np.zeros(3), self.yaw_rad


class ClosedPath:
    """Constant speed along a closed curve in the horizontal plane (plus an optional vertical
    wave), anchored so that the path starts at ``start_ned_m`` and oriented by ``heading_rad``.

    ``shape(s)`` maps a parameter s ∈ [0, 2π) to an (x, y, z) offset; motion is re-parameterised
    by arc length so the speed is exactly ``speed_m_s`` everywhere.
    """

    _SAMPLES = 4096

    def __init__(self, shape: Callable[[np.ndarray], np.ndarray], start_ned_m, speed_m_s: float,
                 heading_rad: float = 0.0) -> None:
        s = np.linspace(0.0, 2.0 * math.pi, self._SAMPLES + 1)
        pts = shape(s)  # 3 × N
        c, sn = math.cos(heading_rad), math.sin(heading_rad)
        rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        pts = rot @ (pts - pts[:, :1])
        seg = np.linalg.norm(np.diff(pts, axis=1), axis=0)
        arc = np.concatenate(([0.0], np.cumsum(seg)))
        self.length_m = float(arc[-1])
        # plain floats: this is evaluated at every control tick
        self._arc = arc.tolist()
        self._pts = (pts.T + np.asarray(start_ned_m, dtype=float)).tolist()
        self._start = np.asarray(start_ned_m, dtype=float)
        self.speed_m_s = speed_m_s

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        if self.speed_m_s == 0.0:
            return self._start.copy(), np.zeros(3), 0.0
        d = (self.speed_m_s * time_s) % self.length_m
        i = min(max(bisect.bisect_right(self._arc, d) - 1, 0), self._SAMPLES - 1)
        a0, a1 = self._arc[i], self._arc[i + 1]
        f = (d - a0) / (a1 - a0)
        (ax, ay, az), (bx, by, bz) = self._pts[i], self._pts[i + 1]
        dx, dy, dz = bx - ax, by - ay, bz - az
        k = self.speed_m_s / math.sqrt(dx * dx + dy * dy + dz * dz)
        return (np.array((ax + f * dx, ay + f * dy, az + f * dz)),
                np.array((dx * k, dy * k, dz * k)), math.atan2(dy, dx))


def circle(start_ned_m, speed_m_s: float, radius_m: float = 3.0,
           heading_rad: float = 0.0) -> ClosedPath:
    """Counter-clockwise (seen from above) circle; the start point is its southern-most point
    when ``heading_rad`` is 0 (the ball first moves east)."""
    return ClosedPath(lambda s: np.stack((-radius_m * np.cos(s), radius_m * np.sin(s),
                                          0.0 * s)), start_ned_m, speed_m_s, heading_rad)


def figure8(start_ned_m, speed_m_s: float, length_m: float = 8.0, width_m: float = 4.0,
            heading_rad: float = 0.0) -> ClosedPath:
    """A figure eight (lemniscate of Gerono) through its crossing point, long axis east–west
    when ``heading_rad`` is 0."""
    a, b = length_m / 2.0, width_m / 2.0
    return ClosedPath(lambda s: np.stack((b * np.sin(2 * s), a * np.sin(s), 0.0 * s)),
                      start_ned_m, speed_m_s, heading_rad)


def lissajous(start_ned_m, speed_m_s: float, size_m: tuple[float, float] = (6.0, 8.0),
              vertical_m: float = 0.4, heading_rad: float = 0.0) -> ClosedPath:
    """A 3:2 Lissajous curve with a gentle vertical wave."""
    a, b = size_m[0] / 2.0, size_m[1] / 2.0
    return ClosedPath(lambda s: np.stack((a * np.sin(2 * s), b * np.sin(3 * s),
                                          -vertical_m * np.sin(s))),
                      start_ned_m, speed_m_s, heading_rad)


class RandomWalk:
    """Smooth random horizontal motion, as a walking person or a carried target moves: the
    velocity wanders (a seeded second-order Gauss–Markov process: its acceleration is itself
    smooth, correlated over ``accel_time_constant_s``, and its direction and speed over
    ``time_constant_s``) with about the given RMS speed, and the target follows it with at most
    ``max_accel_m_s2`` of acceleration, pulled back towards the start when it strays beyond
    ``radius_m``. A first-order (Ornstein–Uhlenbeck) velocity would have unbounded, white
    acceleration — steps no body makes (its 99th percentile above 10 m/s² at 2.5 m/s).
    Precomputed on a fine grid, so position is a pure function of time."""

    def __init__(self, start_ned_m, speed_m_s: float, seed: int, radius_m: float = 5.0,
                 time_constant_s: float = 2.0, duration_s: float = 900.0,
                 dt_s: float = 0.01, max_accel_m_s2: float = 2.0,
                 accel_time_constant_s: float = 0.5) -> None:
        if max_accel_m_s2 <= 0.0:
            raise ValueError("max_accel_m_s2 must be positive")
        rng = np.random.default_rng(seed)
        n = int(duration_s / dt_s) + 1
        # the wanted velocity: a' = -a/τa - v/(τa·τv) + white noise (plain floats: fast)
        ta, tv = accel_time_constant_s, time_constant_s
        noise = (rng.standard_normal((n, 2)) * math.sqrt(dt_s)).tolist()
        wanted = np.zeros((n, 2))
        vx = vy = ax = ay = 0.0
        for k in range(n):
            wanted[k] = vx, vy
            nx, ny = noise[k]
            ax += dt_s * (-ax / ta - vx / (ta * tv)) + nx
            ay += dt_s * (-ay / ta - vy / (ta * tv)) + ny
            vx += ax * dt_s
            vy += ay * dt_s
        rms = math.sqrt(float(np.mean(np.sum(wanted ** 2, axis=1))))
        wanted *= speed_m_s / rms if rms > 0.0 else 0.0
        # the target follows the wanted velocity within its acceleration, kept near the start;
        # the wanted velocity is rescaled until the target's own RMS speed is speed_m_s
        # (at most 3 times the RMS speed: faster, it could not turn within the radius)
        limit = 3.0 * speed_m_s
        for _ in range(6):
            speeds = np.linalg.norm(wanted, axis=1, keepdims=True)
            capped = wanted * np.minimum(1.0, limit / np.maximum(speeds, 1e-9))
            pos, vel = self._follow(capped.tolist(), dt_s, max_accel_m_s2, radius_m)
            rms = math.sqrt(float(np.mean(np.sum(vel ** 2, axis=1))))
            if rms <= 0.0 or abs(rms / speed_m_s - 1.0) < 0.02:
                break
            wanted *= speed_m_s / rms
        self._t = np.arange(n) * dt_s
        self._pos, self._vel = pos, vel
        self._start = np.asarray(start_ned_m, dtype=float)
        self._dt = dt_s

    @staticmethod
    def _follow(wanted: list[list[float]], dt_s: float, max_accel_m_s2: float,
                radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        n = len(wanted)
        pos = np.zeros((n, 2))
        vel = np.zeros((n, 2))
        px = py = 0.0
        vx, vy = wanted[0]
        for k in range(n):
            pos[k] = px, py
            vel[k] = vx, vy
            wx, wy = wanted[min(k + 1, n - 1)]
            # where it would stop: beyond the radius, it heads no further out, and back
            reach = math.hypot(vx, vy) / (2.0 * max_accel_m_s2)
            sx, sy = px + vx * reach, py + vy * reach
            r = math.hypot(sx, sy)
            if r > radius_m:
                out = max(0.0, (wx * sx + wy * sy) / r) + min(2.0, r - radius_m)
                wx -= out * sx / r
                wy -= out * sy / r
            dvx, dvy = wx - vx, wy - vy
            norm = math.hypot(dvx, dvy)
            if norm > max_accel_m_s2 * dt_s:
                dvx *= max_accel_m_s2 * dt_s / norm
                dvy *= max_accel_m_s2 * dt_s / norm
            vx += dvx
            vy += dvy
            px += vx * dt_s
            py += vy * dt_s
        return pos, vel

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        k = min(max(time_s / self._dt, 0.0), len(self._t) - 1.000001)
        i = int(k)
        f = k - i
        xy = self._pos[i] * (1 - f) + self._pos[i + 1] * f
        v = self._vel[i] * (1 - f) + self._vel[i + 1] * f
        return (self._start + np.array([xy[0], xy[1], 0.0]), np.array([v[0], v[1], 0.0]),
                math.atan2(v[1], v[0]))


@dataclass(frozen=True, slots=True)
class Delayed:
    """Holds a trajectory's starting pose until ``start_s``, then runs it, getting up to speed
    with constant acceleration over ``ramp_s`` (time along the path runs slow at first)."""

    trajectory: Trajectory
    start_s: float
    ramp_s: float = 0.0

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        t = time_s - self.start_s
        if t <= 0.0:
            pos, _, yaw = self.trajectory(0.0)
            return pos, np.zeros(3), yaw
        if t >= self.ramp_s:
            return self.trajectory(t - 0.5 * self.ramp_s)
        pos, vel, yaw = self.trajectory(0.5 * t * t / self.ramp_s)
        return pos, vel * (t / self.ramp_s), yaw


@dataclass(frozen=True, slots=True)
class Circle:
    """Constant-speed horizontal circle around a centre, counter-clockwise seen from above."""

    center_ned_m: tuple[float, float, float]
    radius_m: float
    speed_m_s: float
    phase_rad: float = 0.0

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        omega = self.speed_m_s / self.radius_m
        a = self.phase_rad - omega * time_s  # NED: decreasing angle is counter-clockwise
        c = np.array(self.center_ned_m, dtype=float)
        pos = c + self.radius_m * np.array([math.cos(a), math.sin(a), 0.0])
        vel = self.radius_m * omega * np.array([math.sin(a), -math.cos(a), 0.0])
        return pos, vel, math.atan2(vel[1], vel[0])



PathName = Literal["static", "circle", "figure8", "lissajous", "random_walk"]


def named_path(path: PathName, start_ned_m, speed_m_s: float, size_m: float = 6.0,
               heading_rad: float = 0.0, seed: int = 0, start_delay_s: float = 0.0,
               ramp_s: float = 0.0, accel_m_s2: float = 2.0) -> Trajectory:
    """A trajectory by name, starting at ``start_ned_m``: the ball's paths (``size_m`` is the
    circle's diameter, the figure eight's and the Lissajous curve's length, the random walk's
    diameter), oriented by ``heading_rad``; held for ``start_delay_s`` and brought up to speed
    over ``ramp_s``. ``accel_m_s2`` bounds the random walk's acceleration."""
    start = tuple(float(x) for x in start_ned_m)
    if path == "static" or speed_m_s == 0.0:
        trajectory: Trajectory = Static(start)
    elif path == "circle":
        trajectory = circle(start, speed_m_s, radius_m=size_m / 2.0, heading_rad=heading_rad)
    elif path == "figure8":
        trajectory = figure8(start, speed_m_s, length_m=size_m, width_m=size_m / 2.0,
                             heading_rad=heading_rad)
    elif path == "lissajous":
        trajectory = lissajous(start, speed_m_s, size_m=(0.75 * size_m, size_m),
                               heading_rad=heading_rad)
    elif path == "random_walk":
        trajectory = RandomWalk(start, speed_m_s, seed=seed, radius_m=size_m / 2.0,
                                max_accel_m_s2=accel_m_s2)
    else:
        raise ValueError(f"unknown path {path!r}")
    if start_delay_s > 0.0 or ramp_s > 0.0:
        return Delayed(trajectory, start_delay_s, ramp_s)
    return trajectory


# --------------------------------------------------------------------------------------------
# Marker boards
# --------------------------------------------------------------------------------------------
