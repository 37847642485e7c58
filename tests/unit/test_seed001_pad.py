"""Seed 001's pad baselines against the report's text (/work/shared/seeds/001_*.txt): the
detector's template scales (§1.3.6, §2.5) and its landing logic (§2.3, §2.5, §2.6.2)."""

import math

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, Percept, RequestKind, Status
from autopilot.behaviors.land_pad import LandPadParams, LandPadSettings
from autopilot.behaviors.land_pad_seed001 import (
    COMMAND,
    IGNORE_DISTANCE_PX,
    WAIT_S,
    Seed001LandPad,
    seed_command,
)
from autopilot.control.ardrone import ArDroneLimits, ArDroneTiltModel, Twist
from autopilot.mission import load_mission
from autopilot.perception.baselines import Seed001PadDetector
from autopilot.perception.pad import CIRCLE_BOARD_RATIO, PadDetection, pad_texture
from drivers.base import CameraInfo, CameraIntrinsics, SetpointFrame
from drivers.sim.model import camera_rotation_body

from ..factories import vehicle_state

# the shipped down camera: 640 x 480, 80° across
FX = 320.0 / math.tan(math.radians(40.0))


def _down_camera() -> CameraInfo:
    return CameraInfo("down", CameraIntrinsics(640, 480, FX, FX, 319.5, 239.5),
                      camera_rotation_body(-90.0, 0.0), np.zeros(3), 30.0)


# -- the detector: "copies will be made on various scales" ------------------------------------


def test_template_scales_cover_the_whole_descent():
    """"a single template of relatively large size will be stored locally, copies will be made
    on various scales" (§1.3.6): from above the search altitude (6 m) down to the pad filling
    the frame — the old scales (a 40-160 px disc) lost it below ~1.9 m."""
    det = Seed001PadDetector("red", 0.8)
    sizes = det.disc_sizes_px(FX, 480)
    low, high = det.height_range_m(FX, 480)
    assert high == pytest.approx(10.0)  # above land_pad's 6 m search
    assert low < 0.85  # the printed pad as tall as the frame
    assert sizes[-1] * CIRCLE_BOARD_RATIO == pytest.approx(480.0)
    ratios = np.array(sizes[1:]) / np.array(sizes[:-1])
    assert ratios.max() <= 1.25 + 1e-9  # no gap wider than the step
    # every height of the descent is within ±12 % (√1.25) of a template
    for height in np.linspace(low, high, 200):
        apparent = FX * 0.8 / height
        assert min(abs(math.log(apparent / s)) for s in sizes) <= math.log(1.25) / 2 + 1e-9


def test_the_seed_scale_step_and_threshold_are_kept():
    """The report's template test used scales [0.5, 1, 1.5, 2] (§2.4); its confidence is a
    threshold on TM_CCOEFF's best match (§2.5: ``CONFIDENCE = 53500000.0``), here per
    template energy."""
    det = Seed001PadDetector("red", 0.8)
    assert det.scale_step <= 2.0
    assert 0.0 < det.min_confidence < 1.0
    with pytest.raises(ValueError, match="scale_step"):
        Seed001PadDetector("red", 0.8, scale_step=1.0)


def _render(height_m: float, offset_px=(0.0, 0.0)) -> tuple[np.ndarray, tuple[float, float]]:
    """The printed pad on grey ground, seen straight down from ``height_m`` by the pinhole
    down camera (no lens distortion); returns the frame and the pad's true centre."""
    texture, width_m = pad_texture("circle", 0.8, color="red")
    side = max(2, round(FX * width_m / height_m))
    board = cv2_resize(texture, side)
    frame = np.full((480, 640, 3), 110, np.uint8)
    cu, cv = 319.5 + offset_px[0], 239.5 + offset_px[1]
    x0, y0 = round(cu - (side - 1) / 2.0), round(cv - (side - 1) / 2.0)
    xs, ys = slice(max(0, x0), min(640, x0 + side)), slice(max(0, y0), min(480, y0 + side))
    frame[ys, xs] = board[ys.start - y0:ys.stop - y0, xs.start - x0:xs.stop - x0]
    return frame, (x0 + (side - 1) / 2.0, y0 + (side - 1) / 2.0)


