"""The ``ball`` target kind: a coloured ball on a path (follow_ball, seed 003), orange-ish
distractors beside it, and decoy balls crossing the line of sight (fault ``decoy_crossing``).

The ball starts ``start_distance_m`` ahead of the vehicle's starting position and heading, at
``height_m``, and (after ``start_delay_s``) moves along its path at ``speed_mps``. Distractors are
orange-ish objects that are not the ball — orange boxes, poles, bricks and discs, and spheres of
neighbouring hues — placed beside the ball's path, where the following camera will see them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
from pydantic import Field

from autopilot.config.base import ColorName, ConfigModel, HsvTriple, NonNegative, Positive
from autopilot.perception.colors import COLORS, ORANGEISH_RGBA
from autopilot.targets import TargetKind, World, register_target

if TYPE_CHECKING:
    from drivers.sim.config import SimConfig
    from drivers.sim.scenario import ScenarioObject, Trajectory

NAME = "ball"  # its section, and its body in the simulated world (ground truth: scoring only)


class BallScenario(ConfigModel):
    path: Literal["static", "circle", "figure8", "lissajous", "random_walk"] = "circle"
    speed_mps: Annotated[float, Field(ge=0, le=15)] = 1.0
    diameter_m: Annotated[float, Field(gt=0.02, le=2)] = 0.2
    color: ColorName = "orange"
    height_m: Annotated[float, Field(gt=0.1, le=50)] = 1.5  # of the ball's centre
    start_distance_m: Annotated[float, Field(gt=0.5, le=50)] = 2.0  # ahead of the vehicle
    start_delay_s: NonNegative = 0.0  # the ball waits this long before moving
    #: it gets up to speed this fast; on a random walk, its greatest acceleration
    accel_mps2: Annotated[float, Field(gt=0, le=50)] = 2.0
    size_m: Annotated[float, Field(gt=0.5, le=100)] = 8.0  # extent of the path


class BallPerceptionConfig(ConfigModel):
    camera: str
    color: ColorName
    #: Explicit HSV ranges ([[h, s, v], [h, s, v]] pairs) instead of the colour's preset.
    hsv_ranges: list[tuple[HsvTriple, HsvTriple]] | None = None
    diameter_m: Positive
    open_kernel_px: Annotated[int, Field(ge=1, le=31)]
    close_kernel_px: Annotated[int, Field(ge=1, le=31)]
    min_radius_px: Positive
    max_radius_px: Positive
    min_circularity: Annotated[float, Field(ge=0, le=1)]
    min_fill_ratio: Annotated[float, Field(ge=0, le=1)]
    min_solidity: Annotated[float, Field(ge=0, le=1)] = 0.85  # blob area / its convex hull's


def build(ball: BallScenario, world: World) -> list[ScenarioObject]:
    """The ball (body ``ball``), the scenario's ``distractors`` and the decoy balls of its
    ``decoy_crossing`` faults."""
    from drivers.sim.scenario import Geom, MocapBody

    scenario, sim = world.scenario, world.sim
    path = ball_trajectory(ball, sim, world.seed)
    objects: list[ScenarioObject] = [
        MocapBody(NAME, [Geom("sphere", (ball.diameter_m / 2.0,), COLORS[ball.color][0])], path)]
    objects += distractors(scenario.distractors, world.seed, sim, path)
    for k, fault in enumerate(f for f in scenario.faults if f.kind == "decoy_crossing"):
        color = COLORS[fault.color or ball.color][0]
        objects.append(MocapBody(f"decoy{k}_ball", [Geom(
            "sphere", (ball.diameter_m / 2.0,), color, collide=False)],
            Crossing(path, fault, sim.vehicle.initial_north_east_m)))
    return objects


class Crossing:
    """A decoy ball's path (fault ``decoy_crossing``): hidden under the ground outside the
    fault's window; within it, a straight line across the line of sight from the vehicle's
    start to where the ball is halfway through the window, ``behind_m`` beyond the ball,
    passing that point at the window's middle."""

    def __init__(self, ball: Trajectory, fault, start_north_east_m) -> None:
        self.start, self.end = fault.start_s, fault.start_s + fault.duration_s
        mid = 0.5 * (self.start + self.end)
        centre = np.asarray(ball(mid)[0], dtype=float)
        sight = centre[:2] - np.asarray(start_north_east_m, dtype=float)
        norm = float(np.linalg.norm(sight))
        sight = sight / norm if norm > 1e-6 else np.array([1.0, 0.0])
        self.mid = mid
        self.centre = centre + fault.behind_m * np.array([sight[0], sight[1], 0.0])
        self.velocity = fault.speed_m_s * np.array([-sight[1], sight[0], 0.0])
        self.hidden = np.array([self.centre[0], self.centre[1], 5.0])

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        if not self.start <= time_s < self.end:
            return self.hidden, np.zeros(3), 0.0
        return self.centre + self.velocity * (time_s - self.mid), self.velocity, 0.0


