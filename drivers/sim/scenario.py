"""Scenario objects: what a mission's scenario adds to the simulated world.

A scenario object builds its bodies into the world before the model is compiled and moves them
by script during the run, without touching the airframe model. Positions are given in the local
NED frame (origin on the ground below the vehicle's start), like everything above the simulator.

The simulator calls, in order: :meth:`ScenarioObject.build` once (before compiling),
:meth:`ScenarioObject.bind` once (after), :meth:`ScenarioObject.update` before every physics
step that runs the flight controller or captures a sample (so every frame and ground-truth
sample shows the object exactly where its script puts it), and :meth:`ScenarioObject.truth`
whenever ground truth is sampled.
"""

from __future__ import annotations

import abc
import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import mujoco
import numpy as np

from drivers.geometry import quat_from_euler
from drivers.sim.frames import ENU_FROM_NED, enu_to_ned, ned_to_enu


@dataclass(frozen=True, slots=True, eq=False)
class BodyTruth:
    """True pose and motion of a body, local NED (for scoring, tests and plots only)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    attitude_q: np.ndarray  # body FRD → NED (for bodies without a heading: identity)


class WorldFrame:
    """Maps the local NED frame into MuJoCo's ENU world (the local origin's ENU position)."""

    def __init__(self, origin_enu_m: np.ndarray) -> None:
        self.origin_enu_m = np.asarray(origin_enu_m, dtype=float)

    def to_enu(self, position_ned_m: np.ndarray) -> np.ndarray:
        return ned_to_enu(position_ned_m) + self.origin_enu_m

    def to_ned(self, position_enu_m: np.ndarray) -> np.ndarray:
        return enu_to_ned(np.asarray(position_enu_m) - self.origin_enu_m)

    @staticmethod
    def velocity_to_enu(velocity_ned_m_s: np.ndarray) -> np.ndarray:
        return ENU_FROM_NED @ np.asarray(velocity_ned_m_s, dtype=float)


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
    """Smooth random horizontal motion: the velocity is a seeded Ornstein–Uhlenbeck process with
    the given RMS speed, pulled back towards the start when it strays beyond ``radius_m``.
    Precomputed on a fine grid, so position is a pure function of time."""

    def __init__(self, start_ned_m, speed_m_s: float, seed: int, radius_m: float = 5.0,
                 time_constant_s: float = 2.0, duration_s: float = 900.0,
                 dt_s: float = 0.01) -> None:
        rng = np.random.default_rng(seed)
        n = int(duration_s / dt_s) + 1
        a = math.exp(-dt_s / time_constant_s)
        sigma = speed_m_s / math.sqrt(2.0)  # per axis, so the RMS speed is speed_m_s
        noise = rng.standard_normal((n, 2)) * sigma * math.sqrt(1.0 - a * a)
        pos = np.zeros((n, 2))
        vel = np.zeros((n, 2))
        v = rng.standard_normal(2) * sigma
        p = np.zeros(2)
        for k in range(n):
            pos[k], vel[k] = p, v
            p = p + v * dt_s
            pull = -p * max(0.0, np.linalg.norm(p) - radius_m) / radius_m  # soft boundary
            v = a * v + noise[k] + pull * dt_s
        self._t = np.arange(n) * dt_s
        self._pos, self._vel = pos, vel
        self._start = np.asarray(start_ned_m, dtype=float)
        self._dt = dt_s

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


@dataclass(frozen=True, slots=True)
class Geom:
    """A visual (and optionally colliding) shape of a scenario body, offset in its frame."""

    type: str  # sphere | box | cylinder | capsule | plane
    size: tuple[float, ...]
    rgba: tuple[float, float, float, float]
    offset_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    collide: bool = False
    material: str | None = None


_GEOM_TYPES = {
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "plane": mujoco.mjtGeom.mjGEOM_PLANE,
}


class ScenarioObject(abc.ABC):
    name: str
    #: False for objects that never move (update() is then not called every step).
    moves: bool = True

    @abc.abstractmethod
    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        """Add bodies to the world (names must start with ``self.name``)."""

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData,  # noqa: B027 - optional hook
             frame: WorldFrame) -> None:
        """Resolve ids once the model is compiled."""

    def update(self, time_s: float, data: mujoco.MjData) -> None:  # noqa: B027 - optional hook
        """Move scripted bodies to where they are at ``time_s`` (before each physics step)."""

    @abc.abstractmethod
    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth: ...


@dataclass
class MocapBody(ScenarioObject):
    """A body moved along a :class:`Trajectory` (a MuJoCo mocap body: it pushes, is not pushed)."""

    name: str
    geoms: Sequence[Geom]
    trajectory: Trajectory | Callable[[float], tuple[np.ndarray, np.ndarray, float]]
    _mocap_id: int = field(default=-1, init=False)
    _frame: WorldFrame | None = field(default=None, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        pos, _, yaw = self.trajectory(0.0)
        body = spec.worldbody.add_body(name=self.name, mocap=True, pos=frame.to_enu(pos),
                                       quat=_yaw_quat_enu(yaw))
        for i, g in enumerate(self.geoms):
            kwargs = {}
            if g.material is not None:
                kwargs["material"] = g.material
            body.add_geom(
                name=f"{self.name}/geom{i}",
                type=_GEOM_TYPES[g.type],
                size=_pad3(g.size),
                rgba=list(g.rgba),
                pos=ned_to_enu(np.array(g.offset_ned_m, dtype=float)),
                contype=1 if g.collide else 0,
                conaffinity=1 if g.collide else 0,
                **kwargs,
            )

    @property
    def moves(self) -> bool:  # type: ignore[override]
        return not isinstance(self.trajectory, Static) and not (
            isinstance(self.trajectory, ClosedPath) and self.trajectory.speed_m_s == 0.0)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._frame = frame
        self._origin = tuple(frame.origin_enu_m.tolist())

    def update(self, time_s: float, data: mujoco.MjData) -> None:
        (n, e, d), _, yaw = self.trajectory(time_s)
        ox, oy, oz = self._origin
        data.mocap_pos[self._mocap_id] = (e + ox, n + oy, oz - d)
        data.mocap_quat[self._mocap_id] = _yaw_quat_enu(yaw)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        pos, vel, yaw = self.trajectory(time_s)
        return BodyTruth(pos, vel, quat_from_euler(0.0, 0.0, yaw))


def _yaw_quat_enu(yaw_ned_rad: float) -> np.ndarray:
    """MuJoCo (ENU/FLU) orientation of a body with NED heading ``yaw_ned_rad``: a turn about
    the up axis by π/2 − yaw (ENU measures heading from east, counter-clockwise)."""
    half = 0.5 * (0.5 * math.pi - yaw_ned_rad)
    return np.array((math.cos(half), 0.0, 0.0, math.sin(half)))


def _pad3(size: Sequence[float]) -> list[float]:
    return [*size, *([0.0] * (3 - len(size)))]