def cv2_resize(image, side):
    import cv2

    return cv2.resize(image, (side, side), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("height_m", [0.9, 1.4, 6.0])
def test_the_pad_is_found_over_the_whole_descent(height_m):
    """Below 1.7 m too (the old scales stopped at a 160 px disc)."""
    det = Seed001PadDetector("red", 0.8)
    frame, (u, v) = _render(height_m, offset_px=(37.0, -21.0))
    found = det.detect(frame, _down_camera(), 0.0)
    assert found is not None
    # the pad's centre, within a tenth of its apparent diameter (TM_CCOEFF's peak moves
    # with the mismatch between the pad's size and the nearest template's)
    assert np.hypot(found.center_px[0] - u, found.center_px[1] - v) < 0.1 * FX * 0.8 / height_m
    assert found.position_cam_m[2] == pytest.approx(height_m, rel=0.25)


def test_nothing_is_found_on_bare_ground():
    det = Seed001PadDetector("red", 0.8)
    assert det.detect(np.full((480, 640, 3), 110, np.uint8), _down_camera(), 0.0) is None


# -- the landing logic ----------------------------------------------------------------------


def test_command_is_the_reports_sign_rule_with_its_dead_band():
    """§2.6.2 (the rule of the lander's time): ``IGNORE_DISTANCE = 20``; ``if abs(difference)
    < Navigator.IGNORE_DISTANCE: return 0``; ``return 0.1 * self.getSign(difference)``."""
    assert IGNORE_DISTANCE_PX == 20.0
    assert COMMAND == 0.1
    cam = _down_camera()
    cx, cy = cam.intrinsics.cx, cam.intrinsics.cy
    assert seed_command((cx + 19.0, cy - 19.0), cam) == pytest.approx((0.0, 0.0))
    # pad to the image's right: body right; below the image centre: body back
    assert seed_command((cx + 21.0, cy), cam) == pytest.approx((0.0, 0.1))
    assert seed_command((cx + 300.0, cy + 200.0), cam) == pytest.approx((-0.1, 0.1))
    assert seed_command((cx - 25.0, cy - 25.0), cam) == pytest.approx((0.1, -0.1))


def test_commands_are_tilt_fractions_through_the_ardrone_tilt_model():
    """``/cmd_vel`` linear x/y are "the amount of tilt to apply", a fraction of the maximum
    (§3.2); zeros are the AR.Drone's hover mode (the follow baselines' model)."""
    limits = ArDroneLimits()
    model = ArDroneTiltModel(limits)
    model.step(Twist(linear_x=0.1), 0.0, 0.0, np.zeros(3))
    v = model.step(Twist(linear_x=0.1), 0.05, 0.0, np.zeros(3)).velocity_m_s
    assert v[0] == pytest.approx(9.81 * math.tan(0.1 * limits.euler_angle_max_rad) * 0.05,
                                 rel=0.02)
    t = 0.05
    for _ in range(2000):
        t += 0.05
        v = model.step(Twist(linear_x=0.1, linear_y=0.1), t, 0.0, np.zeros(3)).velocity_m_s
    terminal = limits.terminal_speed_m_s(0.1)
    assert v[:2] == pytest.approx((terminal, -terminal), rel=1e-3)  # + linear_y: left (west)
    for _ in range(10):  # hover mode: brakes to a stop
        t += 0.05
        v = model.step(Twist(), t, 0.0, np.zeros(3)).velocity_m_s
    assert v == pytest.approx((0.0, 0.0, 0.0))


def _pad_seen(t, u, v):
    det = PadDetection(t, "circle", np.array([0.0, 0.0, 6.0]), (u, v), 30.0)
    return Percept("pad", "pad", det, det, 1)


def _lander():
    return Seed001LandPad(LandPadParams(), LandPadSettings(lost_after_s=0.5), _down_camera())


def test_searches_like_ours_until_the_pad_is_seen():
    land = _lander()
    out = land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -3.0))))
    assert out.requests[0].kind is RequestKind.START_OFFBOARD
    out = land.update(BehaviorInputs(0.1, vehicle_state(0.1, pos=(0.0, 0.0, -3.0))))
    assert out.phase == "searching"
    assert out.setpoint.position_ned_m[2] == pytest.approx(-6.0)


