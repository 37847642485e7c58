"""The AR.Drone 2.0 driver's synchronous core: navdata to telemetry
(signs, the heading rotation, dead reckoning and its drift, the state mappings), the outer loop
(its signs in the heading frame, saturation, the hover), what the AT loop sends (REF, PCMD, the
offboard timeout, the climb after the takeoff, the emergency), the video clock and cameras."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.cameras import VideoClock, ardrone_cameras, camera_of_frame
from drivers.ardrone.commander import Commander
from drivers.ardrone.config import DroneConfig, parse_config_text
from drivers.ardrone.navdata import ControlState, Demo, State
from drivers.ardrone.outer_loop import OuterLoop
from drivers.ardrone.telemetry import GRAVITY_M_S2, HOVER, DroneLimits, NavdataTelemetry
from drivers.base import (
    Battery,
    FlightMode,
    Health,
    LandedState,
    ProgressiveCommand,
    Setpoint,
    VehicleState,
)
from drivers.geometry import constrain_xy, euler_from_quat, quat_from_euler, quat_rotate

FLYING = State.FLY | State.NAVDATA_DEMO
LIMITS = DroneLimits()


def packet(*, state=FLYING, control=ControlState.FLYING, phi=0.0, theta=0.0, psi=0.0,
           altitude_mm=1000, vx=0.0, vy=0.0, vz=0.0, battery=80, seq=1) -> nav.Navdata:
    """A demo packet as the drone sends it (built and parsed by the real codec); angles in
    degrees, velocities in mm/s."""
    demo = Demo(int(control) << 16, battery, theta * 1000.0, phi * 1000.0, psi * 1000.0,
                altitude_mm, vx, vy, vz)
    return nav.parse(nav.build(int(state), seq, demo))


def state_at(*, yaw_deg=0.0, position=(0.0, 0.0, -1.0), velocity=(0.0, 0.0, 0.0),
             time_s=0.0, roll_deg=0.0, pitch_deg=0.0,
             mode=FlightMode.OFFBOARD) -> VehicleState:
    return VehicleState(time_s, position, velocity,
                        quat_from_euler(math.radians(roll_deg), math.radians(pitch_deg),
                                        math.radians(yaw_deg)),
                        np.zeros(3), True, mode, LandedState.IN_AIR, 1.0,
                        Battery(math.nan, math.nan, 0.8), Health())


# --------------------------------------------------------------------------------------------
# Navdata → VehicleState
# --------------------------------------------------------------------------------------------


def test_the_attitude_is_frd_ned_as_the_drone_reports_it() -> None:
    tel = NavdataTelemetry()
    s = tel.update(packet(phi=10.0, theta=5.0, psi=90.0), 1.0)
    roll, pitch, yaw = euler_from_quat(s.attitude_q)
    assert math.degrees(roll) == pytest.approx(10.0)
    assert math.degrees(pitch) == pytest.approx(5.0)
    assert math.degrees(yaw) == pytest.approx(90.0)
    # theta positive is nose up: the body's x axis points up (negative down) and east (psi 90°)
    nose = quat_rotate(s.attitude_q, np.array([1.0, 0.0, 0.0]))
    assert nose[1] > 0.99 * math.cos(math.radians(5.0))
    assert nose[2] < 0.0
    # phi positive is the right wing down: the body's y axis points down
    right = quat_rotate(tel.update(packet(phi=10.0), 1.1).attitude_q, np.array([0, 1.0, 0]))
    assert right[2] > 0.1


@pytest.mark.parametrize(("psi", "vx", "vy", "north", "east"), [
    (0.0, 1000.0, 0.0, 1.0, 0.0),
    (90.0, 1000.0, 0.0, 0.0, 1.0),  # facing east, flying forward: east
    (0.0, 0.0, 1000.0, 0.0, 1.0),  # facing north, flying right: east
    (90.0, 0.0, 1000.0, -1.0, 0.0),  # facing east, flying right: south
    (-135.0, 1000.0, 0.0, -math.sqrt(0.5), -math.sqrt(0.5)),
])
def test_the_velocity_is_turned_from_the_heading_frame_into_ned(psi, vx, vy, north,
                                                                 east) -> None:
    s = NavdataTelemetry().update(packet(psi=psi, vx=vx, vy=vy, vz=-200.0), 0.0)
    assert s.velocity_ned_m_s == pytest.approx([north, east, -0.2], abs=1e-6)


def test_the_height_is_the_demo_altitude() -> None:
    s = NavdataTelemetry().update(packet(altitude_mm=1234), 0.0)
    assert s.position_ned_m[2] == pytest.approx(-1.234)
    assert s.altitude_m == pytest.approx(1.234)
    assert s.distance_to_ground_m == pytest.approx(1.234)


def test_a_known_velocity_profile_is_dead_reckoned() -> None:
    """Accelerating north at 0.5 m/s² for 2 s, then 1 m/s for 2 s (15 Hz packets): 1 m + 2 m
    north, and the drift grows with the path."""
    tel = NavdataTelemetry(latency_s=0.0)
    dt = 1 / 15
    for k in range(61):
        t = k * dt
        v = 0.5 * t if t <= 2.0 else 1.0
        s = tel.update(packet(vx=v * 1000.0, seq=k + 1), t)
    assert s.time_s == pytest.approx(4.0)
    assert s.position_ned_m[0] == pytest.approx(3.0, abs=0.01)
    assert s.position_ned_m[1] == pytest.approx(0.0, abs=1e-9)
    assert tel.path_m == pytest.approx(3.0, abs=0.01)
    expected = tel.DRIFT_PER_METRE * 3.0 + tel.DRIFT_RATE_M_S * 4.0
    assert tel.drift_m == pytest.approx(expected, rel=0.01)


def test_dead_reckoning_turns_with_the_heading() -> None:
    tel = NavdataTelemetry(latency_s=0.0)
    for k in range(31):  # 2 s forward at 0.5 m/s, facing east
        s = tel.update(packet(psi=90.0, vx=500.0, seq=k + 1), k / 15)
    assert s.position_ned_m[:2] == pytest.approx([0.0, 1.0], abs=1e-6)


def test_a_landed_drone_does_not_move_whatever_its_flow_says() -> None:
    tel = NavdataTelemetry()
    for k in range(30):
        s = tel.update(packet(state=State.NAVDATA_DEMO, control=ControlState.LANDED,
                              vx=80.0, vy=-60.0, altitude_mm=0, seq=k + 1), k / 15)
    assert np.all(s.position_ned_m == 0.0)
    assert tel.drift_m == 0.0
    tel.reset_position(2.0, -1.0)
    s = tel.update(packet(state=State.NAVDATA_DEMO, control=ControlState.LANDED, seq=31), 3.0)
    assert s.position_ned_m[:2] == pytest.approx([2.0, -1.0])


def test_each_sample_carries_its_capture_time() -> None:
    s = NavdataTelemetry(latency_s=0.03).update(packet(), 12.5)
    assert s.time_s == pytest.approx(12.47)
    assert s.attitude_time_s == s.time_s


def test_body_rates_are_the_attitude_change_between_packets() -> None:
    tel = NavdataTelemetry(latency_s=0.0)
    tel.update(packet(psi=0.0, seq=1), 0.0)
    s = tel.update(packet(psi=10.0, seq=2), 0.1)
    assert s.angular_velocity_frd_rad_s == pytest.approx([0.0, 0.0, math.radians(100.0)],
                                                         rel=1e-3, abs=1e-6)
    s = tel.update(packet(psi=10.0, seq=3), 1.0)  # a gap: no rates from it
    assert np.all(s.angular_velocity_frd_rad_s == 0.0)


@pytest.mark.parametrize(("control", "flags", "mode", "landed"), [
    (ControlState.LANDED, State(0), FlightMode.HOLD, LandedState.ON_GROUND),
    (ControlState.TAKING_OFF, State.FLY, FlightMode.TAKEOFF, LandedState.TAKING_OFF),
    (ControlState.HOVERING, State.FLY, FlightMode.HOLD, LandedState.IN_AIR),
    (ControlState.FLYING, State.FLY, FlightMode.OFFBOARD, LandedState.IN_AIR),
    (ControlState.LANDING, State.FLY, FlightMode.LAND, LandedState.LANDING),
    (ControlState.LOOPING, State.FLY, FlightMode.UNKNOWN, LandedState.IN_AIR),
    (ControlState.DEFAULT, State(0), FlightMode.UNKNOWN, LandedState.ON_GROUND),
])
def test_the_control_state_says_the_mode_and_the_landed_state(control, flags, mode,
                                                              landed) -> None:
    s = NavdataTelemetry().update(packet(state=flags | State.NAVDATA_DEMO, control=control),
                                  0.0)
    assert (s.mode, s.landed_state) == (mode, landed)
    assert s.armed == (State.FLY in flags)


def test_health_battery_and_failsafe_come_from_the_state_bits() -> None:
    tel = NavdataTelemetry()
    ok = tel.update(packet(battery=42), 0.0)
    assert ok.health.armable
    assert not ok.failsafe
    assert ok.battery.remaining_fraction == pytest.approx(0.42)
    assert math.isnan(ok.battery.voltage_v)
    emergency = tel.update(packet(state=FLYING | State.EMERGENCY, seq=2), 0.1)
    assert not emergency.health.armable
    assert emergency.health.problems() == ["prearm"]
    low = tel.update(packet(state=FLYING | State.VBAT_LOW, seq=3), 0.2)
    assert low.health.problems() == ["battery"]
    lost = tel.update(packet(state=FLYING | State.COM_LOST, seq=4), 0.3)
    assert lost.failsafe
    assert lost.health.armable


# --------------------------------------------------------------------------------------------
# The outer loop
# --------------------------------------------------------------------------------------------


def _north_of(yaw_deg: float) -> ProgressiveCommand:
    loop = OuterLoop()
    return loop.update(Setpoint.position(3.0, 0.0, -1.0), state_at(yaw_deg=yaw_deg), 0.0)


def test_a_setpoint_north_of_a_drone_is_a_tilt_towards_north_in_its_heading_frame() -> None:
    facing_north = _north_of(0.0)
    assert facing_north.pitch < -0.3  # nose down: forward
    assert abs(facing_north.roll) < 1e-6
    facing_west = _north_of(-90.0)  # north is on its right
    assert facing_west.roll > 0.3
    assert abs(facing_west.pitch) < 1e-6
    facing_east = _north_of(90.0)  # north is on its left
    assert facing_east.roll < -0.3
    assert abs(facing_east.pitch) < 1e-6
    facing_south = _north_of(180.0)
    assert facing_south.pitch > 0.3  # nose up: backwards
    for command in (facing_north, facing_west, facing_east, facing_south):
        assert not command.hover
        assert abs(command.gaz) < 1e-9
        assert abs(command.yaw) < 1e-9


def test_saturation_keeps_the_fractions_in_range_and_the_direction() -> None:
    loop = OuterLoop()
    far = loop.update(Setpoint.position(100.0, 100.0, -30.0, yaw_rad=3.0),
                      state_at(velocity=(-2.0, -2.0, 0.0)), 0.0)
    for value in (far.roll, far.pitch, far.gaz, far.yaw):
        assert -1.0 <= value <= 1.0
    assert far.gaz == 1.0
    assert far.yaw == 1.0
    # north-east at full tilt: forward and right in equal parts, the tilt euler_angle_max
    assert far.roll == pytest.approx(-far.pitch, rel=0.02)
    tilt = math.hypot(far.roll, far.pitch) * LIMITS.euler_angle_max_rad
    assert tilt == pytest.approx(LIMITS.euler_angle_max_rad, rel=0.05)


def _drag_tilt(speed_m_s: float) -> float:
    """The pitch fraction the drag's feed-forward gives a flight at ``speed_m_s`` at its
    setpoint (the integral adds the rest of the drag over time)."""
    share = OuterLoop().gains.drag_feed_forward_per_s
    return math.atan(share * speed_m_s / GRAVITY_M_S2) / LIMITS.euler_angle_max_rad


def test_a_position_goal_is_approached_at_the_position_speed() -> None:
    """Far away and already at the position part's speed towards it: only the drag's
    feed-forward."""
    loop = OuterLoop()
    speed = loop.gains.position_speed_m_s
    cruising = loop.update(Setpoint.position(50.0, 0.0, -1.0),
                           state_at(velocity=(speed, 0.0, 0.0)), 0.0)
    slow = OuterLoop().update(Setpoint.position(50.0, 0.0, -1.0),
                              state_at(velocity=(0.2, 0.0, 0.0)), 0.0)
    assert cruising.pitch == pytest.approx(-_drag_tilt(speed), abs=0.01)
    assert abs(slow.pitch) > abs(cruising.pitch) + 0.3


def test_the_speed_limit_is_the_drones_terminal_speed_share() -> None:
    """A velocity setpoint is flown up to a share of the speed ``euler_angle_max`` holds
    against the drag (12°: ~2.9 m/s), beyond it limited; a wider tilt allows more."""
    loop = OuterLoop()
    top = loop.max_speed_m_s
    assert top == pytest.approx(
        loop.gains.speed_share * GRAVITY_M_S2 * math.tan(math.radians(12.0)) / 0.58, rel=1e-4)
    assert 2.5 < top < 3.5
    at_top = loop.update(Setpoint.velocity_ned(10.0, 0.0, 0.0),
                         state_at(velocity=(top, 0.0, 0.0)), 0.0)
    assert at_top.pitch == pytest.approx(-_drag_tilt(top), abs=0.01)
    wider = OuterLoop(DroneLimits(euler_angle_max_rad=math.radians(20.0)))
    assert wider.max_speed_m_s > 1.5 * top


def test_a_velocity_fed_forward_comes_before_the_position_error() -> None:
    """The outer loop's limit (``constrain_xy`` with the feed-forward as its priority term,
    PX4's order reversed): the feed-forward kept whole, the position part what fits."""
    assert constrain_xy(np.array([0.0, 1.0]), np.array([0.5, 0.0]), 3.0) == \
        pytest.approx([0.5, 1.0])
    kept = constrain_xy(np.array([0.0, 2.5]), np.array([2.0, 0.0]), 3.0)
    assert kept[0] > 0.0
    assert kept[1] == pytest.approx(2.5)
    assert float(np.hypot(*kept)) == pytest.approx(3.0)
    assert constrain_xy(np.array([0.0, 4.0]), np.array([1.0, 0.0]), 3.0) == \
        pytest.approx([0.0, 3.0])


