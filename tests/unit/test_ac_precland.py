"""ArduCopter's precision landing (AC_PrecLand and its retry state machine) as the simulated
ArduCopter flies it in LAND, driven tick by tick without an event loop: the behaviour
AC_PrecLand_StateMachine.cpp describes, with ArduPilot's texts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.sim.flight.ac_precland import AcPrecLand, Status, TargetState
from drivers.sim.flight.arducopter_params import ARDUCOPTER_PARAMS
from drivers.sim.flight.params import Parameters

DT = 0.05
TARGET = np.array([3.0, 1.0, 0.0])  # on the ground (local NED, the origin's height)


def _plnd(**values) -> tuple[AcPrecLand, list[str]]:
    params = Parameters({"PLND_ENABLED": 1, "PLND_TYPE": 1, **values}, ARDUCOPTER_PARAMS)
    texts: list[str] = []
    return AcPrecLand(params, texts.append), texts


class _Flight:
    """A vehicle that goes where the setpoints say (at most 1 m/s horizontally, 0.5 m/s down,
    2 m/s up) — enough to walk through the states."""

    def __init__(self, plnd: AcPrecLand, pos) -> None:
        self.plnd, self.pos, self.now = plnd, np.asarray(pos, float), 0.0
        plnd.activate(self.now, self.pos)

    def step(self, seen: bool = False, ground_down_m: float = 0.0):
        if seen:
            self.plnd.landing_target(self.now, TARGET)
        out = self.plnd.tick(self.now, self.pos, np.zeros(3), False, 0.0,
                             ground_down_m - self.pos[2])
        goal = out.position_ned_m.copy()
        if out.land:
            goal[2] = ground_down_m
        d = goal - self.pos
        d[:2] = d[:2] if np.hypot(*d[:2]) <= DT else d[:2] / np.hypot(*d[:2]) * DT
        d[2] = float(np.clip(d[2], -2 * DT, 0.5 * DT))
        self.pos = self.pos + d
        self.now += DT
        return out

    def run(self, seconds: float, **kwargs):
        out = None
        for _ in range(round(seconds / DT)):
            out = self.step(**kwargs)
        return out


def test_a_target_seen_is_acquired_after_the_kalman_filters_two_seconds_and_landed_on():
    plnd, texts = _plnd(PLND_XY_DIST_MAX=0.0)
    flight = _Flight(plnd, [0.0, 0.0, -5.0])
    flight.run(1.0, seen=True)
    # not yet acquired: as never seen, the failsafe holds (ArduCopter does the same)
    assert texts == ["PrecLand: Target Found", "PrecLand: Failsafe Measures"]
    assert plnd.target_state is TargetState.NEVER_SEEN
    assert plnd.status is Status.FAILSAFE
    flight.run(1.5, seen=True)
    assert "PrecLand: Init Complete" in texts
    out = flight.step(seen=True)
    assert plnd.target_state is TargetState.FOUND
    assert out.land
    assert out.position_ned_m[:2] == pytest.approx(TARGET[:2])


def test_the_raw_estimator_acquires_at_once_and_the_descent_waits_within_xy_dist_max():
    plnd, texts = _plnd(PLND_EST_TYPE=0)  # PLND_XY_DIST_MAX 2.5 m; the target 3.2 m away
    flight = _Flight(plnd, [0.0, 0.0, -5.0])
    out = flight.step(seen=True)
    assert texts == ["PrecLand: Target Found"]
    assert not out.land  # closing in first, at the height it is
    assert out.position_ned_m == pytest.approx([3.0, 1.0, -5.0])
    flight.run(2.0, seen=True)  # within 2.5 m now
    assert flight.step(seen=True).land


def test_a_lost_target_descends_plnd_timeout_then_retries_then_the_failsafe_hovers_and_lands():
    plnd, texts = _plnd(PLND_EST_TYPE=0, PLND_XY_DIST_MAX=0.0)
    flight = _Flight(plnd, [3.0, 1.0, -6.0])
    flight.run(1.0, seen=True)
    # unseen, the target stays acquired 2 s ("Target Lost" then; the descent goes on over it)
    flight.run(1.95)
    seen_at = flight.pos.copy()  # where the vehicle was when the target was last valid
    flight.run(0.15)
    assert "PrecLand: Target Lost" in texts
    assert plnd.target_state is TargetState.RECENTLY_LOST
    assert plnd.status is Status.DESCEND
    # PLND_TIMEOUT (4 s) after that: the retry
    flight.run(3.8)
    assert "PrecLand: Retrying" not in texts
    flight.run(0.3)
    assert texts[-1] == "PrecLand: Retrying"
    assert plnd.retry_count == 1
    out = flight.step()
    assert plnd.status is Status.RETRYING
    # to 1.5 m above where the vehicle was when it last saw the target (PLND_RET_BEHAVE 0)
    assert out.position_ned_m == pytest.approx(seen_at - [0.0, 0.0, 1.5], abs=0.08)
    for _ in range(200):  # up 1.5 m, then back down (within 0.75 m of that height)
        flight.step()
        if "PrecLand: Retry Completed" in texts:
            break
    assert "PrecLand: Retry Completed" in texts
    assert flight.pos[2] == pytest.approx(seen_at[2], abs=0.76)  # back down to that height
    # the retry found nothing: the failsafe (PLND_STRICT 1) hovers 7 s, then lands
    flight.step()
    assert texts[-1] == "PrecLand: Failsafe Measures"
    hover = flight.pos.copy()
    out = flight.run(6.8)
    assert not out.land
    assert flight.pos == pytest.approx(hover, abs=0.01)
    assert flight.run(0.3).land


def test_strictness_never_seen_and_out_of_range():
    # never seen, PLND_STRICT 2: it hovers for good; 0: it lands vertically at once
    plnd, texts = _plnd(PLND_STRICT=2)
    flight = _Flight(plnd, [0.0, 0.0, -5.0])
    assert not flight.run(20.0).land
    assert texts == ["PrecLand: Failsafe Measures"]
    plnd, texts = _plnd(PLND_STRICT=0)
    assert _Flight(plnd, [0.0, 0.0, -5.0]).step().land
    # above PLND_ALT_MAX (8 m) the target is out of range: descend, no failsafe
    plnd, texts = _plnd(PLND_STRICT=2)
    flight = _Flight(plnd, [0.0, 0.0, -12.0])
    assert flight.step().land
    assert plnd.target_state is TargetState.OUT_OF_RANGE
    assert texts == []
    # no retries allowed (PLND_RET_MAX 0): straight to the failsafe once PLND_TIMEOUT is over
    plnd, texts = _plnd(PLND_EST_TYPE=0, PLND_RET_MAX=0, PLND_XY_DIST_MAX=0.0)
    flight = _Flight(plnd, [3.0, 1.0, -6.0])
    flight.run(0.5, seen=True)
    flight.run(6.5)
    assert "PrecLand: Retrying" not in texts
    assert texts[-1] == "PrecLand: Failsafe Measures"
    assert math.isfinite(flight.pos[2])
