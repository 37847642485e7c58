"""Scenario objects: what a mission's scenario adds to the simulated world.

A scenario object builds its bodies into the world before the model is compiled and moves them
by script during the run, without touching the airframe model. Positions are given in the local
NED frame (origin on the ground below the vehicle's start), like everything above the simulator.

The simulator calls, in order: :meth:`ScenarioObject.build` once (before compiling),
:meth:`ScenarioObject.bind` once (after), :meth:`ScenarioObject.update` before every physics
step that runs the flight controller or captures a sample (so every frame and ground-truth
sample shows the object exactly where its script puts it), and :meth:`ScenarioObject.truth`
whenever ground truth is sampled.

Marker boards (:class:`MarkerBoard`, built by :func:`marker_objects`) carry a square fiducial
(ArUco or AprilTag) whose texture is generated at run time from OpenCV's dictionaries.
"""

from __future__ import annotations

import abc
import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import cv2
import mujoco
import numpy as np

from drivers.base import CameraInfo
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.markers import aruco_dictionary
from drivers.sim.frames import ENU_FROM_NED, enu_to_ned, ned_to_enu, quat_enu_flu_to_ned_frd


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


# --------------------------------------------------------------------------------------------
# Paths by name (shared by the ball and the marker boards)
# --------------------------------------------------------------------------------------------

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

Facing = Literal["drone", "travel", "trail", "fixed"]

#: AprilTag families by their OpenCV dictionary names (the same codes and ids).
#: The printed marker's frame in a board's body frame (columns: the marker's axes in FRD). The
#: marker frame is OpenCV's: x right and y up as the marker is read, z out of its face; the
#: board's body x is the face's normal, so the marker's x is the body's left (−y) and its y the
#: body's up (−z).
BOARD_FROM_MARKER = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

_VEHICLE_BODY = "vehicle/base"  # drivers/sim/model.py's VEHICLE_BODY (it imports this module)
_PLATE_M = 0.001  # the printed face's thickness, in front of the board


def marker_texture(dictionary: str, marker_id: int, size_m: float, board_m: float,
                   px_per_cell: int = 16) -> tuple[np.ndarray, float]:
    """The board's face as a grey-scale image: the marker (black square of side ``size_m``,
    code cells of ``px_per_cell`` texels) centred in a white quiet zone. Returns the image and
    the board side it spans (within a texel of ``board_m``, so that the marker is exactly
    ``size_m``)."""
    d = aruco_dictionary(dictionary)
    if not 0 <= marker_id < d.bytesList.shape[0]:
        raise ValueError(f"{dictionary} has no marker {marker_id}")
    if board_m < size_m:
        raise ValueError("the board must be at least as large as the marker")
    side = (d.markerSize + 2) * px_per_cell
    marker = cv2.aruco.generateImageMarker(d, marker_id, side, borderBits=1)
    n = round(board_m / size_m * side)
    n += (n - side) % 2  # an even margin, so the marker sits in the middle
    image = np.full((n, n), 255, np.uint8)
    margin = (n - side) // 2
    image[margin:margin + side, margin:margin + side] = marker
    return image, n * size_m / side