def test_a_zero_velocity_is_the_drones_own_hover() -> None:
    loop = OuterLoop()
    state = state_at(yaw_deg=30.0)
    assert loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0), state, 0.0) == HOVER
    assert loop.update(Setpoint.velocity_body(0.0, 0.0, 0.0), state, 0.0).hover
    assert loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rad=math.radians(30.5)),
                       state, 0.0).hover
    # anything that asks for motion is not
    assert not loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rate_rad_s=0.3),
                           state, 0.0).hover
    assert not loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rad=1.5), state, 0.0).hover
    assert not loop.update(Setpoint.velocity_ned(0.1, 0.0, 0.0), state, 0.0).hover
    assert not loop.update(Setpoint.position(0.0, 0.0, -1.0), state, 0.0).hover


def test_vertical_speed_is_gaz_and_yaw_a_rate() -> None:
    loop, state = OuterLoop(), state_at()
    down = loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.35), state, 0.0)
    assert down.gaz == pytest.approx(-0.5)  # 0.35 m/s of control_vz_max 0.7, down
    up = loop.update(Setpoint.position(0.0, 0.0, -1.5), state, 0.0)  # 0.5 m above
    assert up.gaz > 0.5
    turn = loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rate_rad_s=0.8726646),
                       state, 0.0)
    assert turn.yaw == pytest.approx(0.5)  # clockwise, half of control_yaw
    heading = loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rad=-0.3), state, 0.0)
    assert heading.yaw < 0.0  # anticlockwise to -0.3 rad
    across = loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rad=math.radians(170.0)),
                         state_at(yaw_deg=-170.0), 0.0)
    assert across.yaw < 0.0  # the short way round, through ±180°


