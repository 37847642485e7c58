"""The land_pad behaviour (precision landing, seed 001): search, align, descend in a cone over
the pad, commit near the ground, hand the touchdown to LAND; and when the pad is lost: hold,
climb and look again, a bounded number of times, then fail (the mission's fallback lands)."""

import math

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status, VehicleRequest
from autopilot.behaviors.land_pad import LandPad, LandPadParams, LandPadSettings
from autopilot.config import ConfigError
from autopilot.estimation.target import TargetEstimate
from autopilot.mission import load_mission
from drivers.base import FlightMode

from ..factories import vehicle_state

PAD = (4.0, -2.0, 0.0)


def _pad(t, centre=PAD, age=0.0):
    return TargetEstimate(t, np.array(centre, float), np.zeros(3), np.eye(6) * 1e-4, age,
                          False, 20, True, kind="pad")


def _landing(**params):
    return LandPad(LandPadParams(**params), LandPadSettings(lost_after_s=0.5))


def _fly(behavior, t, pos, target=None, vel=(0.0, 0.0, 0.0), **state):
    return behavior.update(BehaviorInputs(t, vehicle_state(t, pos=pos, vel=vel, **state),
                                          target=target))


def test_searches_at_the_search_altitude_then_fails_when_nothing_is_found():
    land = _landing(search_altitude_m=6.0, search_timeout_s=20.0, search_radius_m=4.0)
    out = land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -3.0))))
    assert out.requests[0].kind is RequestKind.START_OFFBOARD
    out = _fly(land, 0.1, (0.0, 0.0, -3.0))
    assert out.phase == "searching"
    assert out.setpoint.position_ned_m == pytest.approx((0.0, 0.0, -6.0))  # climb first
    out = _fly(land, 5.0, (0.0, 0.0, -6.0))  # then out along the expanding square
    assert out.phase == "searching"
    assert out.setpoint.position_ned_m == pytest.approx((2.0, 0.0, -6.0))  # north, 2 m ahead
    # one ring (6 m up the camera sees 0.8 × (1.2 × 6 − 0.8) = 5.1 m wide: ≥ the radius)
    assert [tuple(c) for c in land._search.waypoints[1:3]] == [(4.0, 0.0), (4.0, 4.0)]
    out = _fly(land, 20.5, (1.0, 1.0, -6.0))
    assert out.status is Status.FAILED
    assert "not found" in out.reason


def _descend_to(land, t, height_m):
    """Aligned over the pad, then down to ``height_m``; returns the time."""
    out = _fly(land, t, (PAD[0], PAD[1], -6.0), _pad(t))
    assert out.phase == "aligning"
    assert out.setpoint.position_ned_m[:2] == pytest.approx(PAD[:2], abs=1e-6)
    t += 1.1
    out = _fly(land, t, (PAD[0], PAD[1], -6.0), _pad(t))
    assert out.phase == "descending"
    z_ref = -6.0
    for _ in range(400):
        t += 0.1
        out = _fly(land, t, (PAD[0], PAD[1], z_ref), _pad(t))
        assert out.setpoint.position_ned_m[2] >= z_ref - 1e-9  # only ever down
        z_ref = out.setpoint.position_ned_m[2]
        if out.phase != "descending" or -z_ref <= height_m:
            break
    return t, out


def test_aligns_descends_commits_and_hands_the_touchdown_to_land():
    land = _landing(commit_height_m=0.5, touchdown_height_m=0.15)
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    t, out = _descend_to(land, 0.1, 0.5)
    assert out.phase == "descending"
    t += 0.1
    out = _fly(land, t, (PAD[0], PAD[1], -0.48), _pad(t))
    assert out.phase == "committed"
    # committed: losing the pad near the ground no longer stops the descent
    for _ in range(5):
        t += 0.2
        out = _fly(land, t, (PAD[0], PAD[1], -0.3), vel=(0.0, 0.0, 0.3))
        assert out.phase == "committed"
        assert out.status is Status.RUNNING
        assert out.setpoint.position_ned_m[:2] == pytest.approx(PAD[:2], abs=1e-6)
    out = _fly(land, t + 0.2, (PAD[0], PAD[1], -0.1), vel=(0.0, 0.0, 0.3))
    assert out.phase == "touching down"
    assert out.requests[0].kind is RequestKind.LAND
    out = _fly(land, t + 2.0, (PAD[0], PAD[1], 0.0), armed=False, in_air=False)
    assert out.status is Status.SUCCEEDED


