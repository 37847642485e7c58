"""Turns a mission's ``scenario:`` section into the simulated world: the ball on its path, the
distractors, the marker board and its decoys, the wind and the seed. Simulator only; a real
vehicle ignores scenarios.

The ball starts ``start_distance_m`` ahead of the vehicle's starting position and heading, at
``height_m``, and (after ``start_delay_s``) moves along its path at ``speed_mps``. Distractors are
orange-ish objects that are not the ball — orange boxes, poles, bricks and discs, and spheres of
neighbouring hues — placed beside the ball's path, where the following camera will see them.
"""

from __future__ import annotations

import math

import numpy as np

from autopilot.config import RoverConfig
from autopilot.mission import BallScenario, Scenario
from autopilot.perception.colors import COLORS, ORANGEISH_RGBA
from autopilot.targets import target_kind
from drivers.sim.config import SimConfig
from drivers.sim.scenario import (
    FeatureGround,
    Geom,
    GroundImage,
    MocapBody,
    ScenarioObject,
    Static,
    Trajectory,
    marker_objects,
    named_path,
)

BALL = "ball"
MARKER = "marker"
IMAGE = "image"
PAD = "pad"
ROVER = "rover"
#: decoy circle pads' colours, in order (blue first: seed 001's "keep away")
DECOY_COLORS = ("blue", "yellow", "green", "orange")


def build_world(scenario: Scenario | None, sim: SimConfig, rover: RoverConfig | None = None
                ) -> tuple[SimConfig, list[ScenarioObject]]:
    """The simulator configuration (seed and wind from the scenario) and the scenario objects.
    ``rover``: the rover as the autopilot's configuration has it (a scenario's rover is built
    to match unless it says otherwise). Cameras that report a fitted calibration are pointed
    at it (:mod:`autopilot.sim_calibration`: fitted once, then cached)."""
    from autopilot.sim_calibration import with_fitted_calibrations

    sim = with_fitted_calibrations(sim)
    if scenario is None:
        return sim, []
    wind = sim.wind.model_copy(update={"gust_mps": scenario.wind.gust_mps,
                                       "steady_ned_m_s": scenario.wind.steady_ned_m_s})
    sim = sim.model_copy(update={"seed": scenario.seed, "wind": wind,
                                 "faults": list(scenario.faults)})
    objects: list[ScenarioObject] = []
    if scenario.ball is not None:
        path = ball_trajectory(scenario.ball, sim, scenario.seed)
        objects.append(MocapBody(BALL, [Geom("sphere", (scenario.ball.diameter_m / 2.0,),
                                             COLORS[scenario.ball.color][0])], path))
        objects += distractors(scenario, sim, path)
        for k, fault in enumerate(f for f in scenario.faults if f.kind == "decoy_crossing"):
            color = COLORS[fault.color or scenario.ball.color][0]
            objects.append(MocapBody(f"decoy{k}_ball", [Geom(
                "sphere", (scenario.ball.diameter_m / 2.0,), color, collide=False)],
                Crossing(path, fault, sim.vehicle.initial_north_east_m)))
    if scenario.marker is not None:
        objects += marker_board(scenario, sim)
    if scenario.image is not None:
        objects += ground_image(scenario, sim)
    if scenario.pad is not None:
        objects += landing_pads(scenario, sim, with_ground=scenario.image is None)
    if scenario.rover is not None:
        if rover is None:
            raise ValueError("scenario.rover needs the configuration's rover section")
        sim, built = rover_world(scenario, sim, rover)
        objects += built
    for name, section in scenario.targets().items():  # the plugins' target kinds
        kind = target_kind(name)
        if kind.build is not None:
            objects += kind.build(section, sim, scenario.seed)
    return sim, objects


def rover_world(scenario: Scenario, sim: SimConfig,
                known: RoverConfig) -> tuple[SimConfig, list[ScenarioObject]]:
    """The rover (body ``rover``: its truth is the deck's top centre) on its path, the UWB
    ranging's quality, and gravel around (the down camera needs a ground with texture)."""
    from autopilot.perception.pad import pad_texture
    from drivers.sim.rover import Rover, rover_path

    r, u = scenario.rover, scenario.uwb
    tag = r.tag if r.tag is not None else known.tag
    north, east = sim.vehicle.initial_north_east_m
    start = (north + r.start_north_east_m[0], east + r.start_north_east_m[1], 0.0)
    path = rover_path(r.path, start, math.radians(r.heading_deg), r.speed_mps, size_m=r.size_m,
                      accel_m_s2=r.accel_mps2, seed=scenario.seed)
    texture, _ = pad_texture(tag.kind, tag.size_m, ids=tag.ids, dictionary=tag.dictionary)
    anchors = u.anchors if u.anchors is not None else known.uwb.anchors_frd_m
    uwb = sim.uwb.model_copy(update={
        key: value for key, value in (("range_noise_m", u.range_noise_m),
                                      ("dropout", u.dropout),
                                      ("nlos_fraction", u.nlos_fraction)) if value is not None})
    body = Rover(ROVER, path,
                 deck_size_m=tuple(r.deck_size_m or known.deck_size_m),
                 deck_height_m=r.deck_height_m if r.deck_height_m is not None
                 else known.deck_height_m,
                 deck_texture_bgr=texture, tag_size_m=tag.size_m,
                 anchors_frd_m=[tuple(a) for a in anchors])
    objects: list[ScenarioObject] = [body]
    if scenario.image is None and scenario.pad is None:
        objects.insert(0, FeatureGround(seed=scenario.seed + 7))
    return sim.model_copy(update={"uwb": uwb}), objects


