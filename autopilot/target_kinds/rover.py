"""The ``rover`` target kind: a rover driving a path with a tag on its deck and UWB anchors
aboard (land_on_rover, seed 004). The configuration's ``rover`` section is the rover as the
autopilot knows it (a scenario's rover is built to match unless it says otherwise); the
estimation's ``relative`` section is the filter fusing its measurements, ``seed004`` the
baseline's."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field, model_validator

from autopilot.config.base import ConfigModel, NonNegative, Positive
from autopilot.targets import TargetKind, World, register_target

if TYPE_CHECKING:
    from drivers.sim.scenario import ScenarioObject

NAME = "rover"  # its section, and its body in the simulated world (the deck's top centre)


class DeckTagScenario(ConfigModel):
    """The tag on the rover's deck (the nested marker pad)."""

    kind: Literal["markers"] = "markers"
    size_m: Annotated[float, Field(gt=0.1, le=5)] = 0.7
    ids: tuple[int, int, int, int, int] = (0, 1, 2, 3, 4)
    dictionary: str = "DICT_APRILTAG_36h11"

    @model_validator(mode="after")
    def _layout(self) -> DeckTagScenario:
        from autopilot.perception.pad import marker_pad_layout

        marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self


class RoverScenario(ConfigModel):
    """A rover driving a path (land_on_rover), its deck carrying the tag. Deck, tag and UWB
    anchors default to the configuration's ``rover`` section (what the autopilot knows)."""

    path: Literal["straight", "circle", "random_turns", "stop_and_go", "static"] = "straight"
    speed_mps: Annotated[float, Field(ge=0, le=5)] = 1.5
    start_north_east_m: tuple[float, float] = (6.0, 3.0)  # from the vehicle's start
    heading_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # where it drives first
    size_m: Annotated[float, Field(gt=2, le=500)] = 24.0  # circle diameter; widest random turn
    accel_mps2: Annotated[float, Field(gt=0, le=5)] = 1.0  # pulling away and braking
    deck_size_m: tuple[Annotated[float, Field(gt=0.2, le=10)],
                       Annotated[float, Field(gt=0.2, le=10)]] | None = None
    deck_height_m: Annotated[float, Field(ge=0, le=5)] | None = None
    tag: DeckTagScenario | None = None


class UwbScenario(ConfigModel):
    """The rover's UWB anchors (default: the configuration's ``rover.uwb.anchors_frd_m``) and
    the ranging's quality (default: ``sim.uwb``)."""

    anchors: list[tuple[float, float, float]] | None = None
    range_noise_m: Annotated[float, Field(ge=0, le=5)] | None = None
    dropout: Annotated[float, Field(ge=0, le=1)] | None = None
    nlos_fraction: Annotated[float, Field(ge=0, le=1)] | None = None



class RelativeEstimationConfig(ConfigModel):
    """The relative-state filter of land_on_rover (autopilot/estimation/relative.py): the drone
    relative to the rover's deck, fused from UWB ranges, the deck's tag, the rangefinder, the
    rover's own reports and the drone's velocity."""

    accel_noise_m_s2: Positive  # white acceleration beyond the modelled one (process noise)
    jerk_noise_m_s3: Positive  # how fast the rover's acceleration may change
    accel_time_constant_s: Positive  # how long its acceleration lasts (Gauss–Markov)
    yaw_accel_noise_rad_s2: Positive  # how hard its turn rate may change
    drone_velocity_noise_m_s: NonNegative  # of the drone's velocity changes (the filter's input)
    uwb_range_noise_m: Positive  # one range (σ)
    uwb_gate_chi2: Positive  # one range's innovation gate (1 dof)
    tag_pixel_noise_px: Positive  # the tag centre's bearing noise
    tag_range_noise_fraction: Positive  # the tag's range noise, a fraction of the range
    tag_heading_noise_deg: Positive
    rangefinder_noise_m: Positive
    rover_velocity_noise_m_s: Positive  # the rover's reported velocity (σ, at least)
    rover_heading_noise_deg: Positive  # its compass, each reading (σ, at least)
    compass_bias_std_deg: Positive  # its compass's slowly wandering bias (σ)
    course_noise_deg: NonNegative  # its course over the ground vs its heading (wheel slip)
    #: how far apart the rover's reported position and the drone's own may be (their two GNSS
    #: errors: a slowly wandering bias, σ per axis), and how slowly it wanders
    rough_position_std_m: tuple[Positive, Positive, Positive]
    bias_time_constant_s: Positive
    gate_chi2: Positive  # 3-dof measurements (tag, rough position)
    history_s: Annotated[float, Field(gt=0, le=5)]  # a measurement this late is still fused
    max_extrapolation_s: Positive  # the estimate is not predicted further than this


