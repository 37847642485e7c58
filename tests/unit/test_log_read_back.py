"""The end-of-run metrics read the flight log back from its file as they use it: the same
figures as from the records in memory, in memory that does not grow with the records."""

import math
import tracemalloc

import numpy as np
import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import (
    FlightLog,
    StoredChannel,
    StoredLog,
    encode,
    read_log,
    read_log_checked,
)
from autopilot.run import flight_metrics
from tests.factories import front_camera

BALL = {"name": "ball", "kind": "ball", "camera": "front", "truth_body": "ball", "size_m": 0.2}
RATE_HZ = 50.0


def _flight(path, duration_s: float) -> tuple[FlightLog, int]:
    """A follow_ball flight's log, closed (ground truth, telemetry, setpoints and control
    ticks at 50 Hz, detections at 30 Hz), and the bytes of JSON written."""
    log = FlightLog(path)
    written = 0

    def write(topic, record):
        nonlocal written
        written += len(encode(record))
        log.write(topic, record["time_s"], record)

    write(ch.MISSION_PLAN, {"time_s": 0.0, "mission": "synthetic", "source": "test", "steps": [
        {"name": "follow_ball", "index": 0, "params": {}, "pipelines": [BALL],
         "standoff_m": 2.0}]})
    write(ch.CAMERA_INFO, {"time_s": 0.0, **ch.clean(ch.camera_info_record(front_camera()))})
    write(ch.MISSION_EVENTS, {"time_s": 0.0, "kind": "step_started", "step_index": 0,
                              "step": "follow_ball", "text": "step 1 follow_ball started"})
    steps = int(duration_s * RATE_HZ)
    for k in range(steps):
        t = k / RATE_HZ
        ball = [2.0 + 0.3 * math.sin(0.5 * t), 0.2 * math.cos(0.5 * t), -2.0]
        vehicle = [0.01 * math.sin(t), 0.0, -2.0]
        write(ch.GROUND_TRUTH, {
            "time_s": t, "vehicle_position_ned_m": vehicle,
            "vehicle_velocity_ned_m_s": [0.01 * math.cos(t), 0.0, 0.0],
            "vehicle_attitude_q": [1.0, 0.0, 0.0, 0.0], "wind_ned_m_s": [0.0, 0.0, 0.0],
            "bodies": {"ball": {"position_ned_m": ball,
                                "velocity_ned_m_s": [0.15 * math.cos(0.5 * t),
                                                     -0.1 * math.sin(0.5 * t), 0.0]}},
            "armed": True, "mode": "offboard"})
        write(ch.VEHICLE_STATE, {
            "time_s": t, "position_ned_m": vehicle, "velocity_ned_m_s": [0.0, 0.0, 0.0],
            "attitude_q": [1.0, 0.0, 0.0, 0.0], "yaw_rad": 0.0, "armed": True,
            "mode": "offboard", "landed_state": "in_air", "battery_remaining": 0.9})
        write(ch.SETPOINTS, {"time_s": t, "source_frame_time_s": t - 0.03, "latency_ms": 30.0,
                             "frame": "local_ned", "velocity_m_s": [0.1, 0.0, 0.0],
                             "yaw_rad": 0.0, "step": "follow_ball", "phase": "tracking"})
        write(ch.CONTROL_TARGET, {
            "time_s": t, "pipeline": "ball", "step": "follow_ball", "step_index": 0,
            "present": True, "position_ned_m": [ball[0] + 0.02, ball[1], ball[2]],
            "velocity_ned_m_s": [0.0, 0.0, 0.0], "position_std_m": [0.05, 0.05, 0.05],
            "age_s": 0.02, "stale": False, "confirmed": True})
        if k % 5 in (0, 2, 4):  # 30 Hz
            write(ch.detection_topic("ball"), {"time_s": t, "camera": "front", "detected": True,
                                               "u_px": 319.5, "v_px": 239.5,
                                               "radius_px": 16.0, "processing_ms": 4.0})
    write(ch.MISSION_EVENTS, {"time_s": steps / RATE_HZ, "kind": "step_succeeded",
                              "step_index": 0, "step": "follow_ball",
                              "text": "step 1 follow_ball succeeded"})
    log.close()
    return log, written


def _metrics_peak_b(log: FlightLog) -> tuple[dict, int]:
    """The end-of-run metrics as :func:`~autopilot.run.fly` computes them, and the peak of
    the Python memory that took."""
    tracemalloc.start()
    try:
        metrics = flight_metrics(log.read_back(), None)
        return metrics, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_long_flights_metrics_do_not_hold_its_records(tmp_path):
    short_log, short_b = _flight(tmp_path / "short.mcap", 20.0)
    long_log, long_b = _flight(tmp_path / "long.mcap", 100.0)
    assert isinstance(long_log.read_back(), StoredLog)
    _, short_peak = _metrics_peak_b(short_log)
    long, long_peak = _metrics_peak_b(long_log)
    assert long["mission"]["follow"]["follow_time_s"] == pytest.approx(100.0, abs=0.05)
    assert long["latency_ms"]["samples"] == 5000
    # 80 s more of flight: 26,400 more records. Held as dicts they take several times their
    # JSON text (the read-back of the whole log did: 6x here); the metrics keep columns of
    # the numbers they score: a few floats per record.
    grown = long_peak - short_peak
    assert grown < 0.5 * (long_b - short_b), (grown, long_b - short_b)


