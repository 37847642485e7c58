"""The ``keep_out`` target kind: blue discs on the ground that every step keeps out of (seed
001's colour semantics, which it proposed and never built: a red circle is a landing area, "a
blue circle should be avoided").

No step looks for them: the kind watches over every flight (:mod:`autopilot.watch`). Its
watcher (:class:`~autopilot.perception.keep_out_map.KeepOutWatcher`) looks for discs of the
keep-out colour in every frame the running step's cameras deliver and keeps a map of the zones
seen (``perception.keep_out``); its guard (:class:`~autopilot.control.keep_out.KeepOutGuard`)
keeps every setpoint out of them (``control.keep_out``). In the simulated world
(``scenario.keep_out``) they are flat discs lying on the ground.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

from pydantic import Field

from autopilot.config.base import ColorName, ConfigModel, HsvTriple, NonNegative, Positive
from autopilot.flightlog import records as ch
from autopilot.targets import ScenarioProblem, TargetKind, World, register_target

if TYPE_CHECKING:
    from autopilot.config import AppConfig
    from drivers.sim.scenario import ScenarioObject

NAME = "keep_out"  # its section, its watcher and guard, its bodies' names (disc k: keep_out<k>)
DISC_THICKNESS_M = 0.004  # (a painted disc or a mat: thin, but above a pad's 2 mm plate)
OBSERVATIONS_TOPIC = ch.watch_topic(NAME, "discs")  # each frame's candidate discs
ZONES_TOPIC = ch.watch_topic(NAME, "zones")  # the zones that count, when they change


class KeepOutDisc(ConfigModel):
    north_east_m: tuple[float, float]  # its centre, from the vehicle's start
    radius_m: Annotated[float, Field(gt=0.05, le=10)] = 0.4


class KeepOutScenario(ConfigModel):
    """Flat discs on the ground to keep out of (seed 001: blue)."""

    discs: list[KeepOutDisc] = Field(default_factory=list)
    color: ColorName = "blue"


class KeepOutPerceptionConfig(ConfigModel):
    """How keep-out discs are found, in whatever frames the running step's cameras deliver."""

    enabled: bool = True
    color: ColorName = "blue"
    #: explicit HSV ranges instead of the colour's preset
    hsv_ranges: list[tuple[HsvTriple, HsvTriple]] | None = None
    min_area_px: Positive = 30.0  # smaller blobs are noise, or too far to place
    min_solidity: Annotated[float, Field(ge=0, le=1)] = 0.85  # blob ÷ convex hull
    open_kernel_px: Annotated[int, Field(ge=1, le=31)] = 3
    close_kernel_px: Annotated[int, Field(ge=1, le=31)] = 5
    #: on the ground: the radii a keep-out disc may have
    min_radius_m: Positive = 0.1
    max_radius_m: Positive = 2.0
    max_fit_error: Annotated[float, Field(gt=0, le=1)] = 0.12  # RMS residual ÷ radius
    min_arc_deg: Annotated[float, Field(ge=0, le=360)] = 200.0  # of its outline seen
    max_range_m: Positive = 12.0  # farther views are not placed
    confirm_after: Annotated[int, Field(ge=1, le=100)] = 3  # views before a zone counts
    merge_gap_m: NonNegative = 0.5  # a view this close to a zone's edge refines it
    memory: Annotated[float, Field(gt=0, le=1)] = 0.95  # older views' weight, per view
    every_n_frames: Annotated[int, Field(ge=1, le=100)] = 1
    use_rangefinder: bool = True  # the ground's level from it; else NED down 0


class KeepOutControlConfig(ConfigModel):
    """The guard every setpoint passes through (once a disc has been seen)."""

    enabled: bool = True
    radius_m: Positive | None = None  # every zone's radius; None: each disc's as measured
    margin_m: NonNegative = 0.5  # beyond the radius
    lookahead_s: Annotated[float, Field(gt=0, le=10)] = 1.0  # motion into a zone this soon
    #: how fast a position setpoint is taken to be flown (the vehicle's position gain; PX4's
    #: MPC_XY_P), at most max_speed_m_s
    position_gain_per_s: Positive = 1.0
    max_speed_m_s: Positive = 5.0
    push_out_speed_m_s: Positive = 0.5  # out of a zone the vehicle is inside, at least