def test_a_body_velocity_is_flown_in_the_heading_frame() -> None:
    facing_east = state_at(yaw_deg=90.0)
    forward = OuterLoop().update(Setpoint.velocity_body(0.5, 0.0, 0.0), facing_east, 0.0)
    assert forward.pitch < -0.1
    assert abs(forward.roll) < 1e-6
    right = OuterLoop().update(Setpoint.velocity_body(0.0, 0.5, 0.0), facing_east, 0.0)
    assert right.roll > 0.1
    assert abs(right.pitch) < 1e-6


def test_the_integral_removes_a_steady_error_and_resets() -> None:
    loop = OuterLoop()
    state = state_at(velocity=(0.4, 0.0, 0.0))  # short of 0.5 m/s, steadily
    sp = Setpoint.velocity_ned(0.5, 0.0, 0.0)
    first = loop.update(sp, state, 0.0)
    for k in range(1, 60):
        later = loop.update(sp, state, k / 30)
    assert later.pitch < first.pitch - 0.03  # more nose down as the error persists
    loop.reset()
    assert loop.update(sp, state, 3.0).pitch == pytest.approx(first.pitch)
    for k in range(1, 60):
        loop.update(sp, state, 3.0 + k / 30)
    assert loop.update(Setpoint.velocity_ned(0.0, 0.0, 0.0), state, 5.0).hover  # resets it
    assert loop.update(sp, state, 5.0 + 1 / 30).pitch == pytest.approx(first.pitch, abs=0.005)


