"""The landing-pad detectors (seed 001's red pad, and the nested marker pad) on frames the
simulator renders with the realistic down camera, against ground truth: seen from high up down
to a few decimetres (the pad cut by the frame's border), a little tilted, on gravel and grass,
with decoy pads of another colour / other ids beside it that must not be taken for it."""

import math

import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.estimation.pose_history import Pose
from autopilot.perception.pad import pad_texture
from autopilot.perception.pad_pipeline import ground_fit, make_detector, pad_target
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.scenario import FeatureGround, GroundImage
from drivers.sim.simulator import Simulator

WHERE = (3.0, 1.0)
DECOY = (3.0, 5.0)  # 4 m east of the pad


def _scene(kind, size_m, decoy_kwargs):
    cfg = load_config()
    image, width = pad_texture(kind, size_m)
    decoy, decoy_width = pad_texture(kind, size_m, **decoy_kwargs)
    sim = Simulator(cfg.sim, scenario=[
        FeatureGround(), GroundImage("pad", image, width, WHERE, 23.0),
        GroundImage("decoy", decoy, decoy_width, DECOY, -40.0)])
    return cfg, sim


@pytest.fixture(scope="module")
def circle():
    cfg, sim = _scene("circle", 0.8, {"color": "blue"})
    yield sim, make_detector(cfg, pad_target("circle", "red"), 0.8)
    sim.close()


@pytest.fixture(scope="module")
def markers():
    cfg, sim = _scene("markers", 1.2, {"ids": (5, 6, 7, 8, 9)})
    yield sim, make_detector(cfg, pad_target("markers", ids=(0, 1, 2, 3, 4)), 1.2)
    sim.close()


def _look(sim, detector, north_east, height_m, rng, tilt_deg=5.0, body="pad"):
    tilt = np.radians(rng.uniform(-tilt_deg, tilt_deg, 2))
    sim.set_vehicle_pose(np.array([north_east[0], north_east[1], -height_m]),
                         quat_from_euler(tilt[0], tilt[1], rng.uniform(-math.pi, math.pi)))
    frame = sim.capture("down")
    camera = sim.camera_infos()["down"]
    truth = sim.ground_truth()
    r_ned_body = quat_to_matrix(truth.vehicle.attitude_q)
    position = camera.rotation_body_cam.T @ (
        r_ned_body.T @ (np.asarray(truth.bodies[body].position_ned_m)
                        - np.asarray(truth.vehicle.position_ned_m)) - camera.position_body_m)
    return detector.detect(frame.image, camera, frame.time_s), position


def _on_the_ground(sim, found):
    """The circle's outline laid on the ground with the vehicle's attitude and the range along
    its z axis (as the pipeline does with telemetry and the rangefinder): its centre's error
    from the pad's, and its diameter."""
    truth = sim.ground_truth()
    pose = Pose(0.0, np.asarray(truth.vehicle.position_ned_m), truth.vehicle.attitude_q)
    pad = np.asarray(truth.bodies["pad"].position_ned_m)
    r22 = quat_to_matrix(pose.attitude_q)[2, 2]
    fit = ground_fit(found, sim.camera_infos()["down"], pose,
                     (pad[2] - pose.position_ned_m[2]) / r22)
    return float(np.linalg.norm(fit.centre_ned_m[:2] - pad[:2])), fit.diameter_m


@pytest.mark.parametrize(("height_m", "lateral_m", "range_share"),
                         [(1.0, 0.01, 0.03), (3.0, 0.015, 0.04), (8.0, 0.04, 0.08)])
def test_circle_pad_against_truth(circle, height_m, lateral_m, range_share):
    sim, detector = circle
    rng = np.random.default_rng(int(height_m * 10))
    for _ in range(3):
        offset = rng.uniform(-0.2, 0.2, 2) * height_m
        found, truth = _look(sim, detector, np.add(WHERE, offset), height_m, rng)
        assert found is not None
        assert not found.clipped
        # the range from the apparent size alone (no rangefinder)
        assert abs(found.range_m / np.linalg.norm(truth) - 1.0) <= range_share
        assert found.fit_error <= 0.06
        # the outline on the ground: what the landing flies on
        error_m, diameter_m = _on_the_ground(sim, found)
        assert error_m <= lateral_m
        assert diameter_m == pytest.approx(0.8, rel=0.05)


def test_circle_pad_cut_by_the_frame_near_the_ground(circle):
    sim, detector = circle
    rng = np.random.default_rng(4)
    for _ in range(3):
        found, _ = _look(sim, detector, np.add(WHERE, rng.uniform(-0.2, 0.2, 2)), 0.45,
                             rng, tilt_deg=2.0)
        assert found is not None
        assert found.clipped
        error_m, _ = _on_the_ground(sim, found)
        assert error_m <= 0.04


def test_a_decoy_of_another_colour_is_not_the_pad(circle):
    sim, detector = circle
    found, _ = _look(sim, detector, DECOY, 2.0, np.random.default_rng(1), tilt_deg=0.0)
    assert found is None


@pytest.mark.parametrize(("height_m", "error_share"),
                         [(0.3, 0.03), (1.0, 0.01), (3.0, 0.01), (10.0, 0.015)])
def test_marker_pad_from_ten_metres_to_thirty_centimetres(markers, height_m, error_share):
    sim, detector = markers
    rng = np.random.default_rng(int(height_m * 10))
    for _ in range(2):
        spread = 0.05 if height_m < 0.5 else 0.15 * height_m
        found, truth = _look(sim, detector, np.add(WHERE, rng.uniform(-spread, spread, 2)),
                             height_m, rng)
        assert found is not None
        assert np.linalg.norm(found.position_cam_m - truth) <= error_share * height_m + 0.003
        assert set(found.ids) <= {0, 1, 2, 3, 4}
        if height_m <= 0.5:
            assert 0 in found.ids  # the small centre marker carries the last decimetres


def test_a_marker_pad_with_other_ids_is_not_the_pad(markers):
    sim, detector = markers
    found, _ = _look(sim, detector, DECOY, 3.0, np.random.default_rng(2), tilt_deg=0.0)
    assert found is None
