"""The failsafe behaviours (autopilot/behaviors/flight.py) without an event loop: the return
home keeps the vehicle's return, or lands where it is."""

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status, VehicleRequest
from autopilot.behaviors.flight import ReturnHome
from drivers.base import FlightMode

from ..factories import vehicle_state


def _tick(step: ReturnHome, t: float, mode: FlightMode, **kw):
    return step.update(BehaviorInputs(now_s=t, state=vehicle_state(t, mode=mode, **kw)))


def _kinds(out) -> list[RequestKind]:
    return [r.kind for r in out.requests]


def test_return_home_asks_for_the_vehicles_return_and_waits_for_the_disarm():
    step = ReturnHome(engage_s=3.0)
    first = step.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    assert _kinds(first) == [RequestKind.RETURN]
    # the mode switch takes a moment; RTL, then its landing: no new request
    for t, mode in [(1.0, FlightMode.OFFBOARD), (2.0, FlightMode.RETURN),
                    (30.0, FlightMode.RETURN), (60.0, FlightMode.LAND)]:
        out = _tick(step, t, mode)
        assert out.status is Status.RUNNING
        assert out.requests == ()
    done = _tick(step, 70.0, FlightMode.LAND, armed=False, in_air=False)
    assert done.status is Status.SUCCEEDED


def test_a_return_taken_away_or_never_taken_up_lands_where_it_is_once():
    step = ReturnHome(engage_s=3.0)
    step.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    assert _tick(step, 1.0, FlightMode.RETURN).requests == ()
    # a hold (the geofence's, a ground station's) for less than engage_s: waits
    assert _tick(step, 2.0, FlightMode.HOLD).requests == ()
    assert _tick(step, 4.5, FlightMode.HOLD).requests == ()
    out = _tick(step, 5.0, FlightMode.HOLD)
    assert _kinds(out) == [RequestKind.LAND]
    assert out.phase == "landing"
    # a mode changed after that (the pilot's) is not fought
    assert _tick(step, 20.0, FlightMode.POSCTL).requests == ()
    assert _tick(step, 30.0, FlightMode.POSCTL).status is Status.RUNNING
    # never taken up at all
    stuck = ReturnHome(engage_s=3.0)
    stuck.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    assert _tick(stuck, 2.0, FlightMode.OFFBOARD).requests == ()
    assert _kinds(_tick(stuck, 3.5, FlightMode.OFFBOARD)) == [RequestKind.LAND]


def test_a_refused_return_lands_and_a_timeout_fails():
    step = ReturnHome(timeout_s=100.0)
    step.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    out = step.request_failed(VehicleRequest(RequestKind.RETURN), "denied")
    assert _kinds(out) == [RequestKind.LAND]
    assert _tick(step, 101.0, FlightMode.LAND).status is Status.FAILED
    # on the ground and disarmed already: nothing to do
    ground = ReturnHome().activate(BehaviorInputs(
        now_s=0.0, state=vehicle_state(0.0, armed=False, in_air=False)))
    assert ground.status is Status.SUCCEEDED


def test_back_from_manual_flight_a_landing_stays_a_landing_and_the_clock_runs_on():
    step = ReturnHome(timeout_s=100.0, engage_s=3.0)
    step.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    assert _kinds(step.request_failed(VehicleRequest(RequestKind.RETURN), "denied")) == \
        [RequestKind.LAND]
    # the pilot flew for a while, then gave the vehicle back: it lands, it does not return
    again = step.activate(BehaviorInputs(now_s=60.0, state=vehicle_state(60.0)))
    assert _kinds(again) == [RequestKind.LAND]
    assert again.phase == "landing"
    assert _tick(step, 101.0, FlightMode.LAND).status is Status.FAILED
    # a return not yet given up on asks for the return again
    fresh = ReturnHome(engage_s=3.0)
    fresh.activate(BehaviorInputs(now_s=0.0, state=vehicle_state(0.0)))
    assert _kinds(fresh.activate(BehaviorInputs(now_s=9.0, state=vehicle_state(9.0)))) == \
        [RequestKind.RETURN]
