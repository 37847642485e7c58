"""The staleness guard in closed loop (lockstep): a short silence of the vehicle holds it and
the step resumes when telemetry returns; a silence past ``runtime.telemetry_grace_s`` ends
the step in the mission's fallback."""

from __future__ import annotations

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log

from .simtools import fly_short

#: (after the vehicle arms) following by 10 s; each fault over before the next begins
FAULTS = ("scenario.faults=["
          "{kind: telemetry_dropout, start_s: 10, duration_s: 0.8}, "
          "{kind: camera_freeze, camera: front, start_s: 13, duration_s: 2}, "
          "{kind: ekf_glitch, start_s: 17, duration_s: 4, magnitude_m: 1.5, direction_deg: 90}]")


def _events(log) -> list[tuple[float, str]]:
    return [(e["time_s"], e["text"]) for e in log[ch.MISSION_EVENTS]]


def test_follow_ball_rides_out_a_dropout_a_freeze_and_a_glitch(tmp_path):
    summary, orphans = fly_short([FAULTS], tmp_path)
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    events = _events(log)
    assert summary["status"] == "completed", (summary["reason"], events)
    silent = [(t, text) for t, text in events if text.startswith("telemetry silent")]
    back = [(t, text) for t, text in events if text.startswith("telemetry back")]
    assert len(silent) == 1
    assert len(back) == 1
    silent_at, back_at = silent[0][0], back[0][0]
    assert "holding" in silent[0][1]
    # the 0.8 s dropout: noticed after telemetry_silence_s, resumed when it ended
    assert 0.0 < back_at - silent_at < 0.8
    # no setpoint while silent; the step asked for OFFBOARD again (it had been told to hold)
    assert not [sp for sp in log[ch.SETPOINTS] if silent_at < sp["time_s"] < back_at]
    after = [text for t, text in events if t >= silent_at]
    assert after.index("request hold") < after.index("request start_offboard")
    assert not [text for _, text in events if text.startswith("telemetry lost")]
    # back in OFFBOARD after the dropout, following through the freeze and the glitch
    resumed = [s["mode"] for s in log[ch.VEHICLE_STATE] if back_at + 1.0 < s["time_s"]]
    assert resumed[0] == "offboard"
    assert resumed[:resumed.index("land")].count("offboard") > 20 * 10  # ≥ 10 s at 20+ Hz


def test_a_silence_past_the_grace_ends_in_the_fallback(tmp_path):
    """A 3 s dropout (grace 2 s): the step ends in the fallback, which lands the vehicle
    safely, even though telemetry comes back later."""
    summary, orphans = fly_short(
        ["scenario.faults=[{kind: telemetry_dropout, start_s: 10, duration_s: 3}]"], tmp_path)
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    events = _events(log)
    assert summary["status"] == "aborted"  # the safe stop flew to its end
    assert "telemetry lost" in summary["reason"]
    assert not [text for _, text in events if text.startswith("telemetry back")]
    texts = [text for _, text in events]
    assert texts.index("request hold") < texts.index("request land")
    assert summary["metrics"]["safety"]["ended_safe"] is True
    last = log[ch.VEHICLE_STATE][-1]
    assert last["armed"] is False
    assert log[ch.GROUND_TRUTH][-1]["vehicle_position_ned_m"][2] > -0.3