def test_steers_toward_the_pad_then_waits_and_lands_when_it_is_below():
    """"decide when the drone should land ... publish movement commands and wait until actions
    have been performed" (§2.5); ``land()``: publish on /ardrone/land, ``rospy.sleep(1.)``."""
    land = _lander()
    cam = _down_camera().intrinsics
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    t, out = 0.0, None
    for k in range(20):  # the pad ahead and to the right: forward and right, never down
        t += 0.05
        out = land.update(BehaviorInputs(t, vehicle_state(t, pos=(0.0, 0.0, -6.0)),
                                         percept=_pad_seen(t, cam.cx + 80, cam.cy - 60)))
        assert out.phase == "steering"
        assert out.setpoint.frame is SetpointFrame.LOCAL_NED
        north, east, down = out.setpoint.velocity_m_s  # heading north: forward, right
        accel_north, accel_east, _ = out.setpoint.acceleration_m_s2
        assert accel_north > 0.0
        assert accel_east > 0.0
        if k:  # (from the vehicle's measured velocity, at rest, on the first)
            assert north > 0.0
            assert east > 0.0
        assert down == 0.0
    # below the drone: hover, wait WAIT_S, then land (never a descent of its own)
    start = t
    while True:
        t += 0.05
        out = land.update(BehaviorInputs(t, vehicle_state(t, pos=(0.0, 0.0, -6.0)),
                                         percept=_pad_seen(t, cam.cx + 5, cam.cy - 5)))
        if out.requests:
            break
        assert out.phase == "waiting"
        if t - start > 0.2:  # the hover mode has braked the slow drift to a stop
            assert out.setpoint.velocity_m_s == pytest.approx((0.0, 0.0, 0.0))
        assert t - start < WAIT_S + 0.1
    assert t - start >= WAIT_S - 1e-9
    assert out.requests[0].kind is RequestKind.LAND
    out = land.update(BehaviorInputs(t + 5.0, vehicle_state(t + 5.0, pos=(0.0, 0.0, 0.0),
                                                            armed=False, in_air=False)))
    assert out.status is Status.SUCCEEDED


def test_a_pad_leaving_the_dead_band_restarts_the_wait():
    land = _lander()
    cam = _down_camera().intrinsics
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    for k, du in enumerate([5, 5, 5, 5, 5, 5, 5, 5, 40, 5, 5, 5, 5, 5, 5, 5, 5, 5]):
        t = 0.1 * (k + 1)
        out = land.update(BehaviorInputs(t, vehicle_state(t, pos=(0.0, 0.0, -6.0)),
                                         percept=_pad_seen(t, cam.cx + du, cam.cy)))
        assert not out.requests  # never 1 s in the band without a break
    assert out.phase == "waiting"


def test_keeps_acting_on_its_last_detection_when_the_pad_is_gone():
    land = _lander()
    cam = _down_camera().intrinsics
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    land.update(BehaviorInputs(0.1, vehicle_state(0.1, pos=(0.0, 0.0, -6.0)),
                               percept=_pad_seen(0.1, cam.cx - 100, cam.cy)))
    old = _pad_seen(0.1, cam.cx - 100, cam.cy).last_detection
    gone = Percept("pad", "pad", None, old, 2)
    out = land.update(BehaviorInputs(0.2, vehicle_state(0.2, pos=(0.0, 0.0, -6.0)),
                                     percept=gone))
    assert out.phase == "steering"
    assert out.setpoint.velocity_m_s[1] < 0.0  # still left (west, heading north)


def test_the_lander_is_selectable_in_the_mission():
    plan = load_mission("land_pad", ["steps.1.land_pad.lander=seed001",
                                     "config.perception.pad.detector=seed001"])
    assert plan.steps[1].params.lander == "seed001"
    with pytest.raises(Exception, match="px4_precland"):
        load_mission("land_pad", ["steps.1.land_pad.lander=seed001",
                                  "steps.1.land_pad.method=px4_precland"])
