"""Seed 004's landing action (Seed004LandOnRover) driven by hand, against its report
(/work/shared/seeds/004_*.txt, 4.4.2, quoted): "Get the relative position to the rover ←
Kalman filter algorithm / Compute the velocity input through the adaptive PID algorithm /
Publish the computed inputs on the offboard control topic"; "The adaptive, or gain scheduled,
PID controller usage is shared and so is the usage of the thresholds associated to the
approach"; figure 4.7: "Distinction between the approach and descent phases". The seed prints
no gain or threshold: the values are config.yaml's ``control.seed004_landing``."""

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status
from autopilot.behaviors.land_on_rover import (
    LandOnRoverParams,
    LandOnRoverSettings,
    Seed004LandingSettings,
    Seed004LandOnRover,
)
from autopilot.config import load_config
from autopilot.estimation.target import TargetEstimate
from drivers.base import Battery, FlightMode, Health, LandedState, VehicleState
from drivers.geometry import quat_from_euler

DECK_Z = -0.45


def _state(t, pos, vel=(0.0, 0.0, 0.0), range_m=None):
    pos = np.asarray(pos, dtype=float)
    rng = DECK_Z - pos[2] if range_m is None else range_m
    return VehicleState(t, pos, np.asarray(vel, dtype=float), quat_from_euler(0.0, 0.0, 0.0),
                        (0.0, 0.0, 0.0), True, FlightMode.OFFBOARD, LandedState.IN_AIR, rng,
                        Battery(16.0, 10.0, 0.9), Health())


def _deck(t, north=0.0, east=0.0, stale=False):
    return TargetEstimate(t, np.array([north, east, DECK_Z]), np.zeros(3), np.eye(6) * 1e-4,
                          0.05, stale, 100, True, kind="deck", heading_rad=0.0,
                          heading_rate_rad_s=0.0, heading_std_rad=0.02,
                          acceleration_ned_m_s2=np.zeros(3))


def _landing(**control):
    cfg = load_config().control.seed004_landing
    settings = Seed004LandingSettings(**{**cfg.model_dump(), **control})
    b = Seed004LandOnRover(LandOnRoverParams(strategy="seed004"),
                           LandOnRoverSettings((1.0, 0.8), 0.45), settings)
    b.activate(BehaviorInputs(0.0, _state(0.0, (0.0, 0.0, -3.45))))
    return b


def test_the_config_holds_the_defaults():
    cfg = load_config().control.seed004_landing
    assert Seed004LandingSettings(**cfg.model_dump()) == Seed004LandingSettings()


def test_gains_are_scheduled_on_the_distance_to_the_deck():
    b = _landing()
    c = b.control
    assert b.gains(c.near_distance_m + 0.5) == c.approach_pid
    assert b.gains(c.near_distance_m - 0.5) == c.near_pid
    assert c.approach_pid[1] == 0.0 < c.near_pid[1]  # the integral only near the deck


def test_approach_commands_velocity_from_the_pid_at_the_approach_height():
    b = _landing()
    # 3 m south of the deck, 3 m above it: Kp × error north, no climb or descent
    out = b.update(BehaviorInputs(0.05, _state(0.05, (-3.0, 0.0, -3.45)), _deck(0.05)))
    assert out.phase == "approaching"
    kp = b.control.approach_pid[0]
    assert out.setpoint.velocity_m_s[0] == pytest.approx(kp * 3.0)
    assert out.setpoint.velocity_m_s[1] == pytest.approx(0.0)
    assert out.setpoint.velocity_m_s[2] == pytest.approx(0.0)
    # too low on the approach: climb back to approach_height_m
    out = b.update(BehaviorInputs(0.1, _state(0.1, (-3.0, 0.0, -2.45)), _deck(0.1)))
    assert out.setpoint.velocity_m_s[2] < 0.0
    # far away: the speed is bounded
    out = b.update(BehaviorInputs(0.15, _state(0.15, (-30.0, 0.0, -3.45)), _deck(0.15)))
    assert np.linalg.norm(out.setpoint.velocity_m_s[:2]) == \
        pytest.approx(b.control.max_speed_m_s)


def test_the_descent_begins_within_the_threshold_and_goes_on_to_the_deck():
    b = _landing()
    c = b.control
    out = b.update(BehaviorInputs(0.05, _state(0.05, (-1.5 * c.descent_threshold_m, 0.0,
                                                      -3.45)), _deck(0.05)))
    assert out.phase == "approaching"
    assert out.setpoint.velocity_m_s[2] == pytest.approx(0.0)
    out = b.update(BehaviorInputs(0.1, _state(0.1, (-0.5 * c.descent_threshold_m, 0.0,
                                                    -3.45)), _deck(0.1)))
    assert out.phase == "descending"
    assert out.setpoint.velocity_m_s[2] == pytest.approx(c.max_descent_speed_m_s)
    # the approach's threshold only starts the descent: drifting off does not stop it
    out = b.update(BehaviorInputs(0.15, _state(0.15, (-0.4, 0.0, -2.0)), _deck(0.15)))
    assert out.phase == "descending"
    assert out.setpoint.velocity_m_s[2] > 0.0
    # near the deck the descent slows with the height (the PID's vertical error)
    out = b.update(BehaviorInputs(0.2, _state(0.2, (0.0, 0.0, DECK_Z - 0.3)), _deck(0.2)))
    assert out.setpoint.velocity_m_s[2] == pytest.approx(c.vertical_gain_per_s * 0.3)
    # contact: the motors are cut
    out = b.update(BehaviorInputs(0.25, _state(0.25, (0.0, 0.0, DECK_Z - 0.1)), _deck(0.25)))
    assert out.phase == "touching down"
    assert out.requests[0].kind is RequestKind.DISARM
    assert out.requests[0].force


def test_the_integral_catches_a_constant_offset_near_the_deck():
    b = _landing()
    pos = (-0.5, 0.0, -3.45)  # within near_distance_m: the near gains, with their integral
    first = b.update(BehaviorInputs(0.02, _state(0.02, pos), _deck(0.02)))
    t, out = 0.02, first
    for _ in range(100):
        t += 0.02
        out = b.update(BehaviorInputs(t, _state(t, pos), _deck(t)))
    assert out.setpoint.velocity_m_s[0] > first.setpoint.velocity_m_s[0] + 0.4


def test_no_estimate_holds_and_the_timeout_fails():
    b = _landing()
    out = b.update(BehaviorInputs(0.05, _state(0.05, (0.0, 0.0, -3.45)), None))
    assert out.status is Status.RUNNING
    assert np.allclose(out.setpoint.velocity_m_s, 0.0)
    out = b.update(BehaviorInputs(0.1, _state(0.1, (0.0, 0.0, -3.45)), _deck(0.1, stale=True)))
    assert np.allclose(out.setpoint.velocity_m_s, 0.0)
    out = b.update(BehaviorInputs(1000.0, _state(1000.0, (0.0, 0.0, -3.45)), _deck(1000.0)))
    assert out.status is Status.FAILED
