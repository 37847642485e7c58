"""PX4's MAVLink conventions: custom modes and setpoint type masks."""

import math

import numpy as np
import pytest

from drivers.base import FlightMode, Setpoint, SetpointFrame
from drivers.mavlink import px4


@pytest.mark.parametrize(("mode", "value"), [
    (FlightMode.HOLD, 0x03040000), (FlightMode.TAKEOFF, 0x02040000),
    (FlightMode.LAND, 0x06040000), (FlightMode.OFFBOARD, 0x00060000),
    (FlightMode.POSCTL, 0x00030000), (FlightMode.RETURN, 0x05040000),
])
def test_px4_custom_modes_round_trip(mode, value):
    assert px4.px4_custom_mode(mode) == value
    assert px4.px4_flight_mode(value) is mode


def test_unknown_custom_mode_is_unknown():
    assert px4.px4_flight_mode(0x09090000) is FlightMode.UNKNOWN
    assert px4.px4_mode_from_pair(4, 7) is None  # follow target: not modelled
    # precision land is (AUTO, PRECLAND)
    assert px4.px4_mode_from_pair(4, 9) is FlightMode.PRECLAND
    assert px4.px4_flight_mode(px4.px4_custom_mode(FlightMode.PRECLAND)) is FlightMode.PRECLAND


def test_mavsdk_velocity_yaw_mask_reads_as_velocity_with_yaw():
    sp = px4.setpoint_from_mavlink(px4.MAV_FRAME_LOCAL_NED, 2503, (9, 9, 9), (1, 2, 3),
                                   0.5, 9.0)
    assert np.isnan(sp.position_ned_m).all()
    assert sp.velocity_m_s.tolist() == [1, 2, 3]
    assert sp.yaw_rad == 0.5
    assert math.isnan(sp.yaw_rate_rad_s)


def test_position_yaw_mask_and_round_trip():
    original = Setpoint.position(1.0, -2.0, -3.0, yaw_rad=0.25)
    frame, mask, pos, vel, yaw, rate, acc = px4.setpoint_to_mavlink(original)
    assert mask == 2552
    assert frame == px4.MAV_FRAME_LOCAL_NED
    back = px4.setpoint_from_mavlink(frame, mask, pos, vel, yaw, rate, acc)
    assert back.position_ned_m.tolist() == [1.0, -2.0, -3.0]
    assert back.yaw_rad == 0.25
    assert np.isnan(back.velocity_m_s).all()


def test_body_velocity_round_trip():
    original = Setpoint.velocity_body(1.0, 0.5, 0.0, yaw_rate_rad_s=0.2)
    back = px4.setpoint_from_mavlink(*px4.setpoint_to_mavlink(original))
    assert back.frame is SetpointFrame.BODY_FRD
    assert back.velocity_m_s.tolist() == [1.0, 0.5, 0.0]
    assert back.yaw_rate_rad_s == 0.2


@pytest.mark.parametrize(("frame", "mask", "match"), [
    (px4.MAV_FRAME_LOCAL_NED, 3135, "without position or velocity"),  # acceleration only
    (6, 2552, "coordinate frame 6"),  # GLOBAL_RELATIVE_ALT_INT
    (px4.MAV_FRAME_BODY_NED, 2552, "BODY_NED position"),
])
def test_setpoints_we_cannot_fly_are_rejected_clearly(frame, mask, match):
    with pytest.raises(px4.SetpointNotSupported, match=match):
        px4.setpoint_from_mavlink(frame, mask, (0, 0, -2), (0, 0, 0), 0.0, 0.0)


def test_acceleration_feed_forward_round_trip():
    original = Setpoint.position_velocity((1.0, 2.0, -3.0), (0.5, 0.0, 0.0), yaw_rad=0.1,
                                          yaw_rate_rad_s=0.4,
                                          acceleration_ned_m_s2=(0.0, 0.8, 0.0))
    frame, mask, pos, vel, yaw, rate, acc = px4.setpoint_to_mavlink(original)
    assert mask & px4.IGNORE_ACCEL == 0
    back = px4.setpoint_from_mavlink(frame, mask, pos, vel, yaw, rate, acc)
    assert back.acceleration_m_s2.tolist() == [0.0, 0.8, 0.0]
    assert (back.yaw_rad, back.yaw_rate_rad_s) == (0.1, 0.4)
    # without one, the acceleration fields are ignored; as a force (FORCE_SET) it is not flown
    assert px4.setpoint_to_mavlink(Setpoint.position(1, 2, -3))[1] & px4.IGNORE_ACCEL == \
        px4.IGNORE_ACCEL
    forced = px4.setpoint_from_mavlink(frame, mask | px4.FORCE_SET, pos, vel, yaw, rate, acc)
    assert np.isnan(forced.acceleration_m_s2).all()