def test_the_tilt_it_flies_leads_the_velocity() -> None:
    """Nosed down and accelerating, the velocity fed back is ahead of the sample: less tilt is
    asked than for a level drone at the same speed (it would overshoot)."""
    sp = Setpoint.velocity_ned(0.5, 0.0, 0.0)
    level = OuterLoop().update(sp, state_at(velocity=(0.2, 0.0, 0.0)), 0.0)
    loop = OuterLoop()
    loop.update(sp, state_at(velocity=(0.2, 0.0, 0.0)), 0.0)
    tilted = loop.update(sp, state_at(velocity=(0.2, 0.0, 0.0), pitch_deg=-8.0), 0.5)
    assert tilted.pitch > level.pitch


# --------------------------------------------------------------------------------------------
# The AT loop's commands
# --------------------------------------------------------------------------------------------


def _commands(datagrams: list[bytes]) -> list[at.AtCommand]:
    return [cmd for datagram in datagrams for cmd in at.parse(datagram)]


def _ref(commands) -> int:
    (ref,) = [c for c in commands if c.name == "REF"]
    return int(ref.args[0])


def _pcmd(commands) -> tuple[int, tuple[float, ...]]:
    (pcmd,) = [c for c in commands if c.name == "PCMD"]
    return int(pcmd.args[0]), pcmd.floats(1)


