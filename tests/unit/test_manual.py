"""Keyboard flying (seed 000's keys): held keys expire unless renewed; the setpoint moves in the
body frame while a key is held, brakes and then holds the spot it stopped at when none is."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot.behaviors.manual import HeldKeys, ManualFlight, ManualSettings
from drivers.base import (
    Battery,
    FlightMode,
    Health,
    LandedState,
    SetpointFrame,
    VehicleState,
)


def _state(position=(0.0, 0.0, -3.0), velocity=(0.0, 0.0, 0.0), yaw_rad=0.0):
    q = (math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2))
    return VehicleState(time_s=0.0, position_ned_m=np.array(position),
                        velocity_ned_m_s=np.array(velocity), attitude_q=np.array(q),
                        angular_velocity_frd_rad_s=np.zeros(3), armed=True,
                        mode=FlightMode.OFFBOARD, landed_state=LandedState.IN_AIR,
                        distance_to_ground_m=-position[2], battery=Battery(16.0, 1.0, 0.9),
                        health=Health())


def test_held_keys_expire_unless_renewed():
    keys = HeldKeys(0.5)
    keys.report(["forward", "yaw_left", "not-a-key"], now_s=10.0)
    assert keys.held(10.2) == {"forward", "yaw_left"}
    assert keys.held(10.51) == frozenset()  # not renewed: released
    keys.report(["forward"], now_s=10.4)
    keys.report(["forward"], now_s=10.8)  # renewed while held
    assert keys.held(11.2) == {"forward"}
    keys.report([], now_s=11.2)  # key up
    assert keys.held(11.2) == frozenset()
    keys.report(["up"], now_s=12.0)
    keys.release_all()  # the socket dropped
    assert keys.held(12.0) == frozenset()


def test_keys_fly_in_the_body_frame():
    s = ManualSettings(speed_m_s=1.5, vertical_speed_m_s=0.8, yaw_rate_rad_s=math.radians(45))
    flight = ManualFlight(s)
    sp = flight.setpoint(frozenset({"forward", "right", "up", "yaw_left"}), _state(), 1.0)
    assert sp.frame is SetpointFrame.BODY_FRD
    np.testing.assert_allclose(sp.velocity_m_s, [1.5, 1.5, -0.8])
    assert sp.yaw_rate_rad_s == pytest.approx(-math.radians(45))
    sp = flight.setpoint(frozenset({"forward", "back", "left"}), _state(), 1.0)
    np.testing.assert_allclose(sp.velocity_m_s, [0.0, -1.5, 0.0])


def test_never_below_the_minimum_height_by_keys():
    flight = ManualFlight(ManualSettings(min_altitude_m=0.8))
    sp = flight.setpoint(frozenset({"down"}), _state(position=(0, 0, -0.7)), 1.0)
    assert sp.position_ned_m[2] == pytest.approx(-0.8)  # holds, at the floor
    sp = flight.setpoint(frozenset({"down", "forward"}), _state(position=(0, 0, -0.7)), 1.0)
    assert sp.velocity_m_s[2] == 0.0
    sp = flight.setpoint(frozenset({"down"}), _state(position=(0, 0, -2.0)), 1.0)
    assert sp.velocity_m_s[2] > 0


def test_no_key_brakes_then_holds_where_it_stopped():
    flight = ManualFlight(ManualSettings(hold_below_m_s=0.25))
    moving = _state(position=(4.0, 1.0, -3.0), velocity=(1.2, 0.0, 0.0), yaw_rad=0.5)
    sp = flight.setpoint(frozenset(), moving, 1.0)
    np.testing.assert_allclose(sp.velocity_m_s, [0.0, 0.0, 0.0])  # braking
    assert np.all(np.isnan(sp.position_ned_m))
    still = _state(position=(4.6, 1.0, -3.0), velocity=(0.1, 0.0, 0.0), yaw_rad=0.5)
    sp = flight.setpoint(frozenset(), still, 2.0)
    np.testing.assert_allclose(sp.position_ned_m, [4.6, 1.0, -3.0])
    assert sp.yaw_rad == pytest.approx(0.5)
    drifted = _state(position=(4.9, 1.2, -3.1), velocity=(0.3, 0.0, 0.0))
    sp = flight.setpoint(frozenset(), drifted, 3.0)  # (the hold point stays)
    np.testing.assert_allclose(sp.position_ned_m, [4.6, 1.0, -3.0])
    sp = flight.setpoint(frozenset({"back"}), drifted, 4.0)
    assert sp.frame is SetpointFrame.BODY_FRD  # a key again: the hold point is let go
    sp = flight.setpoint(frozenset(), still, 5.0)
    np.testing.assert_allclose(sp.position_ned_m, [4.6, 1.0, -3.0])


def test_each_page_holds_its_own_keys():
    keys = HeldKeys(0.5)
    keys.report(["forward"], 1.0, source="tab-a")
    keys.report(["yaw_left"], 1.0, source="tab-b")
    keys.report([], 1.1, source="tab-b")  # tab b lets go: tab a's key stays held
    assert keys.held(1.2) == {"forward"}
    keys.release("tab-a")  # its socket dropped
    assert keys.held(1.2) == frozenset()


def test_never_above_the_maximum_height_by_keys():
    flight = ManualFlight(ManualSettings(max_altitude_m=30.0))
    sp = flight.setpoint(frozenset({"up", "forward"}), _state(position=(0, 0, -30.5)), 1.0)
    assert sp.velocity_m_s[2] == 0.0
    sp = flight.setpoint(frozenset({"up"}), _state(position=(0, 0, -10.0)), 1.0)
    assert sp.velocity_m_s[2] < 0
