"""The ``image`` target kind: a known flat image printed and laid on the ground (hover_image,
seed 000), on gravel and grass."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field

from autopilot.config.base import ConfigModel, NonNegative, Positive
from autopilot.targets import TargetKind, World, register_target

if TYPE_CHECKING:
    from drivers.sim.scenario import ScenarioObject

NAME = "image"  # its section, and its body in the simulated world (ground truth: scoring only)


class ImageScenario(ConfigModel):
    """A printed image lying on the ground (hover_image), on gravel and grass."""

    file: str = "default"  # "default": the generated target; else an image file
    size_m: Annotated[float, Field(gt=0.05, le=50)] = 1.0  # printed width
    north_east_m: tuple[float, float] = (0.0, 0.0)  # its centre, from the vehicle's start
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading of its top


class ImagePerceptionConfig(ConfigModel):
    """How a known flat image (hover_image, seed 000) is found; which image, and its size, are
    the mission step's."""

    camera: str
    features: Literal["orb", "akaze"]
    reference_features: Annotated[int, Field(ge=100, le=20000)]
    frame_features: Annotated[int, Field(ge=100, le=20000)]
    reference_px: Annotated[int, Field(ge=100, le=4000)]
    ratio: Annotated[float, Field(gt=0, lt=1)]
    ransac_px: Positive
    min_inliers: Annotated[int, Field(ge=6)]
    #: frames tracked (Lucas–Kanade) between full detections; 0: a full detection every frame
    track_frames: Annotated[int, Field(ge=0, le=100)] = 0
    #: ours, or seed 000's pipeline as a baseline (autopilot bench hover_image)
    detector: Literal["ours", "seed000"] = "ours"


class ImageEstimationConfig(ConfigModel):
    #: an image lies still on the ground: how hard it may seem to move, and how fast at first
    accel_noise_m_s2: Positive = 0.3
    initial_velocity_std_m_s: Positive = 0.3
    position_noise_px: Positive  # the image centre's bearing noise
    size_noise_px: Positive  # noise of its apparent width (range noise)
    heading_noise_deg: Positive  # of the direction of its top, one detection
    #: learn the down camera's mount tilt from the image, which lies level
    #: (:mod:`autopilot.estimation.level_mount`), after this many frames, to this σ at best
    learn_mount: bool = True
    mount_min_frames: Annotated[int, Field(ge=5, le=10_000)] = 30
    mount_residual_std_deg: NonNegative = 0.1
    #: a frame implying more tilt than this is a bad pose, not the mount (the mount's own
    #: error is a degree or two; raise it for a camera bolted on by eye)
    mount_max_tilt_deg: Annotated[float, Field(gt=0.0, le=30.0)] = 5.0


def build(i: ImageScenario, world: World) -> list[ScenarioObject]:
    """The image on the ground (body ``image``), on a ground with features of its own."""
    from autopilot.perception.image_target import load_target_image
    from drivers.sim.scenario import GroundImage

    north, east = world.sim.vehicle.initial_north_east_m
    world.ground()
    return [GroundImage(NAME, load_target_image(i.file), i.size_m,
                        (north + i.north_east_m[0], east + i.north_east_m[1]), i.yaw_deg)]


KIND = register_target(TargetKind(
    NAME, scenario=ImageScenario, build=build,
    config={"perception.image": ImagePerceptionConfig, "estimation.image": ImageEstimationConfig},
    description="a known flat image on the ground (hover_image)"))
