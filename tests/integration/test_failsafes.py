"""The autopilot's own failsafes in closed loop, in lockstep: the battery reserve for the way
home, a detector, estimator or step that raises, a loop stall the vehicle waited for. (The
event loop's watchdog on the wall clock is in test_failsafes_realtime.py; the geofence in
test_offboard.py; the target lost, stale telemetry and a stalled control task in
test_runtime.py.)"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from autopilot.control.battery import BatteryReserve, ReserveSettings
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.runtime import LAND_RETRY_S
from drivers.base import CommandDenied
from drivers.sim.driver import SimDriver

from .simtools import ended_down, fly_short

_fly = fly_short


# -- the battery reserve ---------------------------------------------------------------------

def test_reserve_counts_the_way_home():
    r = BatteryReserve(ReserveSettings(0.2, speed_m_s=5.0, descent_m_s=1.0, margin=1.0))
    home = np.zeros(3)
    # draining 1 %/s: 100 m out and 10 m up is 20 s + 10 s of flight = 30 %
    for t in range(0, 11):
        call = r.check(float(t), 0.9 - 0.01 * t, (100.0, 0.0, -10.0), home, True)
        assert call is None
    assert r.drain_per_s == pytest.approx(0.01)
    assert r.needed_fraction == pytest.approx(0.30)
    t, remaining = 10.0, 0.8
    while (call := r.check(t, remaining, (100.0, 0.0, -10.0), home, True)) is None:
        t, remaining = t + 1.0, remaining - 0.01
    assert remaining == pytest.approx(0.5, abs=0.011)  # 0.5 - 0.3 = the reserve
    assert call.go_home
    assert "getting home" in call.reason
    # near home: a landing, not a return; a sagged battery triggers at once; off when 0
    near = BatteryReserve(ReserveSettings(0.2, 5.0, 1.0, 1.0))
    call = near.check(0.0, 0.15, (1.0, 1.0, -3.0), home, True)
    assert call is not None
    assert not call.go_home
    assert BatteryReserve(ReserveSettings(0.0, 5.0, 1.0, 1.0)).check(
        0.0, 0.01, (1.0, 1.0, -3.0), home, True) is None
    assert near.check(1.0, math.nan, (1.0, 1.0, -3.0), home, True) is None
    # a return that climbs to RTL_RETURN_ALT first (40 m at 3 m/s: 10 s up, 40 s down)
    up = BatteryReserve(ReserveSettings(0.2, 5.0, 1.0, 1.0, return_altitude_m=40.0,
                                        climb_m_s=3.0))
    for t in range(0, 11):
        up.check(float(t), 0.95 - 0.01 * t, (100.0, 0.0, -10.0), home, True)
    assert up.needed_fraction == pytest.approx(0.70)
    # PX4's landing descends at MPC_Z_V_AUTO_DN (2 m/s here) down to MPC_LAND_ALT1 (10 m),
    # then at the landing speed (1 m/s): 40 m is 15 s + 10 s, not 40 s
    fast = BatteryReserve(ReserveSettings(0.2, 5.0, 1.0, 1.0, return_altitude_m=40.0,
                                          climb_m_s=3.0, fast_descent_m_s=2.0,
                                          slow_below_m=10.0))
    for t in range(0, 11):
        fast.check(float(t), 0.95 - 0.01 * t, (100.0, 0.0, -10.0), home, True)
    assert fast.needed_fraction == pytest.approx(0.55)
    # action land: it lands where it is, so the way home and the climb are not counted
    here = BatteryReserve(ReserveSettings(0.2, 5.0, 1.0, 1.0, return_altitude_m=40.0,
                                          climb_m_s=3.0, land_here=True))
    for t in range(0, 11):
        call = here.check(float(t), 0.95 - 0.01 * t, (100.0, 0.0, -10.0), home, True)
    assert here.needed_fraction == pytest.approx(0.10)
    call = here.check(11.0, 0.15, (100.0, 0.0, -10.0), home, True)
    assert call is not None
    assert not call.go_home


def test_battery_reserve_returns_home_and_lands(tmp_path):
    # at 12 s the battery sags to 15 %: under the 20 % reserve, the vehicle goes home
    summary, orphans = _fly(["failsafe.battery.reserve_fraction=0.2",
                             'scenario.faults=[{kind: battery_sag, start_s: 12, '
                             'remaining_fraction: 0.15}]'], tmp_path)
    assert summary["status"] == "aborted"
    assert "battery reserve" in summary["reason"]
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    texts = [e["text"] for e in log[ch.MISSION_EVENTS]]
    assert "request return" in texts
    assert "fallback return_home started" in texts
    ended_down(log)
    truth = np.array([r["vehicle_position_ned_m"] for r in log[ch.GROUND_TRUTH]])
    far = np.linalg.norm(truth[:, :2], axis=1)
    assert far.max() > 3.0  # it had followed away from home (beyond the 3 m home radius) ...
    assert far[-1] < 1.0  # ... and landed at home
    assert summary["metrics"]["safety"]["ended_safe"] is True


def test_a_return_that_climbs_into_the_fence_ceiling_lands_where_it_is(monkeypatch, tmp_path):
    # the vehicle's RTL climbs to RTL_RETURN_ALT (20 m), the autopilot's fence stops at 6 m:
    # the breach during the fallback lands the vehicle where it is (not a hold, not home);
    # the vehicle refuses that first land (a busy flight stack): asked again, it lands
    land = SimDriver.land
    refused: list[int] = []

    async def refuse_once(driver):
        if not refused:
            refused.append(1)
            raise CommandDenied("land", "temporarily rejected (test)")
        await land(driver)

    monkeypatch.setattr(SimDriver, "land", refuse_once)
    summary, orphans = _fly(["failsafe.battery.reserve_fraction=0.2",
                             "failsafe.geofence.max_altitude_m=6",
                             "sim.params={RTL_RETURN_ALT: 20}",
                             'scenario.faults=[{kind: battery_sag, start_s: 12, '
                             'remaining_fraction: 0.15}]'], tmp_path)
    assert summary["status"] == "aborted"
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    texts = [e["text"] for e in log[ch.MISSION_EVENTS]]
    assert "fallback return_home started" in texts
    assert any("geofence during the fallback: landing where it is" in t for t in texts)
    assert refused
    assert any(t.startswith("land refused") for t in texts)
    ended_down(log)
    truth = np.array([r["vehicle_position_ned_m"] for r in log[ch.GROUND_TRUTH]])
    # stopped within the fence's margin, plus the climb (3 m/s) until the land asked again
    assert -truth[:, 2].min() < 6.0 + 2.0 + 3.0 * LAND_RETRY_S
    modes = [r["mode"] for r in log[ch.VEHICLE_STATE] if r["armed"]]
    assert modes[modes.index("return"):][-1] == "land"
    assert "hold" not in modes[modes.index("return"):]  # the fence did not stop the fallback
    safety = summary["metrics"]["safety"]
    assert safety["ended_safe"] is True
    assert safety["fence_breached"] is False


# -- a detector, estimator or step that raises -------------------------------------------------

@pytest.mark.parametrize("where", ["detector", "estimator", "step"])
def test_a_raising_detector_estimator_or_step_fails_into_the_fallback(where, monkeypatch,
                                                                       tmp_path, caplog):
    from autopilot.behaviors.follow import FollowTarget
    from autopilot.perception.ball_pipeline import BallPipeline

    def broken_after(original, time_of):
        def wrapper(self, *args, **kwargs):
            if time_of(self, args) > 12.0:
                raise RuntimeError(f"broken {where}")
            return original(self, *args, **kwargs)
        return wrapper

    if where == "detector":
        monkeypatch.setattr(BallPipeline, "detect", broken_after(
            BallPipeline.detect, lambda self, args: args[2]))
    elif where == "estimator":
        monkeypatch.setattr(BallPipeline, "estimate", broken_after(
            BallPipeline.estimate, lambda self, args: args[0]))
    else:
        monkeypatch.setattr(FollowTarget, "update", broken_after(
            FollowTarget.update, lambda self, args: args[0].now_s))
    with caplog.at_level(logging.ERROR):
        summary, orphans = _fly([], tmp_path)
    assert summary["status"] == "failed"
    assert f"RuntimeError: broken {where}" in summary["reason"]
    assert summary["reason"].startswith("follow_ball:")
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    texts = [e["text"] for e in log[ch.MISSION_EVENTS]]
    failed = next(i for i, t in enumerate(texts) if t.startswith("step follow_ball failed"))
    assert "fallback safe_stop started" in texts[failed:]
    assert "request land" in texts[failed:]
    ended_down(log)
    assert "Traceback" not in summary["reason"]
    assert any("broken" in (r.exc_text or "") or r.exc_info for r in caplog.records)


# -- a loop stall the vehicle waited for ----------------------------------------------------

def test_a_stall_the_vehicle_waited_for_does_not_fail_the_step():
    """Real time, flying: a loop stall fails the step when the vehicle's clock ran on through
    it (setpoints lapsed there), not when the vehicle's world waited (a real-time simulator
    slowed with a starved CPU: its clock stood still with the loop)."""
    from types import SimpleNamespace

    from autopilot.mission import load_mission
    from autopilot.runtime.failsafes import Failsafes

    def runtime(clock_now, last_tick):
        failed, events = [], []
        config = load_mission("follow_ball").config  # (setpoints expire after 0.3 s)
        flight = SimpleNamespace(clock=SimpleNamespace(lockstep=False, now=lambda: clock_now),
                                 config=config, in_air=True)
        recorder = SimpleNamespace(event=lambda t, kind, text: events.append(text))
        failsafes = Failsafes(flight, recorder, telemetry=None, fence=None)
        failsafes.last_tick_s = last_tick  # (the control loop's newest tick)
        failsafes.fail_step = failed.append
        failsafes.on_loop_stall(0.8)
        return failed, events

    failed, events = runtime(10.05, 10.0)  # the vehicle's clock: 0.05 s through a 0.8 s stall
    assert failed == []
    assert "its world waited" in events[0]
    failed, _ = runtime(10.85, 10.0)  # a vehicle whose clock ran on (any real one)
    assert failed == ["event loop stalled for 0.80 s"]