def _commander() -> Commander:
    return Commander(at.AtCommands(), OuterLoop(), offboard_timeout_s=0.5)


def test_nothing_lands_a_flying_drone_on_connect() -> None:
    c = _commander()
    assert [cmd.name for cmd in _commands(c.tick(0.0, None, None))] == ["PCMD"]  # no REF yet
    c.on_state(state_at(), ControlState.HOVERING)
    assert _ref(_commands(c.tick(0.1, state_at(), ControlState.HOVERING))) & at.REF_TAKEOFF
    landed = _commander()
    landed.on_state(state_at(), ControlState.LANDED)
    assert not _ref(_commands(landed.tick(0.1, state_at(), ControlState.LANDED))) & \
        at.REF_TAKEOFF


def test_offboard_flies_the_newest_setpoint_until_it_is_too_old() -> None:
    c = _commander()
    state = state_at()
    c.on_state(state, ControlState.HOVERING)
    assert c.start_offboard(0.0) is not None  # no setpoint yet: refused
    c.setpoint(Setpoint.velocity_ned(0.5, 0.0, 0.0), 0.0)
    assert c.start_offboard(0.1) is None
    assert c.mode(state, ControlState.HOVERING) is FlightMode.OFFBOARD
    flag, (_, pitch, _, _) = _pcmd(_commands(c.tick(0.2, state, ControlState.HOVERING)))
    assert flag & at.PCMD_PROGRESSIVE
    assert pitch < 0.0
    # 0.5 s without a new one: the hover, and out of offboard (HOLD)
    flag, values = _pcmd(_commands(c.tick(0.6, state, ControlState.FLYING)))
    assert not flag & at.PCMD_PROGRESSIVE
    assert values == (0.0, 0.0, 0.0, 0.0)
    assert not c.offboard
    assert c.offboard_timeouts == 1
    assert c.mode(state, ControlState.FLYING) is FlightMode.HOLD


