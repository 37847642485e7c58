"""The autopilot's own geofence, on every setpoint: targets outside, velocities leading out
(in the body frame too), and motion back in allowed."""

from __future__ import annotations

import math

import numpy as np

from autopilot.control.geofence import FenceSettings, Geofence
from drivers.base import Battery, FlightMode, Health, LandedState, Setpoint, VehicleState


def _state(position=(0.0, 0.0, -3.0), yaw_rad=0.0):
    q = (math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2))
    return VehicleState(time_s=0.0, position_ned_m=np.array(position, dtype=float),
                        velocity_ned_m_s=np.zeros(3), attitude_q=np.array(q),
                        angular_velocity_frd_rad_s=np.zeros(3), armed=True,
                        mode=FlightMode.OFFBOARD, landed_state=LandedState.IN_AIR,
                        distance_to_ground_m=-position[2], battery=Battery(16.0, 1.0, 0.9),
                        health=Health())


HOME = np.array([1.0, 1.0, 0.0])


def test_no_fence_no_checks():
    fence = Geofence(FenceSettings())
    assert fence.check(Setpoint.position(1e6, 0, -3), _state(), HOME) is None


def test_distance_and_height_of_position_targets():
    fence = Geofence(FenceSettings(max_distance_m=10.0, max_altitude_m=20.0))
    assert fence.check(Setpoint.position(9.0, 1.0, -3.0), _state(), HOME) is None  # 8 m
    assert "max_distance_m" in fence.check(Setpoint.position(12.0, 1.0, -3.0), _state(), HOME)
    assert "max_altitude_m" in fence.check(Setpoint.position(0.0, 0.0, -25.0), _state(), HOME)


def test_velocity_leading_out_within_the_lookahead_in_either_frame():
    fence = Geofence(FenceSettings(max_distance_m=10.0, lookahead_s=1.0))
    near_edge = _state(position=(10.0, 1.0, -3.0))  # 9 m from home
    assert fence.check(Setpoint.velocity_ned(0.5, 0, 0), near_edge, HOME) is None
    assert "heading out" in fence.check(Setpoint.velocity_ned(2.0, 0, 0), near_edge, HOME)
    # body frame: facing east, "forward" is east
    east = _state(position=(1.0, 10.0, -3.0), yaw_rad=math.pi / 2)
    assert fence.check(Setpoint.velocity_body(2.0, 0, 0), east, HOME) is not None
    assert fence.check(Setpoint.velocity_body(-2.0, 0, 0), east, HOME) is None


def test_outside_already_going_back_in_is_allowed_going_further_is_not():
    fence = Geofence(FenceSettings(max_distance_m=10.0))
    outside = _state(position=(13.0, 1.0, -3.0))  # 12 m
    assert fence.check_state(outside, HOME) is not None
    assert fence.check(Setpoint.velocity_ned(-2.0, 0, 0), outside, HOME) is None
    assert fence.check(Setpoint.velocity_ned(0.5, 0, 0), outside, HOME) is not None


def test_polygon():
    fence = Geofence(FenceSettings(polygon_ne_m=((0, 0), (20, 0), (20, 10), (0, 10))))
    assert fence.check(Setpoint.position(5, 5, -3), _state((5, 5, -3)), None) is None
    assert "polygon" in fence.check(Setpoint.position(5, 15, -3), _state((5, 5, -3)), None)
    assert "heading out" in fence.check(Setpoint.velocity_ned(0, 3, 0), _state((5, 9, -3)), None)
