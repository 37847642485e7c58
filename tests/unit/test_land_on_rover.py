"""The land_on_rover behaviour (seed 004) driven by hand, without a simulator: approach from
behind, align, descend in the cone, commit, cut the motors at contact, settle; abort and climb
when the error or the uncertainty grows near the deck; bounded retries; no estimate."""

import dataclasses
import math

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status
from autopilot.behaviors.land_on_rover import (
    LandOnRover,
    LandOnRoverParams,
    LandOnRoverSettings,
)
from autopilot.estimation.target import TargetEstimate
from autopilot.mission import load_mission
from drivers.base import Battery, FlightMode, Health, LandedState, VehicleState
from drivers.geometry import quat_from_euler

DECK_Z = -0.45
V_ROVER = np.array([1.5, 0.0, 0.0])


def _state(t, pos, vel=V_ROVER, *, armed=True, range_m=None):
    pos = np.asarray(pos, dtype=float)
    rng = (pos[2] - DECK_Z) * -1.0 if range_m is None else range_m
    return VehicleState(t, pos, np.asarray(vel, dtype=float), quat_from_euler(0.0, 0.0, 0.0),
                        (0.0, 0.0, 0.0), armed, FlightMode.OFFBOARD,
                        LandedState.IN_AIR if armed else LandedState.ON_GROUND, rng,
                        Battery(16.0, 10.0, 0.9), Health())


def _deck(t, x0=5.0, sigma=0.02, stale=False, heading=0.0):
    """The deck's estimate at time t (moving north at 1.5 m/s from x0)."""
    cov = np.eye(6) * sigma ** 2
    return TargetEstimate(t, np.array([x0 + 1.5 * t, 0.0, DECK_Z]), V_ROVER.copy(), cov,
                          0.05, stale, 100, True, kind="deck", heading_rad=heading,
                          heading_rate_rad_s=0.0, heading_std_rad=0.02,
                          acceleration_ned_m_s2=np.zeros(3))


def _landing(**params):
    return LandOnRover(LandOnRoverParams(**params), LandOnRoverSettings((1.0, 0.8), 0.45))


def _tick(b, t, pos, target, **state):
    return b.update(BehaviorInputs(t, _state(t, pos, **state), target=target))


def test_the_landing_goes_through_its_phases_and_cuts_the_motors_at_contact():
    b = _landing()
    out = b.activate(BehaviorInputs(0.0, _state(0.0, (0.0, 0.0, -3.0))))
    assert out.requests[0].kind is RequestKind.START_OFFBOARD
    out = _tick(b, 0.05, (0.0, 0.0, -3.0), _deck(0.05))
    assert out.phase == "approaching"
    # the first setpoint: behind the deck and above it, moving with it, never far ahead of
    # the vehicle (the closing speed is bounded)
    sp = out.setpoint
    assert np.allclose(sp.velocity_m_s[:2], V_ROVER[:2])
    assert np.linalg.norm(sp.position_ned_m[:2] - (0.0, 0.0)) <= 4.0 / 1.8 + 1e-6
    phases = ["approaching"]
    t = 0.1
    for _ in range(400):
        deck = _deck(t)
        goal = deck.position_ned_m + np.array([0.0, 0.0, -3.0]) if out is None or \
            out.setpoint is None else np.array(out.setpoint.position_ned_m, dtype=float)
        out = _tick(b, t, goal, deck)
        phases.append(out.phase)
        if out.requests:
            break
        t += 0.05
    assert [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p] == [
        "approaching", "aligning", "descending", "committed", "touching down"]
    assert out.requests[0].kind is RequestKind.DISARM
    assert out.requests[0].force  # the motors are cut in the air, at contact
    # done once disarmed and resting on the deck (moving with it)
    pos = _deck(t).position_ned_m + np.array([0.0, 0.0, -0.1])
    assert _tick(b, t + 0.1, pos, _deck(t + 0.1), armed=False).status is Status.RUNNING
    assert _tick(b, t + 0.7, pos, _deck(t + 0.7), armed=False).status is Status.SUCCEEDED


def test_the_descent_moves_with_the_deck_and_feeds_its_motion_forward():
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase = "descending"
    deck = _deck(1.0)
    deck = TargetEstimate(**{**{f: getattr(deck, f) for f in deck.__dataclass_fields__},
                             "acceleration_ned_m_s2": np.array([-1.0, 0.0, 0.0])})
    out = _tick(b, 1.0, deck.position_ned_m + np.array([0.0, 0.0, -2.0]), deck)
    assert out.setpoint.velocity_m_s[0] == pytest.approx(1.5)
    assert out.setpoint.velocity_m_s[2] > 0.0  # going down
    assert out.setpoint.acceleration_m_s2[0] == pytest.approx(-1.0)  # the rover brakes


def test_an_error_near_the_deck_aborts_climbs_and_retries_a_bounded_number_of_times():
    b = _landing(max_retries=1)
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase = "descending"
    b._height_ref = 1.0
    deck = _deck(1.0)
    # 0.3 m off at 0.8 m up
    out = _tick(b, 1.0, deck.position_ned_m + np.array([0.3, 0.0, -0.8]), deck)
    assert out.phase == "aborting"
    assert b.retries == 1
    assert "off the deck's centre" in b.abort_reasons[0]
    assert out.setpoint.position_ned_m[2] == pytest.approx(DECK_Z - 3.0)  # back up
    assert out.setpoint.velocity_m_s[0] == pytest.approx(1.5)  # still moving with it
    # up again: align, descend, and the same again → out of retries: the step fails
    out = _tick(b, 3.0, _deck(3.0).position_ned_m + np.array([0.0, 0.0, -3.0]), _deck(3.0))
    assert out.phase == "aligning"
    b.phase = "descending"
    out = _tick(b, 3.1, _deck(3.1).position_ned_m + np.array([0.3, 0.0, -0.8]), _deck(3.1))
    assert out.status is Status.FAILED
    assert "aborted 2 times" in out.reason


