"""The image pipeline on a synthetic view (the reference warped by the exact homography of a
known camera pose, over a textured background): the image's centre and heading in the world."""

import dataclasses
import math

import cv2
import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.perception.image_pipeline import ImagePipeline, image_heading, image_spec
from autopilot.perception.image_target import default_target_image
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.scenario import gravel_texture, image_rotation_ned

from ..factories import front_camera, vehicle_state

SIZE_M = 1.0


def _view(camera, state, centre_ned, yaw_rad):
    """What ``camera`` sees of the default target lying at ``centre_ned`` (top to ``yaw_rad``)."""
    ref = default_target_image(800)
    h, w = ref.shape[:2]
    mpp = SIZE_M / w
    corners_px = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    plane = np.column_stack([(corners_px[:, 0] + 0.5 - w / 2) * mpp,
                             (corners_px[:, 1] + 0.5 - h / 2) * mpp, np.zeros(4)])
    world = centre_ned + plane @ image_rotation_ned(yaw_rad).T
    r_ned_body = quat_to_matrix(state.attitude_q)
    cam = (world - np.asarray(state.position_ned_m)) @ r_ned_body @ camera.rotation_body_cam
    k = camera.intrinsics.matrix
    uv = (cam @ k.T)[:, :2] / cam[:, 2:3]
    homography = cv2.getPerspectiveTransform(corners_px.astype(np.float32),
                                             uv.astype(np.float32))
    background = cv2.resize(cv2.cvtColor(gravel_texture(512), cv2.COLOR_RGB2BGR), (640, 480))
    warped = cv2.warpPerspective(ref, homography, (640, 480), flags=cv2.INTER_AREA)
    mask = cv2.warpPerspective(np.full((h, w), 255, np.uint8), homography, (640, 480))
    return np.where(mask[:, :, None] > 127, warped, background)


@pytest.mark.parametrize(("altitude_m", "yaw_deg"), [(1.5, 30.0), (2.5, -120.0)])
def test_the_image_is_placed_in_the_world(altitude_m, yaw_deg):
    cfg = load_config()
    pipeline = ImagePipeline(cfg, image_spec(cfg, size_m=SIZE_M))
    camera = front_camera(pitch_down_deg=90.0)
    centre = np.array([3.0, 1.0, 0.0])
    estimate = None
    for i in range(5):
        t = 0.1 * i
        state = vehicle_state(t, pos=(2.8, 1.3, -altitude_m), yaw=0.4)
        pipeline.add_state(state)
        image = _view(camera, state, centre, math.radians(yaw_deg))
        found = pipeline.detect(image, camera, t, pipeline.hint(t, camera))
        assert found is not None
        record = pipeline.estimate(t, camera, found)
        assert record["accepted"]
        estimate = pipeline.target(t)
    assert np.linalg.norm(estimate.position_ned_m - centre) < 0.006 * altitude_m
    assert estimate.kind == "image"
    assert math.degrees(abs(math.remainder(estimate.heading_rad - math.radians(yaw_deg),
                                           2 * math.pi))) < 0.5
    record = pipeline.detection_record(0, 0.0, "down", found, None)
    assert record["detected"]
    assert len(record["corners_px"]) == 8
    assert record["radius_px"] == pytest.approx(0.5 * 320.0 * SIZE_M / altitude_m, rel=0.05)


def test_image_heading_is_the_direction_of_its_top():
    for yaw in (0.0, 0.7, -2.5):
        assert image_heading(image_rotation_ned(yaw)) == pytest.approx(yaw)
    tilted = quat_to_matrix(quat_from_euler(0.05, -0.03, 0.0)) @ image_rotation_ned(1.0)
    assert image_heading(tilted) == pytest.approx(1.0, abs=0.01)


def test_a_level_image_teaches_the_down_camera_its_mount_tilt():
    """The down camera is really turned 1.5° and −1° about its x and y axes: seen from 2 m that
    puts the image ~6 cm off. The pipeline learns the tilt from the image's pose (it lies level)
    and, once learned, places the image within 1.5 cm; its σ then carries the learned tilt's."""
    from autopilot.estimation.level_mount import LevelMountSettings, frame_tilt_rad

    cfg = load_config()
    assert cfg.estimation.image.learn_mount
    assert cfg.estimation.camera_mount_std_deg > 0
    pipeline = ImagePipeline(cfg, image_spec(cfg, size_m=SIZE_M))
    nominal = front_camera(pitch_down_deg=90.0)
    tilt = np.radians([1.5, -1.0, 0.0])
    true_camera = dataclasses.replace(
        nominal, rotation_body_cam=nominal.rotation_body_cam @ cv2.Rodrigues(tilt)[0])
    centre = np.array([3.0, 1.0, 0.0])
    rng = np.random.default_rng(3)
    frames = LevelMountSettings().min_frames + 10
    errors = []
    for i in range(frames):
        t = 0.05 * i
        roll, pitch = np.radians(rng.normal(0.0, 2.0, 2))  # the vehicle rocks as it holds
        state = vehicle_state(t, pos=(2.9, 1.1, -2.0), yaw=0.4)
        state = dataclasses.replace(state, attitude_q=quat_from_euler(roll, pitch, 0.4))
        pipeline.add_state(state)
        image = _view(true_camera, state, centre, 0.3)
        found = pipeline.detect(image, nominal, t, None)
        assert found is not None
        record = pipeline.estimate(t, nominal, found)
        # the estimate moves with the correction when it is learned: nothing is rejected
        assert record["accepted"]
        assert not record["reinitialised"] or i == 0
        # the measurement of this frame, as placed with the camera the pipeline believes in
        errors.append(np.linalg.norm(pipeline.filter._kf.x[:2] - centre[:2]))
        if i == 0:  # one frame's tilt, from the exact geometry
            r_world_body = quat_to_matrix(state.attitude_q)
            one = frame_tilt_rad(r_world_body @ nominal.rotation_body_cam,
                                 found.rotation_cam_image)
            assert np.degrees(np.abs(one[:2] - tilt[:2])).max() < 1.0
    learned = pipeline.mount.estimate()
    assert learned is not None
    assert learned.frames == frames
    assert np.allclose(learned.tilt_deg, np.degrees(tilt[:2]), atol=0.3)
    assert errors[5] > 0.04  # before: the mount's tilt, seen from 2 m
    meas = pipeline.estimate(frames * 0.05, nominal, found)["measured_position_ned_m"]
    assert np.linalg.norm(np.asarray(meas)[:2] - centre[:2]) < 0.015
    assert pipeline.navigation.attitude_std_rad < math.radians(0.5)


def test_no_mount_is_learned_where_it_is_believed_perfect():
    cfg = load_config(overrides=["estimation.camera_mount_std_deg=0"])
    assert ImagePipeline(cfg, image_spec(cfg, size_m=SIZE_M)).mount is None