@dataclass
class MarkerBoard(ScenarioObject):
    """A square board carrying a fiducial marker, moved along a trajectory.

    The body's origin is the marker's centre on the printed face; its x axis is the face's
    normal (out of the face), y right and z down as seen from behind the board (FRD), so its
    truth ``attitude_q`` is a heading: the direction the face looks in. The board stays
    upright and turns its face to the vehicle (``drone``), along its direction of travel
    (``travel``), against it (``trail``: towards a follower behind it), or to the fixed
    heading ``yaw_deg`` (``fixed``). The marker frame (OpenCV's) is
    ``R_ned_body @ BOARD_FROM_MARKER``; see :func:`marker_rotation_ned`.

    The face is a thin textured plate (MuJoCo maps a 2D texture onto each face of a box; on the
    −x face it shows mirrored, so the plate's back is buried in the board), the board a plain
    box behind it: no geometry beyond two boxes, no shadows, a texture of a few hundred texels.
    """

    name: str
    marker_id: int
    trajectory: Trajectory | Callable[[float], tuple[np.ndarray, np.ndarray, float]]
    dictionary: str = "DICT_ARUCO_ORIGINAL"
    size_m: float = 0.16
    board_m: float = 0.3
    thickness_m: float = 0.01
    facing: Facing = "drone"
    yaw_deg: float = 0.0  # the face's heading with ``fixed`` (NED, 0 = north)
    board_rgba: tuple[float, float, float, float] = (0.85, 0.85, 0.85, 1.0)
    px_per_cell: int = 16
    _mocap_id: int = field(default=-1, init=False)
    _vehicle_qpos: int = field(default=-1, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)
    _vehicle_start_ned: np.ndarray = field(default_factory=lambda: np.zeros(3), init=False)

    def __post_init__(self) -> None:
        if self.facing not in ("drone", "travel", "trail", "fixed"):
            raise ValueError(f"facing must be drone, travel, trail or fixed, not {self.facing!r}")
        self.texture, self.board_side_m = marker_texture(self.dictionary, self.marker_id,
                                                         self.size_m, self.board_m,
                                                         self.px_per_cell)

    @property
    def moves(self) -> bool:  # type: ignore[override]
        still = isinstance(self.trajectory, Static) or (
            isinstance(self.trajectory, ClosedPath) and self.trajectory.speed_m_s == 0.0)
        return self.facing == "drone" or not still

    def heading(self, position_ned_m: np.ndarray, path_yaw_rad: float,
                vehicle_ned_m: np.ndarray | None) -> float:
        """The face's heading (NED, rad) for the board at a position."""
        if self.facing == "travel":
            return path_yaw_rad
        if self.facing == "trail":
            return path_yaw_rad + math.pi
        if self.facing == "drone" and vehicle_ned_m is not None:
            dn, de = vehicle_ned_m[0] - position_ned_m[0], vehicle_ned_m[1] - position_ned_m[1]
            if dn * dn + de * de > 1e-8:
                return math.atan2(de, dn)
        return math.radians(self.yaw_deg)

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        pos, _, yaw = self.trajectory(0.0)
        self._vehicle_start_ned = frame.to_ned(frame.origin_enu_m)
        vehicle = spec.body(_VEHICLE_BODY)
        if vehicle is not None:
            self._vehicle_start_ned = frame.to_ned(np.array(vehicle.pos, dtype=float))
        heading = self.heading(pos, yaw, self._vehicle_start_ned)
        n = self.texture.shape[0]
        texture = spec.add_texture(name=f"{self.name}/texture", type=mujoco.mjtTexture.mjTEXTURE_2D,
                                   width=n, height=n, nchannel=3)
        texture.data = np.repeat(self.texture[:, :, None], 3, axis=2).tobytes()
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[1.0, 1.0, 1.0, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        body = spec.worldbody.add_body(name=self.name, mocap=True, pos=frame.to_enu(pos),
                                       quat=_yaw_quat_enu(heading))
        half = self.board_side_m / 2.0
        # body FLU: the face's normal is +x
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[_PLATE_M / 2.0, half, half], pos=[-_PLATE_M / 2.0, 0.0, 0.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/board", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.thickness_m / 2.0, half, half],
                      pos=[-_PLATE_M - self.thickness_m / 2.0, 0.0, 0.0],
                      rgba=list(self.board_rgba), contype=0, conaffinity=0)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._origin = tuple(frame.origin_enu_m.tolist())
        vehicle = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, _VEHICLE_BODY)
        if vehicle >= 0 and model.body_jntadr[vehicle] >= 0:
            self._vehicle_qpos = int(model.jnt_qposadr[model.body_jntadr[vehicle]])
        self.update(0.0, data)

    def _vehicle_ned(self, data: mujoco.MjData) -> np.ndarray | None:
        if self._vehicle_qpos < 0:
            return self._vehicle_start_ned
        e, n, u = data.qpos[self._vehicle_qpos:self._vehicle_qpos + 3]
        ox, oy, oz = self._origin
        return np.array((n - oy, e - ox, oz - u))

    def update(self, time_s: float, data: mujoco.MjData) -> None:
        pos, _, yaw = self.trajectory(time_s)
        heading = self.heading(pos, yaw, self._vehicle_ned(data) if self.facing == "drone"
                               else None)
        n, e, d = pos
        ox, oy, oz = self._origin
        data.mocap_pos[self._mocap_id] = (e + ox, n + oy, oz - d)
        data.mocap_quat[self._mocap_id] = _yaw_quat_enu(heading)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        """The marker's centre, the board's motion, and its attitude as rendered."""
        pos, vel, _ = self.trajectory(time_s)
        q = quat_enu_flu_to_ned_frd(np.array(data.mocap_quat[self._mocap_id], dtype=float))
        return BodyTruth(pos, vel, q)