def test_an_uncertain_estimate_pauses_the_descent_then_aborts_near_the_deck():
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase = "descending"
    b._height_ref = 2.0
    # 2σ = 0.6 m at 2 m up: more than the deck allows there (0.28 + 0.15 × 1.65): hold
    deck = _deck(1.0, sigma=0.3)
    out = _tick(b, 1.0, deck.position_ned_m + np.array([0.0, 0.0, -2.0]), deck)
    assert out.phase == "descending"
    assert out.setpoint.velocity_m_s[2] == 0.0
    # lower down, the same uncertainty aborts
    b._height_ref = 0.8
    deck = _deck(1.1, sigma=0.3)
    out = _tick(b, 1.1, deck.position_ned_m + np.array([0.0, 0.0, -0.8]), deck)
    assert out.phase == "aborting"
    assert "uncertain" in b.abort_reasons[-1]


def test_committed_does_not_abort_and_a_stale_estimate_aborts_above_it():
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase, b._height_ref = "committed", 0.3
    deck = _deck(1.0, sigma=0.3)
    out = _tick(b, 1.0, deck.position_ned_m + np.array([0.25, 0.0, -0.3]), deck)
    assert out.phase == "committed"
    stale = _deck(1.1, stale=True)
    out = _tick(b, 1.1, stale.position_ned_m + np.array([0.0, 0.0, -0.3]), stale)
    assert out.phase == "committed"  # blind this close: on down
    assert out.setpoint.velocity_m_s[2] > 0.0
    b2 = _landing()
    b2.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b2.phase, b2._height_ref = "descending", 1.0
    out = _tick(b2, 1.0, (6.5, 0.0, -1.5), _deck(1.0, stale=True))
    assert out.phase == "aborting"
    assert b2.retries == 1


def test_no_estimate_at_all_fails_with_a_clear_reason():
    b = _landing(wait_timeout_s=2.0)
    b.activate(BehaviorInputs(0.0, _state(0.0, (0.0, 0.0, -3.0))))
    out = _tick(b, 1.0, (0.0, 0.0, -3.0), None)
    assert out.phase == "waiting"
    assert out.status is Status.RUNNING
    out = _tick(b, 2.5, (0.0, 0.0, -3.0), None)
    assert out.status is Status.FAILED
    assert "no estimate of the rover's deck" in out.reason


def test_contact_is_also_detected_when_the_descent_stalls():
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase, b._height_ref, b._phase_since = "committed", 0.25, 0.0
    # no rangefinder reading (NaN) and no relative descent: stalled on the deck
    for k in range(12):
        t = 1.0 + 0.05 * k
        out = _tick(b, t, _deck(t).position_ned_m + np.array([0.0, 0.0, -0.25]), _deck(t),
                    range_m=math.nan)
        if out.requests:
            break
    assert out.requests[0].kind is RequestKind.DISARM


def test_motors_are_not_cut_once_the_vehicle_s_own_failsafe_has_taken_over():
    """A failsafe landing (GPS lost: the vehicle's LAND) in the final descent no longer follows
    the deck: the step fails without cutting the motors (found by `autopilot bench faults` on
    the ArduCopter firmware: the cut dropped the vehicle beside the rover)."""
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase, b._height_ref, b._phase_since = "committed", 0.25, 0.0
    t = 1.0
    pos = _deck(t).position_ned_m + np.array([0.0, 0.0, -0.05])  # at the touchdown height
    state = dataclasses.replace(_state(t, pos), mode=FlightMode.LAND, failsafe=True)
    out = b.update(BehaviorInputs(t, state, target=_deck(t)))
    assert out.status is Status.FAILED
    assert "motors not cut" in out.reason
    assert not any(r.kind is RequestKind.DISARM for r in out.requests)
    b2 = _landing()  # the same moment under offboard control: the motors are cut
    b2.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b2.phase, b2._height_ref, b2._phase_since = "committed", 0.25, 0.0
    out = b2.update(BehaviorInputs(t, _state(t, pos), target=_deck(t)))
    assert out.requests[0].kind is RequestKind.DISARM


def test_the_step_validates_its_heights():
    with pytest.raises(Exception, match="commit_height_m"):
        load_mission("land_on_rover", ["steps.1.land_on_rover.commit_height_m=4",
                                       "steps.1.land_on_rover.approach_height_m=3"])
    plan = load_mission("land_on_rover", ["steps.1.land_on_rover.use_marker=false"])
    assert plan.steps[1].params.use_marker is False


def test_a_vehicle_that_ends_on_the_ground_beside_the_deck_has_not_landed_on_it():
    b = _landing()
    b.activate(BehaviorInputs(0.0, _state(0.0, (5.0, 0.0, -3.0))))
    b.phase, b._phase_since = "touching down", 1.0
    # disarmed, standing on something 0.095 m below the body, but 0.36 m below the deck's top:
    # the ground beside the rover
    for t in (1.5, 2.5, 4.1):
        pos = _deck(t).position_ned_m + np.array([1.2, 0.0, 0.36])
        out = _tick(b, t, pos, _deck(t), armed=False, range_m=0.095, vel=(0.0, 0.0, 0.0))
    assert out.status is Status.FAILED
    assert "did not come to rest on the deck" in out.reason