def test_the_file_gives_the_figures_the_records_in_memory_give(tmp_path):
    log, _ = _flight(tmp_path / "flight.mcap", 10.0)
    from_file, _ = _metrics_peak_b(log)
    from autopilot.flightlog.metrics import latency_metrics
    from autopilot.flightlog.safety import safety_metrics
    from autopilot.steps.metrics import mission_metrics

    records = read_log(tmp_path / "flight.mcap")
    assert from_file["mission"] == mission_metrics(records)
    assert from_file["latency_ms"] == latency_metrics(records)
    assert from_file["safety"] == safety_metrics(records)
    assert from_file["mission"]["follow"]["frames_processed"] == 300


def test_a_stored_log_reads_long_channels_from_the_file_when_used(tmp_path):
    _flight(tmp_path / "flight.mcap", 10.0)
    records = read_log(tmp_path / "flight.mcap")
    stored = StoredLog(tmp_path / "flight.mcap")
    assert set(stored) == set(records)
    truth = stored[ch.GROUND_TRUTH]
    assert isinstance(truth, StoredChannel)  # 500 records: read when used, not kept
    assert isinstance(stored[ch.MISSION_EVENTS], list)  # 2: kept
    for topic, items in records.items():
        assert list(stored[topic]) == items
        assert list(stored[topic]) == items  # (again: read from the file again)
        assert len(stored[topic]) == len(items)
    assert truth[0] == records[ch.GROUND_TRUTH][0]
    assert truth[-1] == records[ch.GROUND_TRUTH][-1]
    assert truth[-1:] == records[ch.GROUND_TRUTH][-1:]
    assert truth[7] == records[ch.GROUND_TRUTH][7]
    assert truth[10:20:3] == records[ch.GROUND_TRUTH][10:20:3]
    assert truth[5:2] == []
    with pytest.raises(IndexError):
        truth[len(records[ch.GROUND_TRUTH])]


def test_a_log_cut_short_reads_back_what_it_holds(tmp_path):
    _flight(tmp_path / "flight.mcap", 4.0)
    data = (tmp_path / "flight.mcap").read_bytes()
    whole = read_log(tmp_path / "flight.mcap")
    (tmp_path / "cut.mcap").write_bytes(data[:len(data) // 2])
    cut = read_log(tmp_path / "cut.mcap")
    assert 0 < len(cut[ch.GROUND_TRUTH]) < len(whole[ch.GROUND_TRUTH])
    assert cut[ch.GROUND_TRUTH] == whole[ch.GROUND_TRUTH][:len(cut[ch.GROUND_TRUTH])]
    stored = StoredLog(tmp_path / "cut.mcap")
    assert list(stored[ch.GROUND_TRUTH]) == cut[ch.GROUND_TRUTH]


def test_the_truth_columns_keep_nulls_as_nan_and_bodies_where_they_were():
    from autopilot.flightlog.truth import TruthTable

    samples = [
        {"time_s": 0.0, "vehicle_position_ned_m": [0.0, 1.0, -2.0],
         "vehicle_velocity_ned_m_s": [1.0, None, 0.0], "vehicle_attitude_q": [1, 0, 0, 0],
         "bodies": {}},
        {"time_s": 0.1, "vehicle_position_ned_m": None, "bodies": {
            "ball": {"position_ned_m": [5.0, None, -1.0], "velocity_ned_m_s": [0, 0, 0]}}},
        {"time_s": 0.2, "vehicle_position_ned_m": [0.2, 1.0, -2.0],
         "vehicle_velocity_ned_m_s": [2.0, 0.0, 0.0], "vehicle_attitude_q": [1, 0, 0, 0],
         "bodies": {"ball": {"position_ned_m": [6.0, 0.0, -1.0]}}, "armed": True},
    ]
    table = TruthTable(samples)
    nan = math.nan

    def same(a, b):
        return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                              equal_nan=True)

    assert table.t.tolist() == [0.0, 0.1, 0.2]
    assert table.has_vehicle.tolist() == [True, False, True]
    assert same(table.v, [[1.0, nan, 0.0], [nan] * 3, [2.0, 0.0, 0.0]])  # (nothing shifted)
    assert same(table.p[1], [nan] * 3)
    assert same(table.q[1], [nan] * 4)
    assert table.last["armed"] is True
    ball = table.body("ball")
    assert ball.t.tolist() == [0.1, 0.2]
    assert same(ball.p, [[5.0, nan, -1.0], [6.0, 0.0, -1.0]])
    assert same(ball.v[1], [nan] * 3)  # not logged in that sample
    assert same(ball.vehicle_p, [[nan] * 3, [0.2, 1.0, -2.0]])
    assert len(table.body("rover")) == 0


def test_a_damaged_log_reads_back_what_it_can_and_never_raises(tmp_path):
    _flight(tmp_path / "flight.mcap", 2.0)
    data = (tmp_path / "flight.mcap").read_bytes()
    whole = read_log(tmp_path / "flight.mcap")
    damaged = {
        "empty": b"",
        "inside the magic": data[:4],
        "not an MCAP file": b"hello, world\n" * 10,
        # the first record's length field made huge (its highest byte)
        "a huge length": data[:16] + b"\x7f" + data[17:],
        "zeroes over a chunk": data[:len(data) // 3] + bytes(4096) + data[len(data) // 3 + 4096:],
    }
    for name, content in damaged.items():
        path = tmp_path / f"{name}.mcap"
        path.write_bytes(content)
        records, complete = read_log_checked(path)
        assert not complete or name == "zeroes over a chunk", name
        for topic, items in records.items():  # what it has is what the flight wrote
            assert items == whole[topic][:len(items)], (name, topic)
        stored = StoredLog(path)
        assert {t: list(items) for t, items in stored.items()} == dict(records), name
        flight_metrics(stored, None)  # scores what there is, without raising
