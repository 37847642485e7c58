"""The ``pad`` target kind: a landing pad on the ground (land_pad, seed 001) — a coloured
circle or the nested marker pad — and decoy pads around it, on gravel and grass."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from autopilot.config.base import ColorName, ConfigModel, HsvTriple, Positive
from autopilot.targets import ScenarioProblem, TargetKind, World, register_target

if TYPE_CHECKING:
    from drivers.sim.scenario import ScenarioObject

NAME = "pad"  # its section, and its body in the simulated world (ground truth: scoring only)
#: decoy circle pads' colours, in order (blue first: seed 001's "keep away")
DECOY_COLORS = ("blue", "yellow", "green", "orange")


class PadScenario(ConfigModel):
    """A landing pad on the ground (land_pad): a coloured circle (``size_m`` across, on a white
    square a quarter wider) or the nested marker pad (``size_m`` square; its markers' ``ids``:
    the small centre one first)."""

    kind: Literal["circle", "markers"] = "circle"
    color: ColorName = "red"  # circle: red = land here (seed 001)
    size_m: Annotated[float, Field(gt=0.1, le=10)] = 0.8
    north_east_m: tuple[float, float] = (0.0, 0.0)  # its centre, from the vehicle's start
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading of its top
    dictionary: str = "DICT_4X4_50"  # markers
    ids: tuple[int, int, int, int, int] = (0, 1, 2, 3, 4)  # markers: centre, then the four

    @model_validator(mode="after")
    def _layout(self) -> PadScenario:
        if self.kind == "markers":
            from autopilot.perception.pad import marker_pad_layout

            marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self



class PadPerceptionConfig(ConfigModel):
    """How a landing pad (land_pad, seed 001) is found; its kind, colour and size are the
    mission step's."""

    camera: str
    #: circle pads: explicit HSV ranges instead of the step's colour's preset
    hsv_ranges: list[tuple[HsvTriple, HsvTriple]] | None = None
    min_radius_px: Positive
    max_fit_error: Annotated[float, Field(gt=0, le=0.5)]  # RMS radial residual ÷ radius
    #: circle pads with a rangefinder height: the disc fitted on the ground may be this much
    #: smaller or larger than its size (else it is something else of that colour)
    size_tolerance: Annotated[float, Field(gt=0, lt=1)]
    #: marker pads: the dictionary of its markers (their ids: the mission step's)
    backend: Literal["aruco", "apriltag"]
    dictionary: str
    min_perimeter_px: Positive
    #: ours, or seed 001's multi-scale template matching (circle pads) as a baseline
    #: (autopilot bench land_pad)
    detector: Literal["ours", "seed001"] = "ours"

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, name: str, info: ValidationInfo) -> str:
        from drivers.markers import apriltag_family_name, aruco_dictionary_name

        if info.data.get("backend") == "apriltag":
            apriltag_family_name(name)
        aruco_dictionary_name(name)
        return name


class PadEstimationConfig(ConfigModel):
    accel_noise_m_s2: Positive  # how hard the pad may move (a pad on the ground: hardly)
    initial_velocity_std_m_s: Positive = 0.5  # how fast it may be moving when first seen
    position_noise_px: Positive  # bearing noise of the pad's centre
    size_noise_px: Positive  # of its apparent size (range noise, without the rangefinder)
    height_noise_m: Positive  # of the ground's height from the rangefinder
    heading_noise_deg: Positive  # marker pads: of the direction of its top, one detection



def build(p: PadScenario, world: World) -> list[ScenarioObject]:
    """The landing pad (body ``pad``) and the scenario's ``decoys`` decoy pads around it
    (circles of other colours, or marker pads with other ids), on gravel and grass."""
    from autopilot.perception.pad import pad_texture
    from drivers.sim.scenario import GroundImage

    north, east = world.sim.vehicle.initial_north_east_m
    centre = np.array([north + p.north_east_m[0], east + p.north_east_m[1]])
    image, width = pad_texture(p.kind, p.size_m, color=p.color, ids=p.ids,
                               dictionary=p.dictionary)
    world.ground()
    objects: list[ScenarioObject] = [GroundImage(NAME, image, width, tuple(centre), p.yaw_deg)]
    rng = np.random.default_rng(world.seed + 4241)
    placed = [centre]
    start = np.array([north, east])
    for k in range(int(world.scenario.decoys)):
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


def check(scenario) -> None:
    """The scenario's ``decoys`` with a pad: a number of decoy pads, each (marker pads) with
    ids of its own from the pad's dictionary (:class:`~autopilot.targets.ScenarioProblem`)."""
    pad, decoys = scenario.pad, scenario.decoys
    if pad is None:
        return
    if isinstance(decoys, list):
        raise ScenarioProblem("decoys", "with a pad, the number of decoy pads (not a list of "
                                        "ids)")
    if pad.kind == "markers" and decoys:
        from autopilot.perception.pad import marker_pad_layout

        ids = pad.ids
        top = max(ids) + (max(ids) - min(ids) + 1) * int(decoys)
        try:
            marker_pad_layout(pad.size_m, [top - 4, top - 3, top - 2, top - 1, top],
                              pad.dictionary)
        except ValueError:
            raise ScenarioProblem("decoys", f"{decoys} decoy marker pads need marker ids up "
                                  f"to {top}, more than {pad.dictionary} has") from None


KIND = register_target(TargetKind(
    NAME, scenario=PadScenario, build=build, check=check,
    config={"perception.pad": PadPerceptionConfig, "estimation.pad": PadEstimationConfig},
    description="a landing pad on the ground: a coloured circle or nested markers (land_pad)"))