def marker_rotation_ned(board_attitude_q: np.ndarray) -> np.ndarray:
    """The marker frame's axes (OpenCV's: x right, y up, z out of the face) in NED, from a
    board's truth attitude."""
    return quat_to_matrix(board_attitude_q) @ BOARD_FROM_MARKER


def marker_in_camera(board: BodyTruth, vehicle: BodyTruth,
                     camera: CameraInfo) -> tuple[np.ndarray, np.ndarray]:
    """A board's marker seen from a camera, from ground truth: the marker centre in the optical
    frame and ``rotation_cam_marker`` (as :class:`~autopilot.perception.marker.MarkerDetection`
    reports them)."""
    r_ned_body = quat_to_matrix(vehicle.attitude_q)
    r_ned_cam = r_ned_body @ camera.rotation_body_cam
    position = r_ned_cam.T @ (np.asarray(board.position_ned_m) - vehicle.position_ned_m
                              - r_ned_body @ camera.position_body_m)
    return position, r_ned_cam.T @ marker_rotation_ned(board.attitude_q)


def marker_objects(*, marker_id: int = 36, dictionary: str = "DICT_ARUCO_ORIGINAL",
                   size_m: float = 0.16, board_m: float = 0.3, path: PathName = "static",
                   speed_mps: float = 0.0, height_m: float = 1.5, start_distance_m: float = 2.0,
                   path_size_m: float = 6.0, facing: Facing = "drone",
                   yaw_deg: float | None = None, decoys: int = 0,
                   decoy_ids: Sequence[int] = (), seed: int = 0, start_delay_s: float = 0.0,
                   accel_mps2: float = 0.0, origin_north_east_m: Sequence[float] = (0.0, 0.0),
                   heading_deg: float = 0.0, name: str = "marker") -> list[ScenarioObject]:
    """The followed marker board and its decoys, for a mission's scenario.

    The board starts ``start_distance_m`` ahead of ``origin_north_east_m`` along
    ``heading_deg`` (the vehicle's start and heading), its marker's centre ``height_m`` above
    the ground, and moves along ``path`` (as the ball's paths; ``path_size_m`` sets their
    size) at ``speed_mps`` after ``start_delay_s``, reaching that speed at ``accel_mps2`` (0:
    at once). ``facing``: drone | travel | trail | fixed; ``yaw_deg`` is the face's heading when
    fixed (default: back towards the start). ``decoys`` boards with other ids of the same
    dictionary (``decoy_ids``, or drawn with ``seed``) stand still beside the path, facing the
    vehicle. The first object is the followed board, named ``name``; decoys are
    ``{name}_decoy{i}``."""
    heading = math.radians(heading_deg)
    north, east = origin_north_east_m
    start = (north + start_distance_m * math.cos(heading),
             east + start_distance_m * math.sin(heading), -height_m)
    ramp = speed_mps / accel_mps2 if accel_mps2 > 0.0 else 0.0
    trajectory = named_path(path, start, speed_mps, path_size_m, heading, seed,
                            start_delay_s, ramp, accel_m_s2=accel_mps2 or 2.0)
    fixed_yaw = heading_deg + 180.0 if yaw_deg is None else yaw_deg
    board = MarkerBoard(name, marker_id, trajectory, dictionary=dictionary, size_m=size_m,
                        board_m=board_m, facing=facing, yaw_deg=fixed_yaw)
    objects: list[ScenarioObject] = [board]
    if decoys <= 0:
        return objects
    rng = np.random.default_rng(seed + 104729)
    count = aruco_dictionary(dictionary).bytesList.shape[0]
    ids = [i for i in decoy_ids if i != marker_id]
    pool = [i for i in range(count) if i != marker_id and i not in ids]
    ids += [int(i) for i in rng.choice(pool, size=max(0, decoys - len(ids)), replace=False)]
    origin = np.array([north, east, 0.0])
    for i, decoy_id in enumerate(ids[:decoys]):
        for _ in range(100):  # beside the path, clear of the start and of the board's start
            along = trajectory(float(rng.uniform(0.0, 60.0)))[0]
            angle = rng.uniform(0.0, 2.0 * math.pi)
            pos = along + rng.uniform(0.6, 2.5) * np.array([math.cos(angle), math.sin(angle),
                                                            0.0])
            pos[2] = -float(rng.uniform(0.5, 2.5))
            if (np.linalg.norm(pos[:2] - origin[:2]) > 1.5
                    and np.linalg.norm(pos - np.asarray(start)) > 0.6):
                break
        objects.append(MarkerBoard(f"{name}_decoy{i}", decoy_id, Static(tuple(pos)),
                                   dictionary=dictionary, size_m=size_m, board_m=board_m,
                                   facing="drone"))
    return objects


