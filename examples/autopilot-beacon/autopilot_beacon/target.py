"""The ``beacon`` target kind: a flat coloured square on the ground.

- ``scenario.beacon`` (:class:`BeaconScenario`): where it lies in the simulated world;
- ``targets.beacon`` in the configuration (:class:`BeaconSettings`): how it is found;
- its pipeline (kind ``beacon``, :mod:`autopilot_beacon.pipeline`), registered with the
  autopilot's pipelines so that replay rebuilds it from a log.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from autopilot.targets import TargetKind, World
from drivers.sim.scenario import Geom, MocapBody, Static

BODY = "beacon"  # its body in the simulated world (ground truth: scoring only)


class BeaconScenario(BaseModel):
    """Where the beacon lies, from the vehicle's starting point."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    north_east_m: tuple[float, float] = (3.0, 2.0)
    size_m: Annotated[float, Field(gt=0.1, le=5)] = 0.6  # the square's side
    color_rgb: tuple[Annotated[float, Field(ge=0, le=1)], Annotated[float, Field(ge=0, le=1)],
                     Annotated[float, Field(ge=0, le=1)]] = (0.1, 0.75, 0.2)


class BeaconSettings(BaseModel):
    """How the beacon is found: a colour range in the down camera (OpenCV's HSV: hue 0–179)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    camera: str = "down"
    hsv_low: tuple[int, int, int] = (40, 90, 60)
    hsv_high: tuple[int, int, int] = (85, 255, 255)
    min_area_px: Annotated[int, Field(ge=1)] = 25
    #: the weight of a new fix in the position estimate (1: the newest fix alone)
    smoothing: Annotated[float, Field(gt=0, le=1)] = 0.4
    #: one fix's position error (1σ), for the estimate's covariance
    fix_noise_m: Annotated[float, Field(gt=0)] = 0.08
    #: the estimate is stale this long after the last fix
    stale_after_s: Annotated[float, Field(gt=0)] = 1.0


def build(section: BeaconScenario, world: World) -> list[MocapBody]:
    north, east = world.sim.vehicle.initial_north_east_m
    half = section.size_m / 2.0
    position = (north + section.north_east_m[0], east + section.north_east_m[1], -0.006)
    return [MocapBody(BODY, [Geom("box", (half, half, 0.005), (*section.color_rgb, 1.0))],
                      Static(position))]


TARGET = TargetKind("beacon", scenario=BeaconScenario, build=build, settings=BeaconSettings,
                    description="a flat coloured square on the ground (an example plugin's)")

from autopilot_beacon import pipeline as _pipeline  # noqa: E402,F401 (registers its kind)
