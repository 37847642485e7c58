"""The simulated AR.Drone 2.0's firmware (sim.firmware: ardrone) flown by its own commands, in
lockstep: the automatic takeoff to about 1 m, the hover, progressive commands as fractions of
the tilt / climb / yaw-rate limits, the altitude limit, landing, the emergency cut, and the
communication watchdog."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot.config import load_config
from drivers.ardrone.navdata import ControlState
from drivers.geometry import euler_from_quat
from drivers.sim.flight.ardrone import COM_LOST_S, Progressive
from drivers.sim.simulator import Simulator

HOVER = Progressive()


def _sim(*overrides: str) -> Simulator:
    cfg = load_config(None, ["sim.firmware=ardrone", "sim.profile=ideal", *overrides])
    return Simulator(cfg.sim)


def _fly(sim: Simulator, seconds: float, command: Progressive | None = HOVER,
         period_s: float = 0.03) -> list:
    """Send ``command`` every ``period_s`` (None: send nothing) for ``seconds``; the truth at
    each step."""
    out = []
    end = sim.time_s + seconds
    while sim.time_s < end - 1e-9:
        if command is not None:
            sim.command("pcmd", command)
        sim.advance_to(sim.time_s + period_s)
        out.append(sim.ground_truth())
    return out


def _height(truth) -> float:
    return -float(truth.vehicle.position_ned_m[2])


@pytest.fixture
def airborne() -> Simulator:
    sim = _sim()
    sim.advance_to(1.5)
    sim.command("ref", True)
    _fly(sim, 6.0)
    return sim


def test_takeoff_climbs_to_about_a_metre_and_hovers(airborne: Simulator) -> None:
    sim = airborne
    assert sim.flight.state is ControlState.HOVERING
    assert sim.flight.armed
    truth = _fly(sim, 3.0)
    heights = [_height(t) for t in truth]
    assert 0.85 < np.mean(heights) < 1.15
    assert max(np.linalg.norm(t.vehicle.velocity_ned_m_s[:2]) for t in truth) < 0.15


def test_a_progressive_pitch_is_a_tilt_not_a_velocity(airborne: Simulator) -> None:
    """pitch -0.5 is half of euler_angle_max (12°) nose down: the drone accelerates forward and
    its speed settles as the AR.Drone's does — tum_ardrone's model identified from flight data
    (v' = c1·(c2·sin θ − v), c1 = 0.58 /s, c2 = 17.8 m/s: 1.7 s to settle, after the attitude's
    own response, c3 = 10 /s: 0.1 s) — where a velocity command would level off at once."""
    sim = airborne
    limit = sim.flight.limits.euler_angle_max_rad
    truth = _fly(sim, 3.0, Progressive(pitch=-0.5, hover=False))
    pitches = [euler_from_quat(t.vehicle.attitude_q)[1] for t in truth[20:]]
    assert np.mean(pitches) == pytest.approx(-0.5 * limit, abs=0.01)
    c1, c2 = 0.58, 17.8
    settled = c2 * math.sin(0.5 * limit)
    for t in (1.0, 2.0, 3.0):
        speed = float(truth[round(t / 0.03) - 1].vehicle.velocity_ned_m_s[0])
        assert speed == pytest.approx(settled * (1.0 - math.exp(-c1 * (t - 0.1))), rel=0.15), t
    assert sim.flight.state is ControlState.FLYING
    # the hover brings the velocity back to zero (the drone's own velocity hold)
    truth = _fly(sim, 4.0)
    assert np.linalg.norm(truth[-1].vehicle.velocity_ned_m_s[:2]) < 0.2
    assert sim.flight.state is ControlState.HOVERING


def test_gaz_and_yaw_are_rates_of_their_limits(airborne: Simulator) -> None:
    sim = airborne
    lim = sim.flight.limits
    yaw0 = euler_from_quat(sim.ground_truth().vehicle.attitude_q)[2]
    truth = _fly(sim, 1.5, Progressive(gaz=0.5, yaw=0.25, hover=False))
    climb = -np.mean([t.vehicle.velocity_ned_m_s[2] for t in truth[15:]])
    assert climb == pytest.approx(0.5 * lim.control_vz_max_m_s, rel=0.2)
    yaw1 = euler_from_quat(truth[-1].vehicle.attitude_q)[2]
    turned = math.remainder(yaw1 - yaw0, 2 * math.pi)
    assert turned == pytest.approx(0.25 * lim.control_yaw_rad_s * 1.5, rel=0.25)


def test_it_never_climbs_above_altitude_max(airborne: Simulator) -> None:
    sim = airborne
    sim.flight.limits.altitude_max_m = 1.6
    truth = _fly(sim, 5.0, Progressive(gaz=1.0, hover=False))
    assert max(_height(t) for t in truth) < 1.75
    assert _height(truth[-1]) == pytest.approx(1.6, abs=0.1)


def test_landing_stops_the_motors_on_the_ground(airborne: Simulator) -> None:
    sim = airborne
    sim.command("ref", False)
    assert sim.flight.state is ControlState.LANDING
    _fly(sim, 5.0)
    assert sim.flight.state is ControlState.LANDED
    assert not sim.flight.armed
    assert _height(sim.ground_truth()) < 0.08


def test_emergency_cuts_the_motors_in_the_air_and_holds_until_reset(
        airborne: Simulator) -> None:
    sim = airborne
    sim.command("ref", True, True)
    assert not sim.flight.armed
    assert sim.flight.emergency
    _fly(sim, 1.0)
    assert _height(sim.ground_truth()) < 0.1  # it fell
    sim.command("ref", True)  # no takeoff in the emergency state
    assert not sim.flight.armed
    sim.command("ref", False, True)  # reset on the ground
    assert not sim.flight.emergency
    sim.command("ref", True)
    assert sim.flight.armed


def test_without_commands_it_takes_the_link_as_lost_and_hovers(airborne: Simulator) -> None:
    sim = airborne
    _fly(sim, 0.5, Progressive(pitch=-0.6, hover=False))
    assert sim.flight.state is ControlState.FLYING
    truth = _fly(sim, COM_LOST_S + 4.0, None)  # the client falls silent
    assert sim.flight.com_lost
    assert sim.flight.state is ControlState.HOVERING
    assert np.linalg.norm(truth[-1].vehicle.velocity_ned_m_s[:2]) < 0.2
    assert 0.7 < _height(truth[-1]) < 1.3
    _fly(sim, 0.1)
    assert not sim.flight.com_lost
