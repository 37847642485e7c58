"""The follow controller (yaw, lateral and face modes, limits) and the follow behaviour's
handling of a lost target (hold, search, fail), with synthetic states and estimates."""

import dataclasses
import math

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status
from autopilot.behaviors.follow_ball import FollowBall, FollowBallParams, LostTargetSettings
from autopilot.control.follow import FollowController, FollowSettings, camera_depression_rad
from autopilot.estimation.target import TargetEstimate
from drivers.base import SetpointFrame

from ..factories import front_camera, vehicle_state


def _settings(mode="yaw", **kw):
    base = dict(mode=mode, standoff_m=2.0, position_gain=1.2, max_speed_m_s=5.0,
                max_vertical_speed_m_s=1.5, max_accel_m_s2=4.0,
                max_yaw_rate_rad_s=math.radians(120), altitude_floor_m=1.0)
    base.update(kw)
    return FollowSettings(**base)


CAMERA = front_camera(pitch_down_deg=5.0)


_state = vehicle_state


def _target(t, pos, vel=(0.0, 0.0, 0.0), age=0.0, stale=False, **face):
    return TargetEstimate(t, np.array(pos, float), np.array(vel, float), np.eye(6) * 0.01,
                          age, stale, 10, True, **face)


def test_depression_of_a_camera_pitched_down():
    assert math.degrees(camera_depression_rad(CAMERA)) == pytest.approx(5.0)


def test_yaw_mode_faces_the_target_and_closes_range_along_the_line_of_sight():
    ctl = FollowController(_settings("yaw"), CAMERA)
    state = _state()
    ctl.reset(state)
    target = _target(0.0, (4.0, 3.0, -1.8))  # 5 m away, ahead-right
    sp = ctl.update(0.1, state, target)  # 0.1 s later: the acceleration limit allows 0.4 m/s
    assert sp.frame is SetpointFrame.LOCAL_NED
    v = np.array(sp.velocity_m_s)
    bearing = np.array([0.8, 0.6])
    assert v[:2] @ bearing == pytest.approx(np.linalg.norm(v[:2]))  # purely radial
    assert np.linalg.norm(v) == pytest.approx(0.4, abs=1e-6)
    assert sp.yaw_rad == pytest.approx(math.atan2(3.0, 4.0))  # a heading: the bearing
    assert math.isnan(sp.yaw_rate_rad_s)


def test_yaw_mode_does_not_orbit_a_target_moving_sideways():
    ctl = FollowController(_settings("yaw", max_accel_m_s2=100.0), CAMERA)
    state = _state()
    ctl.reset(state)
    # target at the standoff straight ahead, moving east (sideways) at 2 m/s
    d = camera_depression_rad(CAMERA)
    target = _target(0.0, (2.0 * math.cos(d), 0.0, -2.0 + 2.0 * math.sin(d)), (0.0, 2.0, 0.0))
    sp = ctl.update(0.05, state, target)
    assert abs(sp.velocity_m_s[1]) < 1e-6  # no sideways flight ...
    # ... a turn: the heading leads the bearing by its rate × yaw_lead_s
    rate = 2.0 / (2.0 * math.cos(d))
    assert sp.yaw_rad == pytest.approx(_settings().yaw_lead_s * rate, rel=1e-3)


def test_yaw_mode_with_sideways_feedforward_flies_along():
    ctl = FollowController(_settings("yaw", max_accel_m_s2=100.0, sideways_feedforward=1.0),
                           CAMERA)
    state = _state()
    ctl.reset(state)
    d = camera_depression_rad(CAMERA)
    target = _target(0.0, (2.0 * math.cos(d), 0.0, -2.0 + 2.0 * math.sin(d)), (0.0, 2.0, 0.0))
    assert ctl.update(0.05, state, target).velocity_m_s[1] == pytest.approx(2.0)


def test_yaw_mode_flies_the_sideways_motion_the_yaw_cannot_follow():
    s = _settings("yaw", max_accel_m_s2=100.0)
    ctl = FollowController(s, CAMERA)
    state = _state()
    ctl.reset(state)
    # passing at the standoff at 4 m/s: a bearing rate of 2 rad/s, beyond the 60°/s the yaw
    # alone follows; the rest of the sideways speed is flown
    d = camera_depression_rad(CAMERA)
    horizontal = 2.0 * math.cos(d)
    target = _target(0.0, (horizontal, 0.0, -2.0 + 2.0 * math.sin(d)), (0.0, 4.0, 0.0))
    flown = ctl.update(0.05, state, target).velocity_m_s[1]
    assert flown == pytest.approx(4.0 - s.yaw_tracked_bearing_rate_rad_s * horizontal)


