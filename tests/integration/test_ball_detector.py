"""The ball detector on rendered frames, scored against ground truth."""

import math

import cv2
import numpy as np
import pytest

from autopilot.perception.ball import BallDetector, BallDetectorSettings, ball_position
from autopilot.perception.colors import COLORS, ORANGEISH_RGBA
from drivers import camera_model
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.scenario import Geom, MocapBody, Static
from drivers.sim.simulator import Simulator

ORANGE_RGBA, ORANGE_HSV = COLORS["orange"]
DIAMETER = 0.2
DISTRACTORS = [
    MocapBody("box", [Geom("box", (0.15, 0.15, 0.15), ORANGE_RGBA)], Static((5.0, -2.5, -1.0))),
    MocapBody("pole", [Geom("cylinder", (0.06, 0.6), ORANGE_RGBA)], Static((5.0, 2.2, -0.6))),
    MocapBody("brick", [Geom("box", (0.3, 0.1, 0.06), ORANGE_RGBA)], Static((4.0, -1.0, -0.4))),
    MocapBody("red-orange", [Geom("sphere", (0.1,), ORANGEISH_RGBA[1])],
              Static((3.0, -1.0, -2.2))),
    MocapBody("amber", [Geom("sphere", (0.1,), ORANGEISH_RGBA[2])], Static((3.0, 1.0, -2.2))),
]


@pytest.fixture(scope="module")
def detector():
    return BallDetector(BallDetectorSettings(hsv_ranges=ORANGE_HSV, diameter_m=DIAMETER))


def _render(sim_config, ball_ned, others=(), vehicle=(0.0, 0.0, -2.0), euler=(0.0, 0.0, 0.0)):
    objects = [MocapBody("ball", [Geom("sphere", (DIAMETER / 2,), ORANGE_RGBA)],
                         Static(ball_ned)), *others]
    sim = Simulator(sim_config, scenario=objects)
    try:
        sim.set_vehicle_pose(vehicle, quat_from_euler(*euler))
        frame = sim.capture("front")
        truth = sim.ground_truth()
    finally:
        sim.close()
    cam = frame.camera
    r_wb = quat_to_matrix(truth.vehicle.attitude_q)
    p_cam = cam.rotation_body_cam.T @ (
        r_wb.T @ (np.asarray(ball_ned) - truth.vehicle.position_ned_m) - cam.position_body_m)
    return frame, camera_model.project_points(cam.intrinsics, p_cam), p_cam


@pytest.mark.parametrize(
    ("ball", "euler"),
    [
        ((2.0, 0.0, -2.0), (0, 0, 0)),
        ((2.0, 0.8, -2.3), (0, 0, 0)),
        ((4.0, -1.5, -2.5), (0.05, -0.1, 0.0)),
        ((6.0, 2.5, -1.5), (0.0, 0.0, 0.2)),
        ((1.2, 0.3, -2.2), (-0.1, 0.05, 0.0)),
        ((8.0, 0.0, -2.0), (0, 0, 0)),
    ],
)
def test_centre_and_range_against_ground_truth(sim_config, detector, ball, euler):
    frame, (u, v), p_cam = _render(sim_config, ball, DISTRACTORS, euler=euler)
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    assert math.hypot(det.u_px - u, det.v_px - v) < 2.0
    assert det.range_m == pytest.approx(float(np.linalg.norm(p_cam)), rel=0.03)
    assert np.linalg.norm(det.position_cam_m - p_cam) < 0.05 * np.linalg.norm(p_cam)
    assert det.candidates == 1  # every distractor rejected


def test_distractors_alone_give_nothing(sim_config, detector):
    frame, _, _ = _render(sim_config, (-5.0, 0.0, -2.0), DISTRACTORS)  # ball behind the camera
    assert detector.candidates(frame.image) == []
    assert detector.detect(frame.image, frame.camera, frame.time_s) is None


@pytest.mark.parametrize(("box_half_m", "box_at"), [(0.08, (4.0, 0.18, -2.18)),
                                                    (0.15, (4.0, 0.25, -2.25))])
def test_ball_merged_with_a_box_behind_it(sim_config, detector, box_half_m, box_at):
    """A box of the ball's colour overlapping it in the image, smaller and larger than it."""
    ball = (3.0, 0.0, -2.0)
    box = MocapBody("box", [Geom("box", (box_half_m,) * 3, ORANGE_RGBA)], Static(box_at))
    frame, (u, v), _ = _render(sim_config, ball, [box])
    n, _ = cv2.connectedComponents(detector.mask(frame.image))
    assert n == 2  # one merged blob
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    assert math.hypot(det.u_px - u, det.v_px - v) < 2.0


def test_ball_cut_by_the_image_border(sim_config, detector):
    # centre inside the image, a slice of the ball beyond its right edge
    # (the lens's barrel pulls the image edges in: 1.95 m east puts the centre at u ≈ 627)
    frame, (u, v), _ = _render(sim_config, (2.0, 1.95, -2.0))
    assert u < frame.camera.intrinsics.width_px
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    assert det.cut_by_border
    assert math.hypot(det.u_px - u, det.v_px - v) < 3.0


def test_window_search_matches_full_search(sim_config, detector):
    frame, (u, v), _ = _render(sim_config, (3.0, 0.5, -2.2), DISTRACTORS)
    full = detector.detect(frame.image, frame.camera, frame.time_s)
    hinted = detector.detect(frame.image, frame.camera, frame.time_s, (u + 10, v - 8), 12.0)
    assert hinted.u_px == pytest.approx(full.u_px)
    assert hinted.v_px == pytest.approx(full.v_px)


def test_red_wraps_around_hue_zero(sim_config):
    rgba, ranges = COLORS["red"]
    red = BallDetector(BallDetectorSettings(hsv_ranges=ranges, diameter_m=DIAMETER))
    objects = [MocapBody("ball", [Geom("sphere", (DIAMETER / 2,), rgba)], Static((2.5, 0.3, -2.0)))]
    sim = Simulator(sim_config, scenario=objects)
    try:
        sim.set_vehicle_pose((0.0, 0.0, -2.0), quat_from_euler(0, 0, 0))
        frame = sim.capture("front")
    finally:
        sim.close()
    assert len(ranges) == 2
    assert red.detect(frame.image, frame.camera, frame.time_s) is not None


def test_ball_position_off_axis_geometry(sim_config):
    """The sphere-image relation used for range holds away from the optical axis (the centre
    as the lens images it; the minor semi-axis of the ideal pinhole image)."""
    sim = Simulator(sim_config)
    cam = sim.cameras["front"].info
    sim.close()
    f = cam.intrinsics.fx
    for p_cam in (np.array([0.0, 0.0, 3.0]), np.array([1.2, -0.8, 2.5])):
        d = np.linalg.norm(p_cam)
        alpha = math.asin(0.1 / d)
        direction = p_cam / d
        cos_t = direction[2]
        b = f * math.sin(alpha) / math.sqrt(cos_t ** 2 - math.sin(alpha) ** 2)
        u, v = camera_model.project_points(cam.intrinsics, p_cam)
        assert np.allclose(ball_position(cam, u, v, b, 0.2), p_cam, atol=1e-9)