# --------------------------------------------------------------------------------------------
# Calibration boards
# --------------------------------------------------------------------------------------------

CalibrationPattern = Literal["chessboard", "charuco"]

#: The printed pattern's frame in a calibration board's body frame (columns: the pattern's axes
#: in the body's FRD). The pattern frame is OpenCV's object frame as a camera in front of the
#: board reads it: x right, y down, z into the face; the body's x is the face's normal, so the
#: pattern's x is the body's left (−y), its y the body's down (+z), its z the body's back (−x).
BOARD_FROM_PATTERN = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def calibration_texture(pattern: CalibrationPattern, squares: tuple[int, int], *,
                        marker_ratio: float = 0.75, dictionary: str = "DICT_5X5_100",
                        px_per_square: int = 64, margin_squares: int = 1,
                        blur_squares: float = 0.0) -> np.ndarray:
    """A calibration board's face as a grey-scale image: ``squares`` (columns, rows) squares of
    ``px_per_square`` texels, chessboard or ChArUco (OpenCV's layout, markers of
    ``marker_ratio`` of a square from ``dictionary``), in a white margin of ``margin_squares``
    squares; the top-left square is black. ``blur_squares``: the standard deviation of a
    Gaussian blur of the print, in squares (see :class:`CalibrationBoard`).

    Square edges fall on texel boundaries at every mipmap level up to
    log2(``px_per_square``) when ``px_per_square`` is a power of two, so that OpenGL's texture
    filtering blurs them symmetrically and leaves the corners where they are."""
    cols, rows = squares
    if cols < 2 or rows < 2:
        raise ValueError(f"a calibration board needs at least 2x2 squares, got {cols}x{rows}")
    if px_per_square < 8:
        raise ValueError("px_per_square must be at least 8")
    margin = margin_squares * px_per_square
    if pattern == "chessboard":
        cells = (np.indices((rows, cols)).sum(axis=0) % 2).astype(np.uint8) * 255
        face = np.kron(cells, np.ones((px_per_square, px_per_square), np.uint8))
        image = cv2.copyMakeBorder(face, margin, margin, margin, margin, cv2.BORDER_CONSTANT,
                                   value=255)
    elif pattern == "charuco":
        if not 0.0 < marker_ratio < 1.0:
            raise ValueError(f"marker_ratio must be in (0, 1), got {marker_ratio}")
        board = charuco_board(squares, 1.0, marker_ratio, dictionary)
        size = (cols * px_per_square + 2 * margin, rows * px_per_square + 2 * margin)
        image = board.generateImage(size, marginSize=margin, borderBits=1)
    else:
        raise ValueError(f"unknown calibration pattern {pattern!r} (chessboard, charuco)")
    if blur_squares > 0.0:
        image = cv2.GaussianBlur(image, (0, 0), blur_squares * px_per_square,
                                 borderType=cv2.BORDER_REPLICATE)
    return image