def test_yaw_mode_fallen_behind_heads_for_where_the_target_will_be():
    s = _settings("yaw", max_accel_m_s2=100.0, max_speed_m_s=20.0)
    ctl = FollowController(s, CAMERA)
    state = _state()
    ctl.reset(state)
    # 6 m ahead (4 m too far), running east at 3 m/s: aim 1 s ahead of it (the horizon)
    target = _target(0.0, (6.0, 0.0, -2.0), (0.0, 3.0, 0.0))
    sp = ctl.update(0.05, state, target)
    v = np.array(sp.velocity_m_s)
    assert math.atan2(v[1], v[0]) == pytest.approx(math.atan2(3.0, 6.0), abs=1e-6)
    assert sp.yaw_rad == pytest.approx(s.yaw_lead_s * 3.0 / 6.0, rel=1e-3)  # facing it
    # without the horizon: straight at it, the yaw alone following its sideways motion
    ctl = FollowController(_settings("yaw", max_accel_m_s2=100.0, max_speed_m_s=20.0,
                                     intercept_horizon_s=0.0), CAMERA)
    ctl.reset(state)
    assert ctl.update(0.05, state, target).velocity_m_s[1] == pytest.approx(0.0, abs=1e-9)


def test_chasing_a_turning_target_slows_to_turn_inside_it():
    # 6 m behind a target that crosses at 3 m/s: the line of sight turns at 0.5 rad/s; with
    # 1 m/s² to turn with, the vehicle closes at no more than 0.8 × 1 / 0.5 = 1.6 m/s (faster
    # it would be carried round outside the target's turn)
    s = _settings("yaw", max_accel_m_s2=1.0, max_speed_m_s=20.0)
    ctl = FollowController(s, CAMERA)
    state = _state()
    ctl.reset(state)
    target = _target(0.0, (6.0, 0.0, -2.0), (0.0, 3.0, 0.0))
    v = np.array(ctl.update(100.0, state, target).velocity_m_s)  # long after: no rate limit
    assert np.linalg.norm(v[:2]) == pytest.approx(1.6, rel=1e-6)
    # with acceleration to spare it closes as fast as its gain asks
    ctl = FollowController(_settings("yaw", max_accel_m_s2=10.0, max_speed_m_s=20.0), CAMERA)
    ctl.reset(state)
    assert np.linalg.norm(ctl.update(100.0, state, target).velocity_m_s[:2]) > 5.0


def test_face_mode_stands_in_front_of_the_face_and_turns_to_the_target():
    ctl = FollowController(_settings("face", standoff_m=1.0, max_accel_m_s2=100.0,
                                     position_gain=1.0), CAMERA)
    state = _state(pos=(0.0, 0.0, -2.0))
    ctl.reset(state)
    d = camera_depression_rad(CAMERA)
    # a marker 2 m north whose face looks west (heading −90°): its standoff point is 1 m west
    # of it; the vehicle flies there and keeps turned to the marker
    target = _target(0.0, (2.0, 0.0, -2.0), heading_rad=-math.pi / 2)
    sp = ctl.update(0.05, state, target)
    desired = np.array([2.0, -math.cos(d), -2.0 - math.sin(d)])
    assert np.allclose(ctl.desired_position_ned_m, desired)
    assert np.allclose(sp.velocity_m_s, desired - state.position_ned_m)
    assert sp.yaw_rad == pytest.approx(0.0)
    # without a known face it follows along the line of sight, like yaw mode
    ctl.reset(state)
    ctl.update(0.05, state, _target(0.0, (2.0, 0.0, -2.0)))
    assert ctl.desired_position_ned_m[1] == pytest.approx(0.0)


def test_lateral_mode_keeps_heading_and_translates():
    ctl = FollowController(_settings("lateral", max_accel_m_s2=100.0), CAMERA)
    state = _state(yaw=0.0)
    ctl.reset(state)
    target = _target(0.0, (2.0, 1.5, -1.83))  # ahead and to the right
    sp = ctl.update(0.05, state, target)
    assert sp.velocity_m_s[1] > 0.5  # translate east
    assert sp.yaw_rad == pytest.approx(0.0)  # heading held


def test_limits_speed_acceleration_yaw_rate_and_floor():
    s = _settings("yaw")
    ctl = FollowController(s, CAMERA)
    state = _state()
    ctl.reset(state)
    target = _target(0.0, (-30.0, 30.0, 5.0), (10.0, -10.0, 3.0))  # far, behind, underground
    previous = np.zeros(3)
    for k in range(1, 200):
        now = k * 0.05
        sp = ctl.update(now, state, target)
        v = np.array(sp.velocity_m_s)
        assert math.hypot(v[0], v[1]) <= s.max_speed_m_s + 1e-9
        assert abs(v[2]) <= s.max_vertical_speed_m_s + 1e-9
        assert np.linalg.norm(v - previous) <= s.max_accel_m_s2 * 0.05 + 1e-9
        assert math.isfinite(sp.yaw_rad)
        previous = v
    assert ctl.desired_position_ned_m[2] <= -s.altitude_floor_m  # never below the floor
    low = _state(pos=(0.0, 0.0, -1.0))  # at the floor, target below: no descent
    assert ctl.update(10.05, low, target).velocity_m_s[2] <= 0.0 + 1e-9