def test_the_descent_pauses_outside_the_cone_over_the_pad():
    land = _landing(acceptance_radius_m=0.1, cone_slope=0.15)
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    _fly(land, 0.1, (PAD[0], PAD[1], -6.0), _pad(0.1))
    out = _fly(land, 1.2, (PAD[0], PAD[1], -6.0), _pad(1.2))
    assert out.phase == "descending"
    z = out.setpoint.position_ned_m[2]
    # pushed 1.5 m off at 6 m: outside 0.1 + 0.15 × 6 = 1.0 m, the height reference holds
    for k in range(10):
        t = 1.3 + 0.1 * k
        out = _fly(land, t, (PAD[0] + 1.5, PAD[1], z), _pad(t))
        assert out.setpoint.position_ned_m[2] == pytest.approx(z)
    out = _fly(land, 2.5, (PAD[0] + 0.3, PAD[1], z), _pad(2.5))
    assert out.setpoint.position_ned_m[2] > z


def test_lost_pad_climbs_to_look_again_then_fails_after_the_retries():
    land = _landing(max_retries=2, lost_timeout_s=2.0, reacquire_climb_m=1.5)
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    t, out = _descend_to(land, 0.1, 3.0)
    for attempt in range(1, 3):
        height = -out.setpoint.position_ned_m[2]
        here = (PAD[0] + 0.05, PAD[1], -height)
        t += 0.7  # the estimate goes stale
        out = _fly(land, t, here, _pad(t - 0.7, age=0.7))
        assert out.phase == "lost"
        assert out.setpoint.position_ned_m == pytest.approx(here)  # hold where it was lost
        out = _fly(land, t + 1.0, here)
        assert out.phase == "lost"
        t += 2.1
        out = _fly(land, t, here)
        assert out.phase == "reacquiring"
        assert land.retries == attempt
        # climbs over where the pad was last seen
        assert out.setpoint.position_ned_m == pytest.approx(
            (PAD[0], PAD[1], -min(height + 1.5, 6.0)))
        t += 1.0
        out = _fly(land, t, out.setpoint.position_ned_m, _pad(t))  # seen again
        assert out.phase == "aligning"
        t += 1.1
        out = _fly(land, t, (PAD[0], PAD[1], out.setpoint.position_ned_m[2]), _pad(t))
        assert out.phase == "descending"
    t += 0.7
    out = _fly(land, t, (PAD[0], PAD[1], -4.0), _pad(t - 0.7, age=0.7))
    assert out.phase == "lost"
    out = _fly(land, t + 2.1, (PAD[0], PAD[1], -4.0))
    assert out.status is Status.FAILED
    assert "2 retries" in out.reason


def test_the_trim_cancels_a_steady_offset_over_the_pad():
    land = _landing(trim_gain_per_s=0.6, max_trim_m=0.3)
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    # the vehicle sits 5 cm south of its setpoint: the setpoint walks north until it is over
    t = 0.1
    for _ in range(100):
        out = _fly(land, t, (PAD[0] - 0.05, PAD[1], -6.0), _pad(t))
        t += 0.1
    assert out.setpoint.position_ned_m[0] - PAD[0] == pytest.approx(0.05 * 0.6 * 9.9,
                                                                    rel=0.05)
    for _ in range(100):  # never beyond max_trim_m
        out = _fly(land, t, (PAD[0] - 0.05, PAD[1], -6.0), _pad(t))
        t += 0.1
    assert math.hypot(*(np.array(out.setpoint.position_ned_m[:2]) - PAD[:2])) == \
        pytest.approx(0.3)


@pytest.mark.parametrize(("override", "message"), [
    ("steps.1.land_pad.pad=square", "pad"),
    ("steps.1.land_pad.color=purple", "color"),
    ("steps.1.land_pad.method=autoland", "method"),
    ("steps.1.land_pad.commit_height_m=-1", "commit_height_m"),
    ("steps.1.land_pad.unknown_key=1", "unknown_key"),
])
def test_bad_step_parameters_are_named(override, message):
    with pytest.raises(ConfigError) as err:
        load_mission("land_pad", [override])
    assert message in str(err.value)


@pytest.mark.parametrize(("override", "message"), [
    ("scenario.pad.kind=triangle", "scenario.pad.kind"),
    ("scenario.pad.size_m=0", "scenario.pad.size_m"),
    ("scenario.pad.color=purple", "scenario.pad.color"),
    ("scenario.decoys=[3, 4]", "decoys"),
])
def test_bad_scenario_keys_are_named(override, message):
    with pytest.raises(ConfigError) as err:
        load_mission("land_pad", [override])
    assert message in str(err.value)


