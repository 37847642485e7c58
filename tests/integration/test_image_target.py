"""The image-target detector (seed 000's hover target) on frames the simulator renders with the
realistic down camera, against ground truth: the generated target lying on the ground, seen from
1-3 m at any heading, a little tilted, on a ground with features of its own."""

import math

import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.perception.image_target import (
    ImageTargetDetector,
    ImageTargetSettings,
    default_target_image,
)
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.scenario import FeatureGround, GroundImage, image_rotation_ned
from drivers.sim.simulator import Simulator

SIZE_M = 1.0
WHERE = (3.0, 1.0)


@pytest.fixture(scope="module")
def scene():
    image = default_target_image()
    yaw_deg = 37.0
    # on gravel and grass: background features compete, as outdoors
    sim = Simulator(load_config().sim, scenario=[
        FeatureGround(), GroundImage("image", image, SIZE_M, WHERE, yaw_deg)])
    yield sim, ImageTargetDetector(image, ImageTargetSettings(size_m=SIZE_M)), yaw_deg
    sim.close()


def _truth_in_camera(sim, yaw_deg):
    camera = sim.camera_infos()["down"]
    truth = sim.ground_truth()
    r_ned_body = quat_to_matrix(truth.vehicle.attitude_q)
    to_cam = camera.rotation_body_cam.T @ r_ned_body.T
    p_image = np.asarray(truth.bodies["image"].position_ned_m)
    position = camera.rotation_body_cam.T @ (
        r_ned_body.T @ (p_image - np.asarray(truth.vehicle.position_ned_m))
        - camera.position_body_m)
    return camera, position, to_cam @ image_rotation_ned(math.radians(yaw_deg))


@pytest.mark.parametrize(("altitude_m", "heading_deg", "tolerance_m"),
                         [(1.2, 0.0, 0.005), (2.0, 120.0, 0.01), (3.0, -75.0, 0.02)])
def test_pose_of_the_image_against_truth(scene, altitude_m, heading_deg, tolerance_m):
    sim, detector, yaw_deg = scene
    rng = np.random.default_rng(int(altitude_m * 10))
    for _ in range(3):
        offset = rng.uniform(-0.3, 0.3, 2)
        tilt = np.radians(rng.uniform(-6.0, 6.0, 2))
        sim.set_vehicle_pose(np.array([WHERE[0] + offset[0], WHERE[1] + offset[1], -altitude_m]),
                             quat_from_euler(tilt[0], tilt[1], math.radians(heading_deg)))
        frame = sim.capture("down")
        camera, position, rotation = _truth_in_camera(sim, yaw_deg)
        found = detector.detect(frame.image, camera, frame.time_s)
        assert found is not None
        assert np.linalg.norm(found.position_cam_m - position) <= tolerance_m
        angle = math.degrees(math.acos(np.clip((np.trace(rotation.T @ found.rotation_cam_image)
                                                - 1.0) / 2.0, -1.0, 1.0)))
        assert angle <= 3.0
        assert found.inliers >= 30
        assert found.reprojection_error_px <= 1.5


def test_nothing_is_found_where_the_image_is_not(scene):
    sim, detector, _ = scene
    sim.set_vehicle_pose(np.array([WHERE[0] + 6.0, WHERE[1], -2.0]), quat_from_euler(0, 0, 0))
    frame = sim.capture("down")
    assert detector.detect(frame.image, sim.camera_infos()["down"], frame.time_s) is None


def test_tracked_between_full_detections_against_truth(scene):
    sim, _, yaw_deg = scene
    detector = ImageTargetDetector(default_target_image(),
                                   ImageTargetSettings(size_m=SIZE_M, track_frames=3))
    tracked = []
    for k in range(8):  # drifting 1.5 cm and turning 1° a frame
        sim.set_vehicle_pose(np.array([WHERE[0] + 0.015 * k, WHERE[1] - 0.01 * k, -2.0]),
                             quat_from_euler(0.02, -0.03, math.radians(40.0 + k)))
        frame = sim.capture("down")
        camera, position, _ = _truth_in_camera(sim, yaw_deg)
        found = detector.detect(frame.image, camera, frame.time_s)
        assert found is not None
        assert np.linalg.norm(found.position_cam_m - position) <= 0.01
        tracked.append(found.tracked)
    # a full detection, three tracked frames, a full one, three tracked, …
    assert tracked == [False, True, True, True, False, True, True, True]
