"""The ``marker`` target kind: a fiducial marker on a white board (follow_marker, seed 002:
ArUco id 36, 16 cm), moving like the ball, and decoy boards beside its path."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field, ValidationInfo, field_validator

from autopilot.config.base import ConfigModel, NonNegative, Positive
from autopilot.targets import TargetKind, World, register_target

if TYPE_CHECKING:
    from drivers.sim.scenario import ScenarioObject

NAME = "marker"  # its section, and its body in the simulated world (ground truth: scoring only)


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

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, name: str) -> str:
        from drivers.markers import aruco_dictionary_name

        aruco_dictionary_name(name)  # raises ValueError
        return name


class MarkerPerceptionConfig(ConfigModel):
    """The followed fiducial marker (seed 002: ArUco id 36, 16 cm) and how it is found."""

    camera: str
    backend: Literal["aruco", "apriltag"]
    #: OpenCV dictionary (DICT_ARUCO_ORIGINAL, DICT_4X4_50, DICT_APRILTAG_36h11, …) or an
    #: AprilTag family (tag36h11, tag25h9, tag16h5)
    dictionary: str
    id: Annotated[int, Field(ge=0)]
    size_m: Positive  # side of the black square
    corner_refinement: Literal["edges", "subpix", "apriltag", "contour", "none"]
    min_perimeter_px: Positive

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, name: str, info: ValidationInfo) -> str:
        from drivers.markers import apriltag_family_name, aruco_dictionary_name

        if info.data.get("backend") == "apriltag":
            apriltag_family_name(name)
        else:
            aruco_dictionary_name(name)
        return name


class MarkerEstimationConfig(ConfigModel):
    """Measurement noise of marker detections (the motion model is ``estimation.target``'s)."""

    pixel_noise_px: Positive  # bearing noise of the marker's centre
    size_noise_px: Positive  # noise of its side length in the image (range noise)
    heading_noise_deg: Positive  # direction of its face, one clear detection
    ambiguous_heading_noise_deg: Positive  # … when the two poses fit about equally well
    heading_accel_noise_deg_s2: Positive  # how hard the face may turn


def build(m: MarkerScenario, world: World) -> list[ScenarioObject]:
    """The marker board (body ``marker``) and the scenario's ``decoys`` (how many: ids drawn
    from its dictionary; or their ids)."""
    from drivers.sim.scenario import marker_objects

    sim, decoys = world.sim, world.scenario.decoys
    ids = list(decoys) if isinstance(decoys, list) else []
    return marker_objects(
        marker_id=m.id, dictionary=m.dictionary, size_m=m.size_m, board_m=m.board_m,
        path=m.path, speed_mps=m.speed_mps, height_m=m.height_m,
        start_distance_m=m.start_distance_m, path_size_m=m.path_size_m, facing=m.facing,
        yaw_deg=m.yaw_deg, decoys=len(ids) if ids else int(decoys), decoy_ids=ids,
        seed=world.seed, start_delay_s=m.start_delay_s, accel_mps2=m.accel_mps2,
        origin_north_east_m=sim.vehicle.initial_north_east_m,
        heading_deg=sim.vehicle.initial_yaw_deg, name=NAME)


KIND = register_target(TargetKind(
    NAME, scenario=MarkerScenario, build=build,
    config={"perception.marker": MarkerPerceptionConfig,
            "estimation.marker": MarkerEstimationConfig},
    description="a fiducial marker on a board, moving like the ball (follow_marker)"))