def test_too_many_decoy_marker_pads_for_the_dictionary_are_refused():
    with pytest.raises(ConfigError) as err:
        load_mission("land_pad", ["scenario.pad.kind=markers", "scenario.decoys=12"])
    # named at the argument the user typed, not at the mission file's scenario line
    assert "--set: scenario.decoys: 12 decoy marker pads need marker ids" in str(err.value)


def test_px4_precland_hands_the_descent_to_px4_and_streams_the_target():
    land = _landing(method="px4_precland")
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    _fly(land, 0.1, (PAD[0], PAD[1], -6.0), _pad(0.1))
    out = _fly(land, 1.2, (PAD[0], PAD[1], -6.0), _pad(1.2))
    assert out.phase == "precision landing"
    assert out.setpoint is None  # no offboard setpoints: PX4 flies
    kinds = [r.kind for r in out.requests]
    assert kinds == [RequestKind.LANDING_TARGET, RequestKind.PRECISION_LAND]
    assert out.requests[0].position_ned_m == pytest.approx(PAD)
    # while the pad is seen, its estimate goes to PX4; not seen, nothing goes
    out = _fly(land, 1.3, (PAD[0], PAD[1], -5.9), _pad(1.3, centre=(4.02, -2.0, 0.0)),
               mode=FlightMode.PRECLAND)
    assert [r.kind for r in out.requests] == [RequestKind.LANDING_TARGET]
    assert out.requests[0].position_ned_m == pytest.approx((4.02, -2.0, 0.0))
    out = _fly(land, 2.5, (PAD[0], PAD[1], -5.0), _pad(1.3, age=1.2), mode=FlightMode.PRECLAND)
    assert out.requests == ()
    assert out.status is Status.RUNNING
    out = _fly(land, 20.0, (PAD[0], PAD[1], 0.0), mode=FlightMode.PRECLAND, armed=False,
               in_air=False)
    assert out.status is Status.SUCCEEDED


def test_px4_precland_interrupted_in_the_air_fails_the_step():
    land = _landing(method="px4_precland")
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    _fly(land, 0.1, (PAD[0], PAD[1], -6.0), _pad(0.1))
    assert _fly(land, 1.2, (PAD[0], PAD[1], -6.0), _pad(1.2)).phase == "precision landing"
    # the mode change shows a little later: OFFBOARD at first is not an interruption
    assert _fly(land, 1.5, (PAD[0], PAD[1], -6.0)).status is Status.RUNNING
    out = _fly(land, 3.0, (PAD[0], PAD[1], -5.0), mode=FlightMode.HOLD)
    assert out.status is Status.FAILED
    assert "interrupted" in out.reason


def test_a_refused_hand_over_is_flown_by_the_step_itself():
    """The vehicle refuses its precision landing (ArduCopter with PLND_ENABLED 0): still over
    the pad under this step's setpoints, the step descends onto it; any other refusal, or
    one outside the hand-over, fails the step."""
    land = _landing(method="vehicle_precland")
    land.activate(BehaviorInputs(0.0, vehicle_state(0.0, pos=(0.0, 0.0, -6.0))))
    _fly(land, 0.1, (PAD[0], PAD[1], -6.0), _pad(0.1))
    out = _fly(land, 1.2, (PAD[0], PAD[1], -6.0), _pad(1.2))
    handed = out.requests[-1]
    assert handed.kind is RequestKind.PRECISION_LAND
    out = land.request_failed(handed, "precision land denied: PLND_ENABLED is 0")
    assert out.status is Status.RUNNING
    assert land.phase == "descending"
    out = _fly(land, 1.3, (PAD[0], PAD[1], -6.0), _pad(1.3), mode=FlightMode.OFFBOARD)
    assert out.status is Status.RUNNING
    assert out.setpoint is not None
    assert out.setpoint.velocity_m_s[2] > 0.0  # down, over the pad
    assert out.setpoint.position_ned_m[:2] == pytest.approx(PAD[:2], abs=0.01)
    assert RequestKind.PRECISION_LAND not in [r.kind for r in out.requests]
    out = land.request_failed(VehicleRequest(RequestKind.LAND), "denied")
    assert out.status is Status.FAILED


def test_a_detector_that_cannot_find_the_pad_is_refused_before_flying():
    with pytest.raises(ConfigError) as err:
        load_mission("land_pad", ["config.perception.pad.detector=seed001",
                                  "steps.1.land_pad.pad=markers"])
    assert "steps.1.land_pad" in str(err.value)
    assert "seed001" in str(err.value)
