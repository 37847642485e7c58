"""The seed reports' follow rules (seeds 001 and 003: the ball; seed 002: the marker) against
their texts, and the AR.Drone tilt model they are flown through.

Each rule test quotes the seed's line it checks. The seeds command an AR.Drone through
ardrone_autonomy's ``cmd_vel``: fractions of the maximum tilt (linear.x/y), climb rate (linear.z)
and yaw rate (angular.z), not velocities."""

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, Percept
from autopilot.behaviors.follow_ball import (
    FollowBall,
    FollowBallParams,
    LostTargetSettings,
    Seed001Rule,
    Seed003Rule,
)
from autopilot.behaviors.follow_marker import Seed002Rule
from autopilot.control.ardrone import GRAVITY_M_S2, ArDroneLimits, ArDroneTiltModel, Twist
from autopilot.control.follow import FollowSettings
from drivers.base import SetpointFrame

from ..factories import front_camera, vehicle_state

DT = 1.0 / 30.0  # the runtime's control tick


# -- the AR.Drone's limits and tilt model ---------------------------------------------------

def test_limits_are_the_sdk_indoor_defaults():
    lim = ArDroneLimits()
    # config_keys.h: MAX_EULER_ANGLES_REF (12000.0f * MDEG_TO_RAD); the SDK's 2.0943999e-01
    assert lim.euler_angle_max_rad == pytest.approx(math.radians(12.0), rel=1e-5)
    # default_control_vz_max (700.0f), in mm/s
    assert lim.control_vz_max_m_s == pytest.approx(0.700)
    # default_control_yaw (100000.0f * MDEG_TO_RAD), per second
    assert lim.control_yaw_rad_s == pytest.approx(math.radians(100.0))
    assert lim.drag_per_s == pytest.approx(0.58)  # tum_ardrone's c1
    assert lim.time_constant_s == pytest.approx(1.0 / 0.58)


def _fly(model, twist, seconds, yaw=0.0, t0=0.0, vel=(0.0, 0.0, 0.0)):
    sp = None
    for k in range(round(seconds / DT) + 1):
        sp = model.step(twist, t0 + k * DT, yaw, np.array(vel))
    return sp


def test_tilt_settles_at_the_drag_terminal_speed():
    model = ArDroneTiltModel()
    sp = _fly(model, Twist(linear_x=0.5), 20.0)  # half tilt: 6° forward, facing north
    expected = GRAVITY_M_S2 * math.tan(math.radians(6.0)) / 0.58  # 1.78 m/s
    assert sp.velocity_m_s[0] == pytest.approx(expected, rel=1e-3)
    assert sp.velocity_m_s[1] == pytest.approx(0.0, abs=1e-9)
    assert ArDroneLimits().terminal_speed_m_s(1.0) == pytest.approx(3.59, abs=0.01)
    assert sp.frame is SetpointFrame.LOCAL_NED
    assert not np.isfinite(sp.position_ned_m).any()


def test_tilt_response_has_the_drag_time_constant():
    model = ArDroneTiltModel()
    tau = 1.0 / 0.58
    v_end = ArDroneLimits().terminal_speed_m_s(1.0)
    sp = _fly(model, Twist(linear_x=1.0), 0.0)
    # from rest the acceleration is g·tan(12°): fed forward to our vehicle at once
    assert sp.velocity_m_s[0] == 0.0
    assert sp.acceleration_m_s2[0] == pytest.approx(
        GRAVITY_M_S2 * math.tan(math.radians(12)), rel=1e-5)
    model = ArDroneTiltModel()
    for k in range(200):
        sp = model.step(Twist(linear_x=1.0), k * DT, 0.0, np.zeros(3))
        t = k * DT
        assert sp.velocity_m_s[0] == pytest.approx(v_end * (1 - math.exp(-t / tau)), rel=1e-6,
                                                   abs=1e-9)
    # one time constant: 63 % of the way
    model = ArDroneTiltModel()
    _fly(model, Twist(linear_x=1.0), 0.0)
    sp = model.step(Twist(linear_x=1.0), tau, 0.0, np.zeros(3))
    assert sp.velocity_m_s[0] == pytest.approx(v_end * (1 - math.exp(-1)), rel=1e-6)