def ball_trajectory(ball: BallScenario, sim: SimConfig, seed: int) -> Trajectory:
    from drivers.sim.scenario import named_path

    yaw = math.radians(sim.vehicle.initial_yaw_deg)
    north, east = sim.vehicle.initial_north_east_m
    start = (north + ball.start_distance_m * math.cos(yaw),
             east + ball.start_distance_m * math.sin(yaw), -ball.height_m)
    return named_path(ball.path, start, ball.speed_mps, ball.size_m, yaw, seed,
                      ball.start_delay_s, ball.speed_mps / ball.accel_mps2,
                      accel_m_s2=ball.accel_mps2)


def distractors(count: int, seed: int, sim: SimConfig, path: Trajectory) -> list[ScenarioObject]:
    from drivers.sim.scenario import Geom, MocapBody, Static

    rng = np.random.default_rng(seed + 7919)
    start = np.array([*sim.vehicle.initial_north_east_m, 0.0])
    ball_start = path(0.0)[0]
    orange = ORANGEISH_RGBA[0]
    kinds = [
        ("box", [Geom("box", (0.15, 0.15, 0.15), orange, collide=False)]),
        ("pole", [Geom("cylinder", (0.06, 0.6), orange)]),
        ("red-orange ball", [Geom("sphere", (0.1,), ORANGEISH_RGBA[1])]),
        ("amber ball", [Geom("sphere", (0.1,), ORANGEISH_RGBA[2])]),
        ("brick", [Geom("box", (0.3, 0.1, 0.06), orange)]),
        ("disc", [Geom("cylinder", (0.2, 0.01), orange)]),
    ]
    objects: list[ScenarioObject] = []
    for i in range(count):
        name, geoms = kinds[i % len(kinds)]
        for _ in range(100):  # a spot beside the path, clear of the start and of the ball
            along = path(float(rng.uniform(0.0, 60.0)))[0]
            angle = rng.uniform(0.0, 2.0 * math.pi)
            offset = rng.uniform(1.5, 3.5) * np.array([math.cos(angle), math.sin(angle), 0.0])
            pos = along + offset
            pos[2] = -float(rng.uniform(0.3, 2.5))
            if (np.linalg.norm(pos[:2] - start[:2]) > 2.5
                    and np.linalg.norm(pos - ball_start) > 1.5):
                break
        objects.append(MocapBody(f"distractor{i}_{name.replace(' ', '_')}", geoms,
                                 Static(tuple(pos), float(rng.uniform(-math.pi, math.pi)))))
    return objects


KIND = register_target(TargetKind(
    NAME, scenario=BallScenario, build=build, present_by_default=True,
    #: orange-ish objects near the ball that are not the ball
    scenario_keys={"distractors": (Annotated[int, Field(ge=0, le=30)], 0)},
    config={"perception.ball": BallPerceptionConfig},
    description="a coloured ball on a path, in front of the vehicle (follow_ball)"))