class Seed004EstimationConfig(ConfigModel):
    """Seed 004's fused filter (autopilot/estimation/seed004.py), the baseline of
    ``autopilot bench landing --strategy seed004``: its R values (each a single diagonal
    value), its timers, and what the seed does not give (Q, R_px4, R_compass, R_range)."""

    update_rate_hz: Positive
    predict_rate_hz: Positive
    r_uwb: Positive
    r_tag: Positive
    r_px4: Positive
    r_compass: Positive
    r_range: Positive
    drone_accel_var: Positive
    rover_accel_var: Positive
    yaw_rate_var: Positive
    initial_rover_std_m: Positive
    initial_velocity_std_m_s: Positive


class DeckTagConfig(ConfigModel):
    """The tag printed on the rover's deck: the nested marker pad (five markers of one
    dictionary — AprilTag families included — the small one in the centre), its top towards
    the rover's front."""

    kind: Literal["markers"]
    size_m: Annotated[float, Field(gt=0.1, le=5)]
    ids: tuple[int, int, int, int, int]
    dictionary: str

    @model_validator(mode="after")
    def _layout(self) -> DeckTagConfig:
        from autopilot.perception.pad import marker_pad_layout

        marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self


class RoverUwbConfig(ConfigModel):
    """Where the UWB anchors are on the rover (FRD from its reference point, the ground under
    the deck's centre) and the tag on the drone (FRD from its body origin)."""

    anchors_frd_m: Annotated[list[tuple[float, float, float]], Field(min_length=1,
                                                                       max_length=16)]
    tag_frd_m: tuple[float, float, float]


class RoverConfig(ConfigModel):
    """The rover land_on_rover lands on, as the autopilot knows it (a scenario's rover is built
    to match unless it says otherwise)."""

    deck_size_m: tuple[Annotated[float, Field(gt=0.2, le=10)],
                       Annotated[float, Field(gt=0.2, le=10)]]  # along the rover, across
    deck_height_m: Annotated[float, Field(ge=0, le=5)]  # its top above the reference point
    camera: str  # the camera that sees the deck's tag (pointing down)
    tag: DeckTagConfig
    uwb: RoverUwbConfig

    @model_validator(mode="after")
    def _fits(self) -> RoverConfig:
        if self.tag.size_m > min(self.deck_size_m):
            raise ValueError(f"tag.size_m ({self.tag.size_m}) is larger than the deck "
                             f"({list(self.deck_size_m)})")
        return self



def build(r: RoverScenario, world: World) -> list[ScenarioObject]:
    """The rover (body ``rover``: its truth is the deck's top centre) on its path, the UWB
    ranging's quality (``scenario.uwb``, into the simulator's configuration), and gravel
    around (the down camera needs a ground with texture)."""
    from autopilot.perception.pad import pad_texture
    from drivers.sim.rover import Rover, rover_path

    if world.config is None:
        raise ValueError("scenario.rover needs the configuration's rover section")
    known: RoverConfig = world.config.rover
    sim, u = world.sim, world.scenario.uwb
    tag = r.tag if r.tag is not None else known.tag
    north, east = sim.vehicle.initial_north_east_m
    start = (north + r.start_north_east_m[0], east + r.start_north_east_m[1], 0.0)
    path = rover_path(r.path, start, math.radians(r.heading_deg), r.speed_mps, size_m=r.size_m,
                      accel_m_s2=r.accel_mps2, seed=world.seed)
    texture, _ = pad_texture(tag.kind, tag.size_m, ids=tag.ids, dictionary=tag.dictionary)
    anchors = u.anchors if u.anchors is not None else known.uwb.anchors_frd_m
    world.sim = sim.model_copy(update={"uwb": sim.uwb.model_copy(update={
        key: value for key, value in (("range_noise_m", u.range_noise_m),
                                      ("dropout", u.dropout),
                                      ("nlos_fraction", u.nlos_fraction)) if value is not None})})
    world.ground()
    return [Rover(NAME, path,
                  deck_size_m=tuple(r.deck_size_m or known.deck_size_m),
                  deck_height_m=r.deck_height_m if r.deck_height_m is not None
                  else known.deck_height_m,
                  deck_texture_bgr=texture, tag_size_m=tag.size_m,
                  anchors_frd_m=[tuple(a) for a in anchors])]


KIND = register_target(TargetKind(
    NAME, scenario=RoverScenario, build=build,
    scenario_keys={"uwb": (UwbScenario, UwbScenario())},
    config={"estimation.relative": RelativeEstimationConfig,
            "estimation.seed004": Seed004EstimationConfig, "rover": RoverConfig},
    description="a rover driving a path, a tag on its deck and UWB anchors aboard "
                "(land_on_rover)"))