def test_axes_signs_and_units_of_the_twist():
    lim = ArDroneLimits()
    # +linear.x forward: facing east (yaw 90°), the drone speeds up eastward
    sp = _fly(ArDroneTiltModel(), Twist(linear_x=1.0), 2.0, yaw=math.pi / 2)
    assert sp.velocity_m_s[1] > 1.0
    assert abs(sp.velocity_m_s[0]) < 1e-9
    # +linear.y left: facing north, westward
    sp = _fly(ArDroneTiltModel(), Twist(linear_y=1.0), 2.0)
    assert sp.velocity_m_s[1] < -1.0
    assert abs(sp.velocity_m_s[0]) < 1e-9
    # +linear.z up, a fraction of control_vz_max: 0.5 → 0.35 m/s up (NED down −0.35)
    sp = _fly(ArDroneTiltModel(), Twist(linear_z=0.5), 0.0)
    assert sp.velocity_m_s[2] == pytest.approx(-0.35)
    # +angular.z turns left: a negative (anticlockwise) yaw rate in FRD, of control_yaw
    sp = _fly(ArDroneTiltModel(), Twist(angular_z=0.5), 0.0)
    assert sp.yaw_rate_rad_s == pytest.approx(-0.5 * lim.control_yaw_rad_s)
    # the driver clamps each component to ±1
    fast = _fly(ArDroneTiltModel(), Twist(linear_x=3.0, linear_z=-4.0), 3.0)
    full = _fly(ArDroneTiltModel(), Twist(linear_x=1.0, linear_z=-1.0), 3.0)
    assert np.allclose(fast.velocity_m_s, full.velocity_m_s)
    assert full.velocity_m_s[2] == pytest.approx(0.7)


def test_model_starts_from_the_vehicle_velocity_then_integrates():
    model = ArDroneTiltModel()
    level = Twist(angular_x=1.0, angular_y=1.0)  # zero, auto-hover disabled: it coasts
    sp = model.step(level, 0.0, 0.0, np.array([2.0, 0.0, 0.3]))
    assert sp.velocity_m_s[0] == pytest.approx(2.0)
    # later telemetry does not reset it: the drag alone slows it, with its time constant
    sp = model.step(level, 1.0 / 0.58, 0.0, np.array([9.0, 9.0, 9.0]))
    assert sp.velocity_m_s[0] == pytest.approx(2.0 / math.e)


def test_zero_twist_is_the_auto_hover_which_brakes_to_a_stop():
    assert Twist().auto_hover
    assert not Twist(angular_x=1.0, angular_y=1.0).auto_hover
    model = ArDroneTiltModel()
    speeds = []
    for k in range(90):
        sp = model.step(Twist(), k * DT, 0.0, np.array([3.0, -1.0, 0.0]))
        speeds.append(float(np.hypot(*sp.velocity_m_s[:2])))
        assert sp.velocity_m_s[2] == 0.0
        assert sp.yaw_rate_rad_s == 0.0
    # braking at full tilt plus drag: from 3.16 m/s stopped within about a second, never
    # reversed, and faster than drag alone
    assert all(b <= a for a, b in itertools.pairwise(speeds))
    a_max = GRAVITY_M_S2 * math.tan(math.radians(12.0))
    k = 0.58
    stop_s = math.log(1 + k * math.hypot(3.0, 1.0) / a_max) / k
    assert speeds[math.ceil(stop_s / DT) + 1] == 0.0
    assert speeds[math.floor(stop_s / DT) - 1] > 0.0


# -- seed 001 -------------------------------------------------------------------------------

R_STAR = 20.0  # seed 001: RADIUS = 20


def _seed001(lateral):
    cam = front_camera()
    return Seed001Rule(cam, R_STAR, lateral), cam.intrinsics.cx, cam.intrinsics.cy


def test_seed001_lateral_gains_from_its_text():
    rule, cx, cy = _seed001(lateral=True)
    # ball 50 px left, 40 px low, 2 px small (too far)
    tw = rule.twist(cx - 50, cy + 40, R_STAR - 2)
    # "radius_diff = Navigator.RADIUS - self.lastCircle.radius";
    # "return difference / Navigator.MAX_X_SPEED_DIFF" with "MAX_X_SPEED_DIFF = 5.0"
    assert tw.linear_x == pytest.approx(2 / 5.0)
    # "image_diff_x = Navigator.CENTER[0] - self.lastCircle.x_loc";
    # "return difference / Navigator.MAX_Y_SPEED_DIFF" with "MAX_Y_SPEED_DIFF = 100.0"
    assert tw.linear_y == pytest.approx(50 / 100.0)
    # "image_diff_y = Navigator.CENTER[1] - self.lastCircle.y_loc";
    # "return difference / Navigator.SCALAR_Z_SPEED" with "SCALAR_Z_SPEED = 25.0"
    assert tw.linear_z == pytest.approx(-40 / 25.0)  # beyond full scale: the driver clamps
    assert tw.angular_z == 0.0
    # "twist.angular.x = 1.0 # Disable hover mode", "twist.angular.y = 1.0"
    assert (tw.angular_x, tw.angular_y) == (1.0, 1.0)
    assert not tw.auto_hover