def build(k: KeepOutScenario, world: World) -> list[ScenarioObject]:
    """The discs (bodies ``keep_out0``, ``keep_out1``, …), flat on the ground."""
    from autopilot.perception.colors import COLORS
    from drivers.sim.scenario import Geom, MocapBody, Static

    north, east = world.sim.vehicle.initial_north_east_m
    half = DISC_THICKNESS_M / 2.0
    return [MocapBody(f"{NAME}{i}", [Geom("cylinder", (d.radius_m, half), COLORS[k.color][0])],
                      Static((north + d.north_east_m[0], east + d.north_east_m[1], -half)))
            for i, d in enumerate(k.discs)]


def check(scenario) -> None:
    """Discs do not overlap one another (each is one zone)."""
    section = scenario.section(NAME)
    if section is None:
        return
    discs = section.discs
    for i, a in enumerate(discs):
        for j in range(i):
            b = discs[j]
            gap = ((a.north_east_m[0] - b.north_east_m[0]) ** 2
                   + (a.north_east_m[1] - b.north_east_m[1]) ** 2) ** 0.5
            if gap < a.radius_m + b.radius_m:
                raise ScenarioProblem((NAME, "discs", i), f"overlaps disc {j}")


def watch(config: AppConfig) -> list[object]:
    """The watcher (when ``perception.keep_out.enabled``) and its guard (when
    ``control.keep_out.enabled`` too)."""
    from autopilot.control.keep_out import GuardSettings, KeepOutGuard
    from autopilot.perception.colors import COLORS
    from autopilot.perception.keep_out import DiscAcceptance, DiscDetector, DiscSettings
    from autopilot.perception.keep_out_map import (
        KeepOutMap,
        KeepOutWatcher,
        MapSettings,
        WatcherSettings,
    )

    p = getattr(config.perception, NAME)
    c = getattr(config.control, NAME)
    if not p.enabled:
        return []
    ranges = tuple(tuple(map(tuple, r)) for r in p.hsv_ranges) if p.hsv_ranges \
        else COLORS[p.color][1]
    watcher = KeepOutWatcher(
        NAME, DiscDetector(DiscSettings(ranges, p.min_area_px, p.min_solidity, p.open_kernel_px,
                                        p.close_kernel_px)),
        DiscAcceptance(p.min_radius_m, p.max_radius_m, p.max_fit_error, p.min_arc_deg,
                       p.max_range_m),
        KeepOutMap(MapSettings(p.confirm_after, p.merge_gap_m, p.memory)),
        WatcherSettings(p.every_n_frames, p.use_rangefinder),
        observations_topic=OBSERVATIONS_TOPIC, zones_topic=ZONES_TOPIC)
    if not c.enabled:
        return [watcher]
    guard = KeepOutGuard(NAME, watcher.map.zones, GuardSettings(
        c.margin_m, c.radius_m, c.lookahead_s, c.position_gain_per_s, c.max_speed_m_s,
        c.push_out_speed_m_s))
    return [watcher, guard]


ch.register_schema(OBSERVATIONS_TOPIC, ch.record_schema(
    "KeepOutDiscs", time_s=ch.NUM, seq=ch.INT, camera=ch.STR, ground_down_m=ch.NUM,
    blobs={"type": "array", "items": {"type": "object"}}))
ch.register_schema(ZONES_TOPIC, ch.record_schema(
    "KeepOutZones", time_s=ch.NUM, zones={"type": "array", "items": {"type": "object"}}))

KIND = register_target(TargetKind(
    NAME, scenario=KeepOutScenario, build=build, check=check, watch=watch,
    config={"perception.keep_out": KeepOutPerceptionConfig,
            "control.keep_out": KeepOutControlConfig},
    description="blue discs on the ground that every step keeps out of (seed 001: blue = "
                "keep away)"))
