"""Camera frames in the flight log: which are logged, how they are stored and read back."""

import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog, read_images, read_log
from autopilot.framelog import FrameSampler, encode_jpeg
from tests.factories import front_camera, vehicle_state

pytestmark = pytest.mark.serial  # the log writer's timing


@pytest.mark.parametrize(("rate_hz", "expected"), [(30.0, 30), (60.0, 30), (10.0, 10),
                                               (7.0, 7), (0.0, 0)])
def test_the_sampler_takes_frames_evenly_at_its_rate(rate_hz, expected):
    sampler = FrameSampler(rate_hz, 30.0)
    # a 30 Hz camera whose frames land on a 2 ms physics grid (33 or 34 ms apart)
    times = [round(k / 30.0, 3) for k in range(30)]
    taken = [t for t in times if sampler.take(t)]
    assert len(taken) == expected
    if len(taken) > 2:
        gaps = np.diff(taken)
        assert gaps.max() - gaps.min() <= 1 / 30.0 + 0.002  # one frame, on the 2 ms grid


def test_frames_are_foxglove_compressed_images_read_back_lazily(tmp_path):
    image = np.zeros((48, 64, 3), np.uint8)
    image[10:30, 20:40] = (0, 128, 255)
    log = FlightLog(tmp_path / "flight.mcap")
    log.write(ch.CAMERA_INFO, 0.0, ch.camera_info_record(front_camera()))
    for k in range(3):
        log.write_image("front", 0.1 * k, encode_jpeg(image, 95))
    log.write_image("down", 0.05, encode_jpeg(image, 95))
    log.close()
    with open(tmp_path / "flight.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    schema_names = {s.name for s in summary.schemas.values()}
    assert "foxglove.CompressedImage" in schema_names
    front = list(read_images(tmp_path / "flight.mcap", "front"))
    assert [im.time_s for im in front] == pytest.approx([0.0, 0.1, 0.2])
    assert len(list(read_images(tmp_path / "flight.mcap"))) == 4
    import cv2

    decoded = cv2.imdecode(np.frombuffer(front[0].jpeg, np.uint8), cv2.IMREAD_COLOR)
    error = np.abs(decoded.astype(int) - image)
    assert error.mean() < 1.0  # quality 95
    assert error[14:26, 24:36].max() <= 3  # 4:4:4: the colour holds up to its edges
    # the JSON readers skip the image channels
    assert set(read_log(tmp_path / "flight.mcap")) == {ch.CAMERA_INFO}


def test_records_come_back_as_the_messages_they_were_made_from():
    state = vehicle_state(1.5, pos=(1.0, -2.0, -3.0), vel=(0.5, 0.0, -0.1), yaw=0.7)
    again = ch.vehicle_state_from_record(ch.clean(ch.vehicle_state_record(state)))
    assert again.time_s == state.time_s
    assert again.mode == state.mode
    for name in ("position_ned_m", "velocity_ned_m_s", "attitude_q"):
        assert np.array_equal(getattr(again, name), getattr(state, name))
    camera = front_camera(10.0)
    info = ch.camera_info_from_record(ch.clean(ch.camera_info_record(camera)))
    assert info.intrinsics == camera.intrinsics
    assert np.array_equal(info.rotation_body_cam, camera.rotation_body_cam)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_stops_the_file_not_the_flight(caplog):
    log = FlightLog(Path("/dev/full"))  # every write fails with ENOSPC
    for k in range(2000):
        log.write(ch.MISSION_EVENTS, 0.01 * k, {"time_s": 0.01 * k, "step": "", "text": "x" * 64})
        log.write_image("front", 0.01 * k, b"\xff" * 1000)
    deadline = time.monotonic() + 10.0
    while log.error is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert isinstance(log.error, OSError)
    written = log.images_written
    for k in range(10):  # from then on the records stay in memory: the metrics have them
        log.write(ch.MISSION_EVENTS, 30.0 + k, {"time_s": 30.0 + k, "step": "", "text": "y"})
        log.write_image("front", 30.0 + k, b"\xff" * 1000)  # ... frames are dropped
    assert log.images_written == written
    assert log.images_dropped >= 10
    log.close()
    kept = log.all_records()[ch.MISSION_EVENTS]
    assert [r["text"] for r in kept[-10:]] == ["y"] * 10
    assert len(kept) <= 2010
    # what was still queued for the file when it failed is kept too, and the failure said
    assert len(kept) > 1000
    assert any("writing failed" in r.getMessage() for r in caplog.records)


def test_records_stream_to_the_file_not_to_memory(tmp_path):
    log = FlightLog(tmp_path / "flight.mcap")
    for k in range(5000):
        log.write(ch.MISSION_EVENTS, 0.01 * k, {"time_s": 0.01 * k, "step": "", "text": "x"})
    assert sum(len(v) for v in log.records.values()) == 0  # bounded: nothing kept
    log.close()
    again = log.all_records()[ch.MISSION_EVENTS]
    assert len(again) == 5000
    assert again[-1]["time_s"] == pytest.approx(49.99)
