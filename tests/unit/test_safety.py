"""How a simulated flight ended (autopilot/flightlog/safety.py): judged on the simulator's truth."""

from __future__ import annotations

import math

from autopilot.flightlog import records as ch
from autopilot.flightlog.safety import outcome, safety_metrics


def _truth(t: float, height_m: float, armed: bool | None, mode: str | None,
           tilt_deg: float = 0.0, vz_m_s: float = 0.0, north_m: float = 0.0) -> dict:
    half = math.radians(tilt_deg) / 2.0
    return {"time_s": t, "vehicle_position_ned_m": [north_m, 0.0, -height_m],
            "vehicle_velocity_ned_m_s": [0.0, 0.0, vz_m_s],
            "vehicle_attitude_q": [math.cos(half), math.sin(half), 0.0, 0.0],
            "armed": armed, "mode": mode}


def _state(armed: bool, mode: str, landed: str = "in_air") -> dict:
    return {"time_s": 1.0, "armed": armed, "mode": mode, "landed_state": landed}


def test_the_end_state_is_the_flight_stacks_not_the_last_telemetry() -> None:
    # telemetry stopped while the vehicle was landing; in truth it is still flying offboard
    records = {ch.GROUND_TRUTH: [_truth(0, 0.0, False, "hold"), _truth(5, 10.0, True, "offboard")],
               ch.VEHICLE_STATE: [_state(True, "land")]}
    m = safety_metrics(records)
    assert m["ended_safe"] is False
    assert outcome("aborted", m) == ("unsafe", "left flying")
    # and the other way round: the last telemetry says offboard, the vehicle is in RTL
    records[ch.GROUND_TRUTH][-1] = _truth(5, 10.0, True, "return")
    records[ch.VEHICLE_STATE] = [_state(True, "offboard")]
    assert safety_metrics(records)["ended_safe"] is True


def test_armed_on_a_raised_deck_is_on_the_ground_by_the_land_detector() -> None:
    # touched down on the rover's deck (0.6 m up), still armed in offboard for a moment
    landed = _truth(9, 0.6, True, "offboard")
    records = {ch.GROUND_TRUTH: [_truth(0, 0.0, False, "hold"), landed]}
    assert safety_metrics(records)["ended_safe"] is False  # (no land detector: flying)
    records[ch.GROUND_TRUTH][-1] = {**landed, "landed_state": "on_ground"}
    assert safety_metrics(records)["ended_safe"] is True
    records[ch.GROUND_TRUTH][-1] = {**landed, "landed_state": "in_air"}
    assert safety_metrics(records)["ended_safe"] is False


def test_older_logs_without_the_truths_mode_use_the_telemetry() -> None:
    records = {ch.GROUND_TRUTH: [_truth(0, 0.0, None, None), _truth(5, 10.0, None, None)],
               ch.VEHICLE_STATE: [_state(True, "offboard")]}
    assert safety_metrics(records)["ended_safe"] is False
    records[ch.VEHICLE_STATE] = [_state(False, "land", "on_ground")]
    assert safety_metrics(records)["ended_safe"] is True


def test_crash_flyaway_and_a_clean_end() -> None:
    hard = {ch.GROUND_TRUTH: [_truth(0, 5.0, True, "offboard"),
                              _truth(1, 0.2, True, "offboard", vz_m_s=6.0),
                              _truth(2, 0.0, False, "land")]}
    m = safety_metrics(hard)
    assert m["crashed"] is True
    assert outcome("completed", m)[0] == "unsafe"
    tipped = {ch.GROUND_TRUTH: [_truth(0, 5.0, True, "offboard"),
                                _truth(1, 5.0, True, "offboard", tilt_deg=80.0)]}
    assert safety_metrics(tipped)["crashed"] is True
    away = {ch.GROUND_TRUTH: [_truth(0, 5.0, True, "offboard"),
                              _truth(1, 5.0, True, "hold", north_m=200.0)]}
    assert safety_metrics(away)["flyaway"] is True
    clean = {ch.GROUND_TRUTH: [_truth(0, 0.0, False, "hold"), _truth(5, 5.0, True, "offboard"),
                               _truth(9, 0.0, False, "land", vz_m_s=0.5)]}
    m = safety_metrics(clean)
    assert not m["crashed"]
    assert not m["flyaway"]
    assert not m["fence_breached"]
    assert outcome("completed", m) == ("completed", "")
    assert outcome("error", m) == ("unsafe", "error (traceback)")
