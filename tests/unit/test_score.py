"""Scoring a MAVLink flight against the simulator's ground truth: logs joined on one clock."""

import json

import pytest

from autopilot import score as scoring
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog, read_log


def _write(path, records):
    log = FlightLog(path)
    for topic, time_s, record in records:
        log.write(topic, time_s, record)
    log.close()


def _truth(t):
    return {"time_s": t, "vehicle_position_ned_m": [0, 0, -2], "vehicle_velocity_ned_m_s":
            [0, 0, 0], "vehicle_attitude_q": [1, 0, 0, 0], "wind_ned_m_s": [0, 0, 0],
            "bodies": {"ball": {"position_ned_m": [2, 0, -2], "velocity_ned_m_s": [0, 0, 0]}}}


def test_truth_is_shifted_onto_the_run_clock_by_the_measured_offset(tmp_path, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()
    _write(run / "flight.mcap", [
        (ch.MISSION_EVENTS, 100.0, {"time_s": 100.0, "step": "x", "text": "step x started"}),
        (ch.TIME_SYNC, 110.0, {"time_s": 110.0, "vehicle_to_local_s": 95.5,
                               "round_trip_s": 0.001})])
    (run / "summary.json").write_text(json.dumps({"status": "completed", "metrics": {}}))
    _write(tmp_path / "truth.mcap", [(ch.GROUND_TRUTH, t, _truth(t)) for t in (4.5, 5.0)])
    seen = {}

    def fake_metrics(records):
        seen.update(records)
        return {"follow": {"detection_rate": 1.0}}

    monkeypatch.setattr(scoring, "mission_metrics", fake_metrics)
    assert scoring.score(run, tmp_path / "truth.mcap") == {"follow": {"detection_rate": 1.0}}
    assert [r["time_s"] for r in seen[ch.GROUND_TRUTH]] == [100.0, 100.5]
    summary = json.loads((run / "summary.json").read_text())
    assert summary["metrics"]["follow"] == {"detection_rate": 1.0}
    assert summary["scored_against"].endswith("truth.mcap")


def test_a_lagging_vehicle_clock_is_followed_through_the_run(tmp_path, monkeypatch):
    # a starved simulator: its clock ran at half speed, so the mapping (local − vehicle) grew
    # from 100 s to 105 s over the ten seconds it was logged; truth lands where it happened
    run = tmp_path / "run"
    run.mkdir()
    _write(run / "flight.mcap", [
        (ch.TIME_SYNC, t, {"time_s": t, "vehicle_to_local_s": 100.0 + 0.5 * (t - 110.0),
                           "round_trip_s": 0.001}) for t in (110.0, 115.0, 120.0)])
    _write(tmp_path / "truth.mcap", [(ch.GROUND_TRUTH, t, _truth(t))
                                     for t in (5.0, 10.0, 12.5, 15.0, 20.0)])
    seen = {}
    monkeypatch.setattr(scoring, "mission_metrics", lambda records: seen.update(records) or {})
    scoring.score(run, tmp_path / "truth.mcap")
    # vehicle 10 s ↔ local 110 s, 12.5 ↔ 115, 15 ↔ 120; held beyond the ends
    assert [r["time_s"] for r in seen[ch.GROUND_TRUTH]] == pytest.approx(
        [105.0, 110.0, 115.0, 120.0, 125.0])


def test_a_run_without_a_time_mapping_cannot_be_scored(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    _write(run / "flight.mcap", [(ch.MISSION_EVENTS, 1.0, {"time_s": 1.0, "step": "x",
                                                          "text": "hello"})])
    _write(tmp_path / "truth.mcap", [(ch.GROUND_TRUTH, 1.0, _truth(1.0))])
    with pytest.raises(scoring.ScoreError, match="no time mapping"):
        scoring.score(run, tmp_path / "truth.mcap")
    with pytest.raises(scoring.ScoreError, match="no such file"):
        scoring.score(run, tmp_path / "missing.mcap")


def test_a_truncated_log_reads_up_to_where_it_was_cut(tmp_path):
    path = tmp_path / "cut.mcap"
    _write(path, [(ch.GROUND_TRUTH, t * 0.1, _truth(t * 0.1)) for t in range(2000)])
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    got = read_log(path).get(ch.GROUND_TRUTH, [])
    assert 0 < len(got) < 2000
    assert [r["time_s"] for r in got] == pytest.approx([t * 0.1 for t in range(len(got))])


def test_detections_are_scored_in_the_cameras_the_simulator_really_had(tmp_path, monkeypatch):
    """The truth recording's cameras (calibration and mount errors and all) replace the
    nominal ones the run logged: a detection is judged where the target truly appeared."""
    import dataclasses

    import numpy as np

    from drivers.ardrone.cameras import ardrone_cameras

    nominal = ardrone_cameras()["front"]
    true = dataclasses.replace(nominal, position_body_m=np.array([0.19, 0.01, 0.0]))
    run = tmp_path / "run"
    run.mkdir()
    _write(run / "flight.mcap", [
        (ch.CAMERA_INFO, 100.0, ch.camera_info_record(nominal)),
        (ch.TIME_SYNC, 110.0, {"time_s": 110.0, "vehicle_to_local_s": 95.5,
                               "round_trip_s": 0.001})])
    _write(tmp_path / "truth.mcap", [(ch.CAMERA_TRUTH, 0.0, ch.camera_info_record(true)),
                                     (ch.GROUND_TRUTH, 4.5, _truth(4.5))])
    seen = {}
    monkeypatch.setattr(scoring, "mission_metrics", lambda records: seen.update(records) or {})
    scoring.score(run, tmp_path / "truth.mcap")
    assert len(seen[ch.CAMERA_TRUTH]) == 1
    assert seen[ch.CAMERA_TRUTH][0]["position_body_m"] == pytest.approx([0.19, 0.01, 0.0])
    assert seen[ch.CAMERA_INFO][0]["position_body_m"] == pytest.approx([0.17, 0.0, 0.0])