def test_a_progressive_setpoint_is_flown_as_it_is() -> None:
    c, state = _commander(), state_at()
    c.on_state(state, ControlState.HOVERING)
    c.setpoint(Setpoint(velocity_m_s=(0.0, 0.0, 0.0), progressive=ProgressiveCommand(
        roll=0.2, pitch=-1.5, gaz=0.1, yaw=-0.3, hover=False)), 0.0)
    c.start_offboard(0.0)
    flag, values = _pcmd(_commands(c.tick(0.1, state, ControlState.HOVERING)))
    assert flag & at.PCMD_PROGRESSIVE
    assert values == pytest.approx((0.2, -1.0, 0.1, -0.3))


def test_the_climb_after_the_takeoff_to_the_height_asked() -> None:
    c = _commander()
    c.on_state(state_at(position=(0, 0, 0)), ControlState.LANDED)
    c.takeoff(2.0, LIMITS)
    assert _ref(_commands(c.tick(0.0, state_at(position=(0, 0, 0)), ControlState.LANDED))) \
        & at.REF_TAKEOFF
    taking_off = state_at(position=(0, 0, -0.5))
    assert c.mode(taking_off, ControlState.TAKING_OFF) is FlightMode.TAKEOFF
    assert c.pcmd(0.5, taking_off, ControlState.TAKING_OFF).hover  # the drone's own takeoff
    at_one_metre = state_at(position=(0, 0, -1.0))
    climbing = c.pcmd(2.0, at_one_metre, ControlState.HOVERING)
    assert not climbing.hover
    assert climbing.gaz > 0.5
    assert c.mode(at_one_metre, ControlState.FLYING) is FlightMode.TAKEOFF
    there = state_at(position=(0, 0, -1.95), mode=FlightMode.HOLD)  # (the drone's: hovering)
    assert c.pcmd(4.0, there, ControlState.FLYING).hover
    assert c.climb_to_m is None
    assert c.mode(there, ControlState.HOVERING) is FlightMode.HOLD
    high = _commander()
    high.takeoff(10.0, LIMITS)  # never above control:altitude_max
    assert high.climb_to_m < LIMITS.altitude_max_m


def test_a_climb_that_does_not_get_there_is_given_up() -> None:
    c = _commander()
    c.takeoff(2.5, LIMITS)
    stuck = state_at(position=(0, 0, -1.0), mode=FlightMode.HOLD)
    assert not c.pcmd(0.0, stuck, ControlState.FLYING).hover
    assert not c.pcmd(Commander.CLIMB_TIMEOUT_S - 1.0, stuck, ControlState.FLYING).hover
    assert c.pcmd(Commander.CLIMB_TIMEOUT_S + 0.1, stuck, ControlState.FLYING).hover
    assert c.mode(stuck, ControlState.HOVERING) is FlightMode.HOLD


def test_an_emergency_is_a_few_refs_with_the_emergency_bit() -> None:
    c, state = _commander(), state_at()
    c.on_state(state, ControlState.FLYING)
    c.emergency()
    refs = [_ref(_commands(c.tick(k / 30, state, ControlState.FLYING))) for k in range(8)]
    emergency = [bool(r & at.REF_EMERGENCY) for r in refs]
    assert emergency == [True] * Commander.EMERGENCY_TICKS + [False] * 3
    assert not any(r & at.REF_TAKEOFF for r in refs)


def test_a_drone_back_on_the_ground_is_not_taken_off_again() -> None:
    c = _commander()
    c.on_state(state_at(), ControlState.LANDED)
    c.takeoff(None, LIMITS)
    c.on_state(state_at(), ControlState.LANDED)  # (before the drone took the REF)
    assert c.takeoff_bit
    c.on_state(state_at(), ControlState.HOVERING)
    c.on_state(state_at(), ControlState.LANDED)  # the battery landed it, or it was cut
    assert c.takeoff_bit is False


# --------------------------------------------------------------------------------------------
# Video, cameras, limits
# --------------------------------------------------------------------------------------------


