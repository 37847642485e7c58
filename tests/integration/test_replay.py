"""``autopilot replay``: a logged flight through detection and estimation again."""

import json

import pytest

from autopilot.cli import main
from autopilot.config import ConfigError
from autopilot.flightlog.log import FlightLog, read_log
from autopilot.replay import ReplayError, replay


def test_replay_without_overrides_reproduces_the_flight(logged_flight):
    run_dir, summary = logged_flight
    result = replay(run_dir)
    assert result["frames"]["replayed"] == result["frames"]["in_flight"] == \
        summary["stats"]["frames"]
    flown, again = summary["metrics"]["follow"], result["metrics"]["follow"]
    # the realistic camera's frames are logged as its codec's own JPEG bytes (not re-encoded),
    # so the replay's detector sees exactly the flight's pixels: the same figures
    assert again["detection_rate"] == flown["detection_rate"]
    assert again["frames_in_view"] == flown["frames_in_view"]
    assert again["false_detection_rate"] == flown["false_detection_rate"]
    est_flown, est_again = summary["metrics"]["estimation"], result["metrics"]["estimation"]
    n = est_flown["at_update"]["estimates"]
    assert n > 100
    assert est_again["at_update"]["estimates"] == n
    assert est_again["ticks"] == est_flown["ticks"]  # the same control ticks, replayed
    for key in ("rms_position_error_m", "rms_velocity_error_m_s"):
        assert est_again[key] == pytest.approx(est_flown[key], rel=1e-6), key
    # and the flight's own figures, as the replay quotes them, are summary.json's
    assert result["flight_metrics"]["estimation"]["rms_position_error_m"] == \
        pytest.approx(est_flown["rms_position_error_m"])


def test_overrides_change_what_the_pipeline_does(logged_flight):
    run_dir, summary = logged_flight
    blind = replay(run_dir, ["perception.ball.color=blue"])  # the ball is orange
    assert blind["metrics"]["follow"]["detection_rate"] == 0.0
    # never an estimate to fly on: every control tick lost, no error to average
    assert blind["metrics"]["estimation"]["lost_share"] == 1.0
    assert "rms_position_error_m" not in blind["metrics"]["estimation"]
    sluggish = replay(run_dir, ["estimation.target.accel_noise_m_s2=0.05"])
    flown = summary["metrics"]["estimation"]["rms_velocity_error_m_s"]
    # a filter that believes the ball hardly accelerates lags it on its curve
    assert sluggish["metrics"]["estimation"]["rms_velocity_error_m_s"] > 1.5 * flown
    assert sluggish["metrics"]["follow"]["detection_rate"] >= 0.95


def test_a_bad_override_names_the_key(logged_flight):
    run_dir, _ = logged_flight
    with pytest.raises(ConfigError) as err:
        replay(run_dir, ["estimation.target.gate_chi2=-1"])
    assert "estimation.target.gate_chi2" in str(err.value)
    with pytest.raises(ConfigError, match="no_such_key"):
        replay(run_dir, ["perception.ball.no_such_key=1"])


def test_replay_json_is_shaped_like_summary(logged_flight, capsys):
    run_dir, summary = logged_flight
    assert main(["replay", str(run_dir), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "replayed"
    assert out["mission"] == summary["mission"]
    assert set(out["metrics"]) == {"follow", "estimation"}
    assert out["metrics"]["follow"]["detection_rate"] == pytest.approx(
        summary["metrics"]["follow"]["detection_rate"], abs=0.01)  # (the codec: see above)


def test_replay_of_a_log_cut_short(logged_flight, tmp_path):
    run_dir, _ = logged_flight
    data = (run_dir / "flight.mcap").read_bytes()
    (tmp_path / "flight.mcap").write_bytes(data[: len(data) * 2 // 3])
    result = replay(tmp_path)
    assert not result["log_complete"]
    assert 0 < result["frames"]["replayed"] <= result["frames"]["in_flight"]


def test_replay_needs_logged_frames(tmp_path, logged_flight, capsys):
    with pytest.raises(ReplayError, match="no such file"):
        replay(tmp_path)
    # the same flight's records without its frames (as with log.frames.*_rate_hz=0)
    run_dir, _ = logged_flight
    log = FlightLog(tmp_path / "flight.mcap")
    for topic, rows in read_log(run_dir / "flight.mcap").items():
        for row in rows:
            log.write(topic, row.get("time_s") or 0.0, row)
    log.close()
    assert main(["replay", str(tmp_path)]) == 2
    assert "no logged camera frames" in capsys.readouterr().err
