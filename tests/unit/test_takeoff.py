"""The takeoff step: done at altitude once out of the takeoff mode (PX4 HOLD, ArduPilot GUIDED)."""

import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status
from autopilot.behaviors.flight import Takeoff, TakeoffParams
from drivers.base import FlightMode

from ..factories import vehicle_state


def _step(mode: FlightMode, altitude_m: float) -> Status:
    takeoff = Takeoff(TakeoffParams(altitude_m=2.0))
    ground = vehicle_state(0.0, pos=(0, 0, 0.0), mode=FlightMode.HOLD, armed=False,
                           in_air=False)
    first = takeoff.activate(BehaviorInputs(now_s=0.0, state=ground))
    assert [r.kind for r in first.requests] == [RequestKind.ARM, RequestKind.TAKEOFF]
    state = vehicle_state(5.0, pos=(0, 0, -altitude_m), mode=mode)
    return takeoff.update(BehaviorInputs(now_s=5.0, state=state)).status


@pytest.mark.parametrize("mode", [FlightMode.HOLD, FlightMode.OFFBOARD])
def test_done_at_altitude_in_hold_or_guided(mode):
    assert _step(mode, 1.9) is Status.SUCCEEDED


@pytest.mark.parametrize(("mode", "altitude_m"), [
    (FlightMode.TAKEOFF, 2.0),  # still climbing in PX4's TAKEOFF
    (FlightMode.HOLD, 1.2),     # a stale HOLD from before the climb: not there yet
    (FlightMode.LAND, 2.0),
])
def test_not_done_while_climbing_or_elsewhere(mode, altitude_m):
    assert _step(mode, altitude_m) is Status.RUNNING
