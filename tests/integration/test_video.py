"""``onboard.mp4``: the logged frames of a flight, with overlays, decodable by OpenCV."""

import cv2
import pytest

from autopilot.cli import main
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_images, read_log
from autopilot.mission import load_mission
from autopilot.report.video import VideoError, write_video


def _decode(path):
    capture = cv2.VideoCapture(str(path))
    frames, first = 0, None
    while True:
        ok, image = capture.read()
        if not ok:
            break
        frames += 1
        first = image if first is None else first
    fps = capture.get(cv2.CAP_PROP_FPS)
    capture.release()
    return frames, fps, first


def test_onboard_video_has_every_frame_at_the_camera_rate(logged_flight, tmp_path):
    run_dir, summary = logged_flight
    logged = list(read_images(run_dir / "flight.mcap", "front"))
    camera = next(c for c in read_log(run_dir / "flight.mcap")[ch.CAMERA_INFO]
                  if c["name"] == "front")
    # --record-video: every frame, from takeoff to landing
    assert len(logged) == summary["stats"]["frames_logged"]
    # (the realistic camera drops ~1 % of its frames: they never existed to be logged)
    drop = load_mission("follow_ball").config.sim.cameras["front"].drop_fraction
    expected = summary["sim_time_s"] * camera["rate_hz"] * (1.0 - drop)
    assert len(logged) == pytest.approx(expected, abs=2 + 3 * (expected * drop) ** 0.5)
    path, count = write_video(run_dir, out=tmp_path / "onboard.mp4")
    frames, fps, first = _decode(path)
    assert frames == count == len(logged)
    # frames keep their capture times: a dropped one leaves its gap (the average rate is
    # the camera's less the drops)
    assert camera["rate_hz"] * (1.0 - drop - 0.01) <= fps <= camera["rate_hz"] * (1 + 1e-3)
    assert first.shape == (camera["height_px"], camera["width_px"], 3)


def test_video_command_and_its_errors(logged_flight, tmp_path, capsys):
    run_dir, _ = logged_flight
    with pytest.raises(VideoError, match="no logged frames of camera 'down'"):
        write_video(run_dir, "down", out=tmp_path / "x.mp4")
    assert main(["video", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err


def test_run_records_a_chosen_camera_and_reports(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "--mission", "follow_ball", "--out", str(out), "--report",
                 "--record-video", "down", "--set", "steps.1.follow_ball.duration_s=2"])
    assert code == 0
    printed = capsys.readouterr().out
    assert f"wrote {out / 'onboard.mp4'}" in printed
    down = list(read_images(out / "flight.mcap", "down"))
    front = list(read_images(out / "flight.mcap", "front"))
    assert len(down) > 100  # every frame of the downward camera, from takeoff to landing
    assert len(front) > 100  # and the followed camera's, as always in the simulator
    frames, _, _ = _decode(out / "onboard.mp4")
    assert frames == len(down)
    report = (out / "report.html").read_text()
    assert "<video" in report
    assert "/camera/down/image/compressed" in report


def test_an_unknown_video_camera_is_refused_before_flying(tmp_path, capsys):
    code = main(["run", "--mission", "follow_ball", "--out", str(tmp_path / "run"),
                 "--record-video", "rear"])
    assert code == 2
    assert "rear: no such camera" in capsys.readouterr().err
    assert not (tmp_path / "run" / "flight.mcap").exists()