def test_the_video_clock_keeps_the_fastest_frames_offset() -> None:
    clock = VideoClock(latency_s=0.05)
    assert clock.map(10.0, 110.10) == pytest.approx(110.05)  # offset 100.05
    assert clock.map(10.1, 110.13) == pytest.approx(110.08)  # faster: offset 99.98
    assert clock.offset_s == pytest.approx(99.98)
    assert clock.map(10.2, 110.40) == pytest.approx(110.18)  # slower: the offset kept
    assert clock.map(1.0, 150.0) == pytest.approx(149.95)  # the drone rebooted: afresh


def test_the_nominal_cameras_are_the_ardrones() -> None:
    cams = ardrone_cameras()
    front, down = cams["front"], cams["down"]
    assert (front.intrinsics.width_px, front.intrinsics.height_px) == (640, 360)
    assert (down.intrinsics.width_px, down.intrinsics.height_px) == (320, 240)
    assert front.rotation_body_cam @ np.array([0, 0, 1.0]) == pytest.approx([1.0, 0, 0])
    assert down.rotation_body_cam @ np.array([0, 0, 1.0]) == pytest.approx([0, 0, 1.0])
    assert down.rotation_body_cam @ np.array([0, -1.0, 0]) == pytest.approx([1.0, 0, 0])


def test_the_nominal_cameras_match_the_vehicle_configuration() -> None:
    from autopilot.config import load_config
    from drivers.sim.model import camera_info

    cfg = load_config(None, ["sim.firmware=ardrone"]).vehicle.cameras
    for name, info in ardrone_cameras().items():
        configured = camera_info(name, cfg[name])
        assert info.intrinsics == configured.intrinsics
        assert info.rotation_body_cam == pytest.approx(configured.rotation_body_cam)
        assert info.position_body_m == pytest.approx(configured.position_body_m)
        assert info.rate_hz == configured.rate_hz


def test_a_frame_is_the_selected_cameras_unless_only_another_has_its_size() -> None:
    cams = ardrone_cameras()
    assert camera_of_frame(320, 240, cams, "down") == "down"
    assert camera_of_frame(640, 360, cams, "down") == "front"  # from before the switch
    assert camera_of_frame(1280, 720, cams, "down") == "down"


def test_the_limits_come_from_the_drones_configuration() -> None:
    defaults = DroneLimits.from_config(parse_config_text(DroneConfig().to_text()))
    assert dataclasses.astuple(defaults) == pytest.approx(dataclasses.astuple(LIMITS))
    config = DroneConfig()
    config.set("control:euler_angle_max", "0.3")
    config.set("control:control_vz_max", "1000")
    config.set("control:altitude_max", "5000")
    limits = DroneLimits.from_config(parse_config_text(config.to_text()))
    assert limits.euler_angle_max_rad == pytest.approx(0.3)
    assert limits.control_vz_max_m_s == pytest.approx(1.0)
    assert limits.altitude_max_m == pytest.approx(5.0)
    assert DroneLimits.from_config({"control:control_yaw": "fast"}) == LIMITS


@pytest.mark.parametrize(("keys", "expected"), [
    ({"control:euler_angle_max": 0.9}, "control:euler_angle_max: 0.9 outside 0..0.52"),
    ({"control:no_such_key": 1}, "no configuration key 'control:no_such_key'"),
    ({"general:num_version_soft": "3.0"}, "general:num_version_soft is read-only"),
    ({"control:outdoor": "perhaps"}, "control:outdoor: 'perhaps' is not TRUE or FALSE"),
    ({"video:video_channel": 1}, "video:video_channel: the driver sets it itself"),
    ({"general:navdata_demo": False}, "the driver sets it itself (from link.navdata)"),
])
def test_the_drones_keys_in_the_configuration_are_checked(keys, expected) -> None:
    """``link.ardrone_config``: refused before anything connects, naming the key and what
    was wrong with it."""
    from autopilot.config import ConfigError, load_config

    with pytest.raises(ConfigError, match=r"link\.ardrone_config") as caught:
        load_config(None, [f"link.ardrone_config={json.dumps(keys)}"])
    assert expected in str(caught.value)
    assert load_config(None, ['link.ardrone_config={"control:outdoor": true}']) \
        .link.ardrone_config == {"control:outdoor": True}
