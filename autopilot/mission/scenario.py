"""The simulated world a mission flies in (``scenario:``): the shipped targets' sections
(ball, marker, image, pad, rover), the wind, the faults, and the plugins' target sections
(validated by their kinds, :mod:`autopilot.targets`). Ignored on real hardware."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from autopilot.config import (
    ColorName,
    ConfigModel,
    NonNegative,
)
from autopilot.perception.colors import COLORS
from drivers.sim.faults import Fault


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


class MarkerScenario(ConfigModel):
    """A fiducial marker on a board (seed 002: ArUco id 36, 16 cm), moving like the ball."""

    dictionary: str = "DICT_ARUCO_ORIGINAL"  # OpenCV dictionary or AprilTag family
    id: Annotated[int, Field(ge=0)] = 36
    size_m: Annotated[float, Field(gt=0.02, le=2)] = 0.16  # side of the black square
    board_m: Annotated[float, Field(gt=0.02, le=3)] = 0.3  # the white board around it
    path: Literal["static", "circle", "figure8", "lissajous", "random_walk"] = "static"
    speed_mps: Annotated[float, Field(ge=0, le=15)] = 0.0
    height_m: Annotated[float, Field(gt=0.1, le=50)] = 1.5  # of the marker's centre
    start_distance_m: Annotated[float, Field(gt=0.3, le=50)] = 2.0  # ahead of the vehicle
    start_delay_s: NonNegative = 0.0
    #: as the ball's: getting up to speed, and a random walk's greatest acceleration
    accel_mps2: Annotated[float, Field(gt=0, le=50)] = 2.0
    path_size_m: Annotated[float, Field(gt=0.5, le=100)] = 6.0  # extent of the path
    #: which way the board turns its face: to the drone, along its travel, against it (to a
    #: follower behind it), or a fixed heading (yaw_deg; default: back towards the start)
    facing: Literal["drone", "travel", "trail", "fixed"] = "drone"
    yaw_deg: float | None = None


class WindScenario(ConfigModel):
    gust_mps: NonNegative = 0.0
    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ImageScenario(ConfigModel):
    """A printed image lying on the ground (hover_image), on gravel and grass."""

    file: str = "default"  # "default": the generated target; else an image file
    size_m: Annotated[float, Field(gt=0.05, le=50)] = 1.0  # printed width
    north_east_m: tuple[float, float] = (0.0, 0.0)  # its centre, from the vehicle's start
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading of its top


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


class Scenario(ConfigModel):
    """The simulated world. Beside the shipped targets' sections (ball, marker, image, pad,
    rover), a section for each target kind a plugin registered (:mod:`autopilot.targets`),
    validated by that kind's scenario model."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)

    seed: Annotated[int, Field(ge=0)] = 0
    ball: BallScenario | None = BallScenario()  # null: no ball
    distractors: Annotated[int, Field(ge=0, le=30)] = 0  # orange-ish objects near the ball
    marker: MarkerScenario | None = None
    image: ImageScenario | None = None
    pad: PadScenario | None = None
    rover: RoverScenario | None = None
    uwb: UwbScenario = UwbScenario()
    #: decoy markers beside the marker's path: how many (ids drawn from its dictionary), or
    #: their ids; with a pad, decoy pads around it (other colours, blue first: keep away;
    #: marker pads with other ids): how many
    decoys: Annotated[int, Field(ge=0, le=30)] | list[Annotated[int, Field(ge=0)]] = 0
    wind: WindScenario = WindScenario()
    #: injected faults, each a window after the first arming (drivers/sim/faults.py)
    faults: list[Fault] = Field(default_factory=list)

    @model_validator(mode="after")
    def _target_sections(self) -> Scenario:
        from autopilot.targets import validate_sections

        validate_sections(self.__pydantic_extra__ or {}, lambda kind: kind.scenario, "scenario",
                          unknown="unknown key", also_known=list(type(self).model_fields))
        return self

    def targets(self) -> dict[str, BaseModel]:
        """The plugins' target sections this scenario has (validated), by kind."""
        return dict(self.__pydantic_extra__ or {})

    @model_validator(mode="after")
    def _faults_apply(self) -> Scenario:
        for i, f in enumerate(self.faults):
            if f.kind == "decoy_crossing" and self.ball is None:
                raise ValueError(f"faults[{i}] decoy_crossing: the scenario has no ball to cross")
            if f.kind == "rover_stop" and self.rover is None:
                raise ValueError(f"faults[{i}] rover_stop: the scenario has no rover")
            color = getattr(f, "color", None)
            if color is not None and color not in COLORS:
                raise ValueError(f"faults[{i}] decoy_crossing: unknown color {color!r} "
                                 f"(known: {', '.join(COLORS)})")
        return self

    @model_validator(mode="after")
    def _marker_dictionary(self) -> Scenario:
        if self.marker is not None:
            from drivers.markers import aruco_dictionary_name

            try:
                aruco_dictionary_name(self.marker.dictionary)
            except ValueError as exc:
                raise ValueError(f"marker.dictionary: {exc}") from None
        if self.pad is not None and isinstance(self.decoys, list):
            raise ValueError("decoys: with a pad, the number of decoy pads (not a list of ids)")
        if self.pad is not None and self.pad.kind == "markers" and self.decoys:
            from autopilot.perception.pad import marker_pad_layout

            ids = self.pad.ids
            top = max(ids) + (max(ids) - min(ids) + 1) * int(self.decoys)
            try:
                marker_pad_layout(self.pad.size_m, [top - 4, top - 3, top - 2, top - 1, top],
                                  self.pad.dictionary)
            except ValueError:
                raise ValueError(f"decoys: {self.decoys} decoy marker pads need marker ids up "
                                 f"to {top}, more than {self.pad.dictionary} has") from None
        return self