def _behavior(duration=60.0):
    lost = LostTargetSettings(lost_after_s=0.5, hold_s=1.0,
                              search_yaw_rate_rad_s=math.radians(90), timeout_s=10.0)
    return FollowBall(FollowBallParams(duration_s=duration), _settings(), lost, CAMERA, 0.2)


def test_follow_behaviour_enters_offboard_then_tracks():
    b = _behavior()
    out = b.activate(BehaviorInputs(0.0, _state()))
    assert [r.kind for r in out.requests] == [RequestKind.START_OFFBOARD]
    assert out.setpoint is not None  # hold here while OFFBOARD starts
    out = b.update(BehaviorInputs(0.1, _state(0.1), target=_target(0.1, (2.0, 0.0, -1.8))))
    assert out.status is Status.RUNNING
    assert out.phase == "tracking"


def test_lost_target_holds_then_searches_then_fails():
    b = _behavior()
    b.activate(BehaviorInputs(0.0, _state()))
    # last seen ahead-left, then nothing
    b.update(BehaviorInputs(0.1, _state(0.1), target=_target(0.1, (1.0, -2.0, -1.8))))
    gone = _target(0.7, (1.0, -2.0, -1.8), age=0.6)
    out = b.update(BehaviorInputs(0.7, _state(0.7), target=gone))
    assert out.phase == "holding"
    assert math.isfinite(out.setpoint.position_ned_m[0])  # position hold
    out = b.update(BehaviorInputs(1.8, _state(1.8), target=gone))
    assert out.phase == "searching"
    assert out.setpoint.yaw_rad == pytest.approx(math.atan2(-2.0, 1.0))  # face where it was
    facing = _state(2.5, yaw=math.atan2(-2.0, 1.0))
    out = b.update(BehaviorInputs(2.5, facing, target=gone))
    assert out.phase == "searching"
    assert out.setpoint.yaw_rate_rad_s == pytest.approx(-math.radians(90))  # sweep on, leftwards
    out = b.update(BehaviorInputs(10.8, facing, target=None))
    assert out.status is Status.FAILED
    assert "lost" in out.reason


def test_a_target_hidden_for_a_moment_is_followed_where_it_was_going_then_held():
    lost = LostTargetSettings(lost_after_s=0.5, hold_s=1.0, coast_s=2.0,
                              search_yaw_rate_rad_s=math.radians(90), timeout_s=10.0)
    b = FollowBall(FollowBallParams(duration_s=60.0), _settings(), lost, CAMERA, 0.2)
    b.activate(BehaviorInputs(0.0, _state()))
    seen = _target(1.0, (3.0, 0.0, -1.8), vel=(0.0, 1.0, 0.0))  # crossing eastwards at 1 m/s
    out = b.update(BehaviorInputs(1.0, _state(1.0), target=seen))
    assert out.phase == "tracking"
    # hidden: no usable estimate for 0.6 s, then none at all
    gone = dataclasses.replace(seen, time_s=1.6, age_s=0.6)
    out = b.update(BehaviorInputs(1.6, _state(1.6), target=gone))
    assert out.phase == "coasting"
    out = b.update(BehaviorInputs(3.0, _state(3.0), target=None))
    assert out.phase == "coasting"
    # flown as if the target were 2 m further east, where it was going
    ctl = FollowController(_settings(), CAMERA)
    ctl.reset(_state(3.0))
    expected = ctl.update(3.0, _state(3.0), dataclasses.replace(
        seen, time_s=3.0, age_s=2.0, position_ned_m=np.array([3.0, 2.0, -1.8])))
    assert out.setpoint.yaw_rad == pytest.approx(expected.yaw_rad, abs=0.05)
    assert out.setpoint.yaw_rad > 0.3  # turned east after it
    out = b.update(BehaviorInputs(3.7, _state(3.7), target=None))
    assert out.phase == "holding"  # coasted 2 s: hold, then search, as before
    out = b.update(BehaviorInputs(4.8, _state(4.8), target=None))
    assert out.phase == "searching"


def test_target_reacquired_while_searching():
    b = _behavior()
    b.activate(BehaviorInputs(0.0, _state()))
    b.update(BehaviorInputs(2.0, _state(2.0), target=None))  # lost from the start
    out = b.update(BehaviorInputs(4.0, _state(4.0), target=None))
    assert out.phase == "searching"
    out = b.update(BehaviorInputs(4.1, _state(4.1), target=_target(4.1, (2.0, 0.5, -1.8))))
    assert out.phase == "tracking"


def test_follow_ends_after_its_duration():
    b = _behavior(duration=5.0)
    b.activate(BehaviorInputs(0.0, _state()))
    out = b.update(BehaviorInputs(5.0, _state(5.0), target=_target(5.0, (2.0, 0.0, -1.8))))
    assert out.status is Status.SUCCEEDED