def test_seed001_yaw_mode_turns_instead_of_strafing():
    rule, cx, cy = _seed001(lateral=False)
    tw = rule.twist(cx - 30, cy, R_STAR)
    # "Left/Right rotation speed is maximised at pixel dx = 100": "MAX_Z_ROTATION_DIFF = 100.0"
    assert tw.angular_z == pytest.approx(30 / 100.0)
    assert tw.linear_y == 0.0
    assert tw.linear_x == 0.0
    assert tw.linear_z == 0.0


def test_seed001_dead_bands():
    rule, cx, cy = _seed001(lateral=True)
    # "IGNORE_DISTANCE = 5": "if abs(difference) < Navigator.IGNORE_DISTANCE: return 0"
    assert rule.twist(cx - 4.9, cy + 4.9, R_STAR).linear_y == 0.0
    assert rule.twist(cx - 4.9, cy + 4.9, R_STAR).linear_z == 0.0
    assert rule.twist(cx - 5.0, cy, R_STAR).linear_y == pytest.approx(0.05)
    # "IGNORE_RADIUS = 1"
    assert rule.twist(cx, cy, R_STAR - 0.9).linear_x == 0.0
    assert rule.twist(cx, cy, R_STAR + 1.0).linear_x == pytest.approx(-0.2)


def _ball(u, v, r):
    return SimpleNamespace(u_px=u, v_px=v, radius_px=r)


def _inputs(t, det=None, last=None, seq=0, state=None, kind="ball"):
    percept = Percept(kind, kind, detection=det, last_detection=last if last is not None
                      else det, frame_seq=seq)
    return BehaviorInputs(now_s=t, state=state or vehicle_state(t), percept=percept,
                          percepts=(percept,))


def test_seed001_flies_its_last_circle_through_the_tilt_model():
    rule, cx, cy = _seed001(lateral=True)
    # the ball lost: "self.lastCircle = data" is only written when a circle arrives
    ball = _ball(cx, cy, R_STAR - 5)  # too far: full forward tilt
    sp0 = rule.command(_inputs(0.0, det=None, last=ball))
    assert sp0.frame is SetpointFrame.LOCAL_NED
    assert sp0.velocity_m_s[0] == 0.0  # a tilt, not a velocity: it starts from rest
    assert sp0.acceleration_m_s2[0] == pytest.approx(
        GRAVITY_M_S2 * math.tan(math.radians(12)), rel=1e-5)
    sp1 = rule.command(_inputs(1.0, det=None, last=ball))
    assert sp1.velocity_m_s[0] == pytest.approx(
        ArDroneLimits().terminal_speed_m_s() * (1 - math.exp(-0.58)))
    # before any circle: its initial Circle(320, 180, 20), the target itself — level, coasting
    fresh, _, _ = _seed001(lateral=True)
    sp = fresh.command(_inputs(0.0, state=vehicle_state(0.0, vel=(1.0, 0.0, 0.0))))
    assert sp.velocity_m_s[0] == pytest.approx(1.0)
    assert sp.acceleration_m_s2[0] < 0


def test_seed001_lateral_toggle_switches_the_rule():
    settings = FollowSettings(mode="yaw", standoff_m=2.0, position_gain=1.0,
                              max_speed_m_s=5.0, max_vertical_speed_m_s=1.5, max_accel_m_s2=4.0,
                              max_yaw_rate_rad_s=2.0, altitude_floor_m=1.0)
    beh = FollowBall(FollowBallParams(duration_s=60, controller="seed001"), settings,
                     LostTargetSettings(0.5, 1.0, 1.5, 10.0), front_camera(), 0.2)
    rule = beh._rule
    assert isinstance(rule, Seed001Rule)
    assert not rule.lateral
    # RADIUS: the ball's apparent radius at the standoff, fx·tan(asin(0.1 / 2))
    assert rule.r_target == pytest.approx(320.0 * math.tan(math.asin(0.05)))
    assert beh.toggle_follow_mode() == "lateral"
    assert rule.lateral


# -- seed 003 -------------------------------------------------------------------------------

def _seed003():
    cam = front_camera()
    # r* = √(20·40): its band is then exactly the seed's 20–40 px
    return Seed003Rule(cam, math.sqrt(20.0 * 40.0)), cam.intrinsics.cx, cam.intrinsics.cy