def landing_pads(scenario: Scenario, sim: SimConfig, *,
                 with_ground: bool = True) -> list[ScenarioObject]:
    """The landing pad (body ``pad``) and ``scenario.decoys`` decoy pads around it (circles of
    other colours, or marker pads with other ids), on gravel and grass."""
    from autopilot.perception.pad import pad_texture

    p = scenario.pad
    north, east = sim.vehicle.initial_north_east_m
    centre = np.array([north + p.north_east_m[0], east + p.north_east_m[1]])
    image, width = pad_texture(p.kind, p.size_m, color=p.color, ids=p.ids,
                               dictionary=p.dictionary)
    objects: list[ScenarioObject] = [FeatureGround(seed=scenario.seed + 7)] if with_ground else []
    objects.append(GroundImage(PAD, image, width, tuple(centre), p.yaw_deg))
    rng = np.random.default_rng(scenario.seed + 4241)
    placed = [centre]
    start = np.array([north, east])
    for k in range(int(scenario.decoys)):
        if p.kind == "circle":
            colors = [c for c in DECOY_COLORS if c != p.color]
            kwargs = {"color": colors[k % len(colors)]}
        else:
            span = max(p.ids) - min(p.ids) + 1  # ids that are not the pad's
            kwargs = {"ids": tuple(i + span * (k + 1) for i in p.ids),
                      "dictionary": p.dictionary}
        decoy, decoy_width = pad_texture(p.kind, p.size_m, **kwargs)
        spot = centre
        for _ in range(200):  # clear of the pad, the other decoys and the take-off spot
            angle = rng.uniform(0.0, 2.0 * math.pi)
            spot = centre + rng.uniform(1.3, 3.0) * width * np.array(
                [math.cos(angle), math.sin(angle)])
            if all(np.linalg.norm(spot - q) > 1.3 * width for q in placed) and \
                    np.linalg.norm(spot - start) > 0.8 + width / 2.0:
                break
        placed.append(spot)
        objects.append(GroundImage(f"decoy{k}_pad", decoy, decoy_width, tuple(spot),
                                   float(rng.uniform(-180.0, 180.0))))
    return objects


def ground_image(scenario: Scenario, sim: SimConfig) -> list[ScenarioObject]:
    """The image on the ground (body ``image``), on a ground with features of its own."""
    from autopilot.perception.image_target import load_target_image

    i = scenario.image
    north, east = sim.vehicle.initial_north_east_m
    return [FeatureGround(seed=scenario.seed + 7),
            GroundImage(IMAGE, load_target_image(i.file), i.size_m,
                        (north + i.north_east_m[0], east + i.north_east_m[1]), i.yaw_deg)]


def marker_board(scenario: Scenario, sim: SimConfig) -> list[ScenarioObject]:
    """The marker board (body ``marker``) and its decoys."""
    m = scenario.marker
    decoys = scenario.decoys
    ids = list(decoys) if isinstance(decoys, list) else []
    return marker_objects(
        marker_id=m.id, dictionary=m.dictionary, size_m=m.size_m, board_m=m.board_m,
        path=m.path, speed_mps=m.speed_mps, height_m=m.height_m,
        start_distance_m=m.start_distance_m, path_size_m=m.path_size_m, facing=m.facing,
        yaw_deg=m.yaw_deg, decoys=len(ids) if ids else int(decoys), decoy_ids=ids,
        seed=scenario.seed, start_delay_s=m.start_delay_s, accel_mps2=m.accel_mps2,
        origin_north_east_m=sim.vehicle.initial_north_east_m,
        heading_deg=sim.vehicle.initial_yaw_deg, name=MARKER)


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
    yaw = math.radians(sim.vehicle.initial_yaw_deg)
    north, east = sim.vehicle.initial_north_east_m
    start = (north + ball.start_distance_m * math.cos(yaw),
             east + ball.start_distance_m * math.sin(yaw), -ball.height_m)
    return named_path(ball.path, start, ball.speed_mps, ball.size_m, yaw, seed,
                      ball.start_delay_s, ball.speed_mps / ball.accel_mps2,
                      accel_m_s2=ball.accel_mps2)


def distractors(scenario: Scenario, sim: SimConfig, path: Trajectory) -> list[ScenarioObject]:
    rng = np.random.default_rng(scenario.seed + 7919)
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
    for i in range(scenario.distractors):
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