def charuco_board(squares: tuple[int, int], square_m: float, marker_m_or_ratio: float,
                  dictionary: str):
    """OpenCV's ChArUco board (``cv2.aruco.CharucoBoard``: columns × rows of squares)."""
    d = aruco_dictionary(dictionary)
    needed = squares[0] * squares[1] // 2
    if d.bytesList.shape[0] < needed:
        raise ValueError(f"{dictionary} has {d.bytesList.shape[0]} markers; a "
                         f"{squares[0]}x{squares[1]} ChArUco board needs {needed}")
    return cv2.aruco.CharucoBoard(tuple(squares), square_m, marker_m_or_ratio, d)


@dataclass
class CalibrationBoard(ScenarioObject):
    """A flat camera-calibration board (chessboard or ChArUco) standing still at a pose.

    The body's origin is the centre of the pattern on the printed face; its x axis is the face's
    normal (out of the face), y right and z down as seen from behind the board (FRD), as for a
    :class:`MarkerBoard`, but ``attitude_q`` (body → NED) may tilt it any way. The pattern frame
    (OpenCV's object frame) is ``R_ned_body @ BOARD_FROM_PATTERN``; :meth:`corners_ned` gives
    where the pattern's inner corners are, in the order OpenCV's detectors report them.

    The texture has ``px_per_square`` texels a square (a power of two: see
    :func:`calibration_texture`); choose it larger than a square will appear in the image, so
    that the texture is minified (mipmapped), not magnified.

    ``blur_squares`` softens the print: a Gaussian blur of that standard deviation, in squares
    (e.g. 0.02 for ink that bleeds a little), so it scales with the board's distance, unlike
    the camera's own blur (lens, motion: see the camera's configuration). The blur is
    symmetric, so the corners stay where they are. 0 (the default): a sharp print.
    """

    name: str
    position_ned_m: tuple[float, float, float]
    attitude_q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    pattern: CalibrationPattern = "chessboard"
    squares: tuple[int, int] = (10, 7)  # columns × rows of squares
    square_m: float = 0.05
    marker_m: float | None = None  # ChArUco: the markers' side (default 0.75 of a square)
    dictionary: str = "DICT_5X5_100"
    px_per_square: int = 64
    margin_squares: int = 1  # the white margin around the pattern, in squares
    #: The print's blur (Gaussian standard deviation, in squares); see the class notes.
    blur_squares: float = 0.0
    thickness_m: float = 0.01
    board_rgba: tuple[float, float, float, float] = (0.85, 0.85, 0.85, 1.0)
    #: The face's brightness: the printed white under the scene's light (below 1 keeps the
    #: lit face from saturating).
    face_gain: float = 0.8
    moves = False
    _mocap_id: int = field(default=-1, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)

    def __post_init__(self) -> None:
        marker = 0.75 * self.square_m if self.marker_m is None else self.marker_m
        if not 0.0 < marker < self.square_m:
            raise ValueError(f"marker_m must be between 0 and square_m, got {marker}")
        self.marker_m = marker
        self.texture = calibration_texture(self.pattern, self.squares,
                                           marker_ratio=marker / self.square_m,
                                           dictionary=self.dictionary,
                                           px_per_square=self.px_per_square,
                                           margin_squares=self.margin_squares,
                                           blur_squares=self.blur_squares)
        cols, rows = self.squares
        self.face_size_m = ((cols + 2 * self.margin_squares) * self.square_m,
                            (rows + 2 * self.margin_squares) * self.square_m)

    def pattern_points_m(self) -> np.ndarray:
        """The inner corners in the pattern frame, origin at the pattern's centre, ``(N, 3)``:
        row by row from the top left for a chessboard, by id for ChArUco (OpenCV's order)."""
        cols, rows = self.squares
        ij = np.stack(np.meshgrid(np.arange(1, cols), np.arange(1, rows)), axis=-1)
        xy = ij.reshape(-1, 2) * self.square_m - np.array([cols, rows]) * self.square_m / 2
        return np.column_stack([xy, np.zeros(len(xy))])

    def rotation_ned_pattern(self) -> np.ndarray:
        """The pattern frame's axes in NED (columns)."""
        return quat_to_matrix(np.asarray(self.attitude_q, dtype=float)) @ BOARD_FROM_PATTERN

    def corners_ned(self) -> np.ndarray:
        """Where the inner corners are, local NED, ``(N, 3)`` (order of
        :meth:`pattern_points_m`)."""
        return (np.asarray(self.position_ned_m, dtype=float)
                + self.pattern_points_m() @ self.rotation_ned_pattern().T)

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        height, width = self.texture.shape
        texture = spec.add_texture(name=f"{self.name}/texture",
                                   type=mujoco.mjtTexture.mjTEXTURE_2D,
                                   width=width, height=height, nchannel=3)
        texture.data = np.repeat(self.texture[:, :, None], 3, axis=2).tobytes()
        gain = self.face_gain
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[gain, gain, gain, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        body = spec.worldbody.add_body(name=self.name, mocap=True,
                                       pos=frame.to_enu(np.asarray(self.position_ned_m)),
                                       quat=self._quat_enu())
        half_w, half_h = self.face_size_m[0] / 2.0, self.face_size_m[1] / 2.0
        # body FLU: the face's normal is +x, the face spans y (width) and z (height)
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[_PLATE_M / 2.0, half_w, half_h], pos=[-_PLATE_M / 2.0, 0.0, 0.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/board", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.thickness_m / 2.0, half_w, half_h],
                      pos=[-_PLATE_M - self.thickness_m / 2.0, 0.0, 0.0],
                      rgba=list(self.board_rgba), contype=0, conaffinity=0)

    def _quat_enu(self) -> np.ndarray:
        from drivers.sim.frames import quat_ned_frd_to_enu_flu

        return quat_ned_frd_to_enu_flu(np.asarray(self.attitude_q, dtype=float))

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._origin = tuple(frame.origin_enu_m.tolist())

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(np.asarray(self.position_ned_m, dtype=float), np.zeros(3),
                         np.asarray(self.attitude_q, dtype=float))


# --------------------------------------------------------------------------------------------
# Images on the ground (seed 000's hover target) and a ground with features
# --------------------------------------------------------------------------------------------


def image_rotation_ned(yaw_rad: float) -> np.ndarray:
    """``R_ned_image`` of an image lying face up with its top towards heading ``yaw_rad``:
    x along its columns (ψ + 90°), y down its rows (ψ + 180°), z into the ground."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class GroundImage(ScenarioObject):
    """A printed image lying flat on the ground (a thin textured plate), its top towards
    ``yaw_deg`` (NED heading), ``size_m`` wide; the height follows the image's aspect ratio.
    ``image_bgr``: the picture (OpenCV's BGR). Its truth: the image's centre on its face, and
    the heading of its top as the attitude (a yaw-only quaternion)."""

    name: str
    image_bgr: np.ndarray
    size_m: float
    north_east_m: tuple[float, float] = (0.0, 0.0)
    yaw_deg: float = 0.0
    thickness_m: float = 0.002
    max_texture_px: int = 2048
    moves: bool = False

    def __post_init__(self) -> None:
        h, w = self.image_bgr.shape[:2]
        self.height_m = self.size_m * h / w
        scale = min(1.0, self.max_texture_px / max(h, w))
        image = self.image_bgr if scale == 1.0 else cv2.resize(
            self.image_bgr, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
        # MuJoCo maps a 2D texture onto a box's +z face with its first row at the face's +y
        # edge and its columns along +x: as printed, seen from above
        self._texture = np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))

    @property
    def position_ned_m(self) -> np.ndarray:
        n, e = self.north_east_m
        return np.array([n, e, -self.thickness_m])

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        h, w = self._texture.shape[:2]
        spec.add_texture(name=f"{self.name}/texture", type=mujoco.mjtTexture.mjTEXTURE_2D,
                         width=w, height=h, nchannel=3).data = self._texture.tobytes()
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[1.0, 1.0, 1.0, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        n, e = self.north_east_m
        centre = frame.to_enu(np.array([n, e, -self.thickness_m / 2.0]))
        # the body's +x (FLU forward) along the image's columns, its +y (left) to its top
        body = spec.worldbody.add_body(name=self.name, pos=centre,
                                       quat=_yaw_quat_enu(math.radians(self.yaw_deg)
                                                          + math.pi / 2.0))
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.size_m / 2.0, self.height_m / 2.0, self.thickness_m / 2.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(self.position_ned_m, np.zeros(3),
                         quat_from_euler(0.0, 0.0, math.radians(self.yaw_deg)))


def gravel_texture(size_px: int = 1024, seed: int = 7) -> np.ndarray:
    """An outdoor ground as the down camera sees it from a few metres (RGB): soil and sparse
    grass tones varying over several scales, strewn with small stones — features everywhere,
    none regular (not a checkerboard). Tiles seamlessly (its noise wraps)."""
    rng = np.random.default_rng(seed)
    s = size_px

    def noise(cells: int) -> np.ndarray:  # smooth, wrapping value noise in [-1, 1]
        grid = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
        tiled = np.tile(grid, (3, 3))
        big = cv2.resize(tiled, (3 * s, 3 * s), interpolation=cv2.INTER_CUBIC)
        return big[s:2 * s, s:2 * s]

    field = 0.5 * noise(8) + 0.3 * noise(32) + 0.2 * noise(128)
    soil = np.array([0.40, 0.34, 0.25])
    grass = np.array([0.30, 0.38, 0.20])
    mix = np.clip(0.5 + field, 0.0, 1.0)[:, :, None]
    image = (soil * (1.0 - mix) + grass * mix) * (1.0 + 0.25 * noise(256)[:, :, None])
    image = np.clip(image * 255.0, 0, 255).astype(np.uint8)
    for _ in range(int(s * s / 900)):  # stones, a few pixels to a few centimetres across
        x, y = (int(v) for v in rng.integers(0, s, 2))
        r = float(np.exp(rng.uniform(np.log(1.5), np.log(9.0))))
        tone = float(rng.uniform(0.45, 0.8))
        colour = tuple(int(255 * tone * c) for c in (1.0, 0.96, rng.uniform(0.8, 0.92)))
        cv2.ellipse(image, (x, y), (max(1, int(r)), max(1, int(r * rng.uniform(0.5, 1.0)))),
                    float(rng.uniform(0, 180)), 0, 360, colour, -1, cv2.LINE_AA)
    return image


@dataclass
class FeatureGround(ScenarioObject):
    """Replaces the world's ground texture with :func:`gravel_texture`, each tile
    ``tile_m`` on a side (about a centimetre a texel): what an image matcher meets outdoors
    around its target. Adds no body."""

    name: str = "ground"
    tile_m: float = 10.0
    size_px: int = 1024
    seed: int = 7
    moves: bool = False

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        texture, material, plane = spec.texture("ground"), spec.material("ground"), \
            spec.geom("ground")
        if texture is None or material is None or plane is None:
            raise ValueError("the world has no textured plane named 'ground'")
        image = gravel_texture(self.size_px, self.seed)
        texture.builtin = mujoco.mjtBuiltin.mjBUILTIN_NONE
        texture.width, texture.height, texture.nchannel = self.size_px, self.size_px, 3
        texture.data = image.tobytes()
        extent = 2.0 * float(plane.size[0])
        material.texrepeat = [extent / self.tile_m, extent / self.tile_m]

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
