"""The flight report: each plot's data extraction, and a report from a log that was cut."""

import json
import math

import numpy as np
import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.report import data
from autopilot.report.html import write_report
from tests.factories import front_camera


def _log(n: int = 50) -> dict:
    """A tiny synthetic flight: the vehicle 2.5 m south of a ball at rest, flying north 1 m/s."""
    ball = {"name": "ball", "kind": "ball", "camera": "front", "truth_body": "ball",
            "size_m": 0.2}
    recs = {ch.MISSION_PLAN: [{"steps": [
                {"name": "takeoff", "index": 0, "params": {}, "pipelines": []},
                {"name": "follow_ball", "index": 1, "params": {"duration_s": 10},
                 "pipelines": [ball], "standoff_m": 2.0}]}],
            ch.CAMERA_INFO: [ch.clean(ch.camera_info_record(front_camera()))],
            ch.MISSION_EVENTS: [
                {"time_s": 0.0, "kind": "step_started", "step_index": 0, "step": "takeoff",
                 "text": "step takeoff started"},
                {"time_s": 1.0, "kind": "step_succeeded", "step_index": 0, "step": "takeoff",
                 "text": "step takeoff succeeded"},
                {"time_s": 1.0, "kind": "step_started", "step_index": 1, "step": "follow_ball",
                 "text": "step follow_ball started"}],
            ch.VEHICLE_STATE: [], ch.GROUND_TRUTH: [], ch.TARGET_ESTIMATES: [],
            ch.detection_topic("ball"): [], ch.SETPOINTS: []}
    for k in range(n):
        t = 0.1 * k
        recs[ch.VEHICLE_STATE].append({"time_s": t, "position_ned_m": [t - 2.5, 0, -2],
                                       "velocity_ned_m_s": [1.0, 0, 0], "yaw_rad": math.pi / 2})
        recs[ch.GROUND_TRUTH].append({"time_s": t, "vehicle_position_ned_m": [t - 2.5, 0, -2],
                                      "vehicle_attitude_q": [1.0, 0, 0, 0],  # facing north
                                      "bodies": {"ball": {"position_ned_m": [0, 0, -2]}}})
        recs[ch.TARGET_ESTIMATES].append({"time_s": t, "pipeline": "ball",
                                          "position_ned_m": [0.1, 0, -2],
                                          "position_std_m": [0.05, 0.05, 0.02]})
        recs[ch.detection_topic("ball")].append({"time_s": t, "camera": "front",
                                         "detected": k % 5 != 0})
        recs[ch.SETPOINTS].append({"time_s": t, "frame": "body_frd", "velocity_m_s": [1, 0, 0],
                                   "latency_ms": 30.0 + k % 3})
    return recs


def test_phases_come_from_the_mission_events():
    assert data.phases(_log()) == [(0.0, 1.0, "takeoff"), (1.0, pytest.approx(4.9),
                                                            "follow_ball")]


def _target(log):
    (target,) = data.targets(log)
    return target


def test_the_followed_target_comes_from_the_step_records():
    target = _target(_log())
    assert (target.pipeline, target.camera, target.truth_body, target.size_m,
            target.standoff_m) == ("ball", "front", "ball", 0.2, 2.0)
    # a log from before per-step plan records (the project's first weeks) is no longer read
    # as following a ball: it has no followed target, and the report draws none
    old = {**_log(), ch.MISSION_PLAN: [{"standoff_m": 2.0, "camera": "front",
                                        "ball_diameter_m": 0.2,
                                        "steps": [{"takeoff": {}}, {"follow_ball": {}}]}]}
    assert data.targets(old) == []


def test_standoff_error_is_true_distance_minus_standoff():
    s = data.standoff_error(_log(), _target(_log()))
    assert s["error_m"][0] == pytest.approx(0.5)  # 2.5 m away, standoff 2 m
    assert s["error_m"][-1] == pytest.approx(abs(4.9 - 2.5) - 2.0)
    assert s["estimated_error_m"][0] == pytest.approx(0.6)  # the estimate is 0.1 m further


def test_detection_timeline_and_estimate_against_truth():
    target = _target(_log())
    d = data.detection_timeline(_log(), target)
    assert d["detected"].sum() == 40
    # flying north past the ball: in view until it is (nearly) alongside, then behind
    assert d["has_truth"]
    assert d["in_view"][:20].all()
    assert not d["in_view"][26:].any()
    no_truth = data.detection_timeline({**_log(), ch.GROUND_TRUTH: []}, target)
    assert not no_truth["has_truth"]
    assert not no_truth["in_view"].any()
    e = data.estimate_vs_truth(_log(), target)
    assert np.allclose(e["estimate"][:, 0] - e["truth"][:, 0], 0.1)
    assert np.allclose(e["std"][:, 2], 0.02)


def test_body_frame_commands_are_turned_into_ned_by_the_vehicle_yaw():
    v = data.velocity_tracking(_log())
    assert np.allclose(v["command"][:, :2], [[0.0, 1.0]] * 50, atol=1e-9)  # facing east
    assert np.allclose(v["actual"][:, 0], 1.0)


def test_latencies():
    assert sorted(set(data.latencies_ms(_log()))) == [30.0, 31.0, 32.0]


def test_a_cut_log_still_gives_a_report_that_says_so(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    log = FlightLog(run / "flight.mcap")
    recs = _log(3000)
    for topic, rows in recs.items():
        for r in rows:
            log.write(topic, r.get("time_s", 0.0), r)
    log.close()
    whole = write_report(run).read_text()
    assert "cut short" not in whole
    assert whole.count("<img") == 6  # every plot drawn
    data_bytes = (run / "flight.mcap").read_bytes()
    (run / "flight.mcap").write_bytes(data_bytes[: len(data_bytes) // 2])
    (run / "summary.json").write_text(json.dumps({"status": "completed", "metrics": {
        "follow": {"detection_rate": 0.8}}}))
    cut = write_report(run).read_text()
    assert "cut short" in cut
    assert cut.count("<img") >= 3  # what the first half of the log holds
    assert "follow.detection_rate" in cut


def test_a_faults_run_lists_its_faults_on_the_log_clock():
    from autopilot.report.html import _faults_table

    records = {ch.MISSION_PLAN: [{"scenario": {"faults": [
        {"kind": "camera_dropout", "start_s": 2.0, "duration_s": 3.0, "camera": "front"},
        {"kind": "battery_sag", "start_s": 4.0, "duration_s": None,
         "remaining_fraction": 0.12}]}}],
        ch.VEHICLE_STATE: [{"time_s": 1.0, "armed": False}, {"time_s": 1.5, "armed": True}]}
    table = _faults_table(records)
    assert "<h2>Injected faults</h2>" in table
    assert "camera_dropout</td><td>3.5 s – 6.5 s</td><td>camera=front" in table
    assert "battery_sag</td><td>5.5 s – end</td><td>remaining_fraction=0.12" in table
    assert _faults_table({ch.MISSION_PLAN: [{"scenario": {"faults": []}}]}) == ""
