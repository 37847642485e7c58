"""Scenario objects: what a mission's scenario adds to the simulated world — the common
ground (:mod:`.bodies`), scripted motions (:mod:`.paths`), marker boards (:mod:`.markers`),
calibration boards (:mod:`.calibration`), images on the ground (:mod:`.ground`).

A scenario object builds its bodies into the world before the model is compiled and moves them
by script during the run, without touching the airframe model. Positions are given in the local
NED frame (origin on the ground below the vehicle's start), like everything above the simulator.

The simulator calls, in order: :meth:`ScenarioObject.build` once (before compiling),
:meth:`ScenarioObject.bind` once (after), :meth:`ScenarioObject.update` before every physics
step that runs the flight controller or captures a sample (so every frame and ground-truth
sample shows the object exactly where its script puts it), and :meth:`ScenarioObject.truth`
whenever ground truth is sampled.

Marker boards (:class:`MarkerBoard`, built by :func:`marker_objects`) carry a square fiducial
(ArUco or AprilTag) whose texture is generated at run time from OpenCV's dictionaries.
"""

from drivers.sim.scenario.bodies import (
    GEOM_TYPES,
    BodyTruth,
    Geom,
    MocapBody,
    ScenarioObject,
    WorldFrame,
    pad3,
    yaw_quat_enu,
)
from drivers.sim.scenario.calibration import (
    BOARD_FROM_PATTERN,
    CalibrationBoard,
    CalibrationPattern,
    calibration_texture,
    charuco_board,
)
from drivers.sim.scenario.ground import (
    FeatureGround,
    GroundImage,
    gravel_texture,
    image_rotation_ned,
)
from drivers.sim.scenario.markers import (
    BOARD_FROM_MARKER,
    Facing,
    MarkerBoard,
    marker_in_camera,
    marker_objects,
    marker_rotation_ned,
    marker_texture,
)
from drivers.sim.scenario.paths import (
    Circle,
    ClosedPath,
    Delayed,
    PathName,
    RandomWalk,
    Static,
    Trajectory,
    circle,
    figure8,
    lissajous,
    named_path,
)

__all__ = [
    "BOARD_FROM_MARKER",
    "BOARD_FROM_PATTERN",
    "GEOM_TYPES",
    "BodyTruth",
    "CalibrationBoard",
    "CalibrationPattern",
    "Circle",
    "ClosedPath",
    "Delayed",
    "Facing",
    "FeatureGround",
    "Geom",
    "GroundImage",
    "MarkerBoard",
    "MocapBody",
    "PathName",
    "RandomWalk",
    "ScenarioObject",
    "Static",
    "Trajectory",
    "WorldFrame",
    "calibration_texture",
    "charuco_board",
    "circle",
    "figure8",
    "gravel_texture",
    "image_rotation_ned",
    "lissajous",
    "marker_in_camera",
    "marker_objects",
    "marker_rotation_ned",
    "marker_texture",
    "named_path",
    "pad3",
    "yaw_quat_enu"
]
