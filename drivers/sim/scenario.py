"""Scenario objects: what a mission's scenario adds to the simulated world.

A scenario object builds its bodies into the world before the model is compiled and moves them
by script during the run, without touching the airframe model. Positions are given in the local
NED frame (origin on the ground below the vehicle's start), like everything above the simulator.

The simulator calls, in order: :meth:`ScenarioObject.build` once (before compiling),
:meth:`ScenarioObject.bind` once (after), :meth:`ScenarioObject.update` before every physics
step, and :meth:`ScenarioObject.truth` whenever ground truth is sampled.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import mujoco
import numpy as np

from drivers.geometry import quat_from_euler
from drivers.sim.frames import ENU_FROM_NED, enu_to_ned, ned_to_enu, quat_ned_frd_to_enu_flu


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


@dataclass(frozen=True, slots=True)
class Circle:
    """Constant-speed horizontal circle, counter-clockwise seen from above when speed > 0."""

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
        return not isinstance(self.trajectory, Static)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._frame = frame

    def update(self, time_s: float, data: mujoco.MjData) -> None:
        pos, _, yaw = self.trajectory(time_s)
        data.mocap_pos[self._mocap_id] = self._frame.to_enu(pos)
        data.mocap_quat[self._mocap_id] = _yaw_quat_enu(yaw)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        pos, vel, yaw = self.trajectory(time_s)
        return BodyTruth(pos, vel, quat_from_euler(0.0, 0.0, yaw))


def _yaw_quat_enu(yaw_ned_rad: float) -> np.ndarray:
    return quat_ned_frd_to_enu_flu(quat_from_euler(0.0, 0.0, yaw_ned_rad))


def _pad3(size: Sequence[float]) -> list[float]:
    return [*size, *([0.0] * (3 - len(size)))]