def test_seed003_bands_and_priorities_from_its_text():
    rule, cx, cy = _seed003()
    assert rule.r_lo == pytest.approx(20.0)
    assert rule.r_hi == pytest.approx(40.0)
    # "if(r<20 && circles.size()>0) { forwardx(); …" with "msg_vel = changeTwist(1,0,0,0);"
    # — full scale, whatever the other axes say (range first)
    assert rule.twist((cx + 200, cy - 200, 15.0)) == Twist(linear_x=1.0)
    # "if(r>40) { backx(); …" changeTwist(-1,0,0,0)
    assert rule.twist((cx, cy, 45.0)) == Twist(linear_x=-1.0)
    # "if(y<200 && circles.size()>0) //go up" changeTwist(0,0,1,0) — height before side
    assert rule.twist((cx + 200, cy - 60, 30.0)) == Twist(linear_z=1.0)
    # "if(y>300 && circles.size()>0) // go down" changeTwist(0,0,-1,0)
    assert rule.twist((cx, cy + 60, 30.0)) == Twist(linear_z=-1.0)
    # "if(x>350 && circles.size()>0) { backy(); }" changeTwist(0,-1,0,0): right
    assert rule.twist((cx + 60, cy, 30.0)) == Twist(linear_y=-1.0)
    # "if(x<250 && circles.size()>0) { forwardy(); }" changeTwist(0,1,0,0): left
    assert rule.twist((cx - 60, cy, 30.0)) == Twist(linear_y=1.0)
    # "if(x<350 && x>250) { stop(); }" changeTwist(0,0,0,0): the auto-hover
    assert rule.twist((cx + 40, cy - 40, 30.0)).auto_hover
    # "if(circles.size()==0) { stop(); }"
    assert rule.twist(None).auto_hover
    # exactly on an edge (r == 20 and none of the strict tests holds): nothing is published
    assert rule.twist((cx, cy, 20.0)) is None


def test_seed003_acts_once_per_frame_and_keeps_the_last_twist():
    rule, cx, cy = _seed003()
    far = _ball(cx, cy, 15.0)
    rule.command(_inputs(0.0, det=far, seq=1))
    for k in range(1, 30):
        sp = rule.command(_inputs(k * DT, det=far, seq=1))
    assert sp.velocity_m_s[0] > 1.5  # a second at full tilt
    # a frame on a band's edge publishes nothing: the drone keeps going
    edge = _ball(cx, cy, 20.0)
    sp_edge = rule.command(_inputs(1.0 + DT, det=edge, seq=2))
    assert sp_edge.acceleration_m_s2[0] > 0
    # a frame without the ball: stop(), the auto-hover brakes
    sp_none = rule.command(_inputs(1.0 + 2 * DT, det=None, last=far, seq=3))
    assert sp_none.acceleration_m_s2[0] < -GRAVITY_M_S2 * math.tan(math.radians(12)) + 1e-9


# -- seed 002 -------------------------------------------------------------------------------

def test_seed002_p_controllers_from_its_text():
    rule = Seed002Rule(standoff_m=1.0)
    tw = rule.twist((0.1, -0.05, 2.0))
    # "twist.linear.x=(transform.getOrigin().z()-1)*0.1;"
    assert tw.linear_x == pytest.approx((2.0 - 1) * 0.1)
    # "twist.linear.y=-transform.getOrigin().x()*0.2;"
    assert tw.linear_y == pytest.approx(-0.1 * 0.2)
    # "twist.linear.z=-transform.getOrigin().y()*2.0;"
    assert tw.linear_z == pytest.approx(0.05 * 2.0)
    # "this project does not manage angular components"
    assert tw.angular_z == 0.0
    assert tw.angular_x == 0.0
    assert tw.angular_y == 0.0


def _marker(x, y, z, t):
    return SimpleNamespace(position_cam_m=np.array([x, y, z]), time_s=t)


def test_seed002_zero_twist_on_a_repeated_sighting_and_its_dispatch_period():
    rule = Seed002Rule(standoff_m=1.0)
    # never seen: "If no tf are received: break operations" — nothing sent, hovering
    assert rule.command(_inputs(0.0, kind="marker")).acceleration_m_s2[0] == 0.0
    m1 = _marker(0.0, 0.0, 2.0, 0.1)
    sp = rule.command(_inputs(0.1, det=m1, seq=1, kind="marker"))
    assert rule._twist.linear_x == pytest.approx(0.1)
    assert sp.acceleration_m_s2[0] > 0
    # within the 0.1 s the twist is sent for ("Send command for 0.1 second"), it holds, even
    # with a new frame
    m2 = _marker(0.0, 0.0, 1.5, 0.15)
    rule.command(_inputs(0.15, det=m2, seq=2, kind="marker"))
    assert rule._twist.linear_x == pytest.approx(0.1)
    rule.command(_inputs(0.2, det=m2, seq=2, kind="marker"))
    assert rule._twist.linear_x == pytest.approx(0.05)
    # the same transform again: "if(twist == twist_old) twist = null;"
    rule.command(_inputs(0.3, det=None, last=m2, seq=3, kind="marker"))
    assert rule._twist.auto_hover
    rule.command(_inputs(0.4, det=None, last=m2, seq=4, kind="marker"))
    assert rule._twist.auto_hover
    m3 = _marker(0.0, 0.0, 1.8, 0.45)
    rule.command(_inputs(0.5, det=m3, seq=5, kind="marker"))
    assert rule._twist.linear_x == pytest.approx(0.08)
