"""``autopilot bench calibration`` and ``autopilot calibrate`` on the simulator's camera:
views of a ChArUco board rendered from known poses (distortion, noise, motion blur), the
calibration scored against the simulator's true intrinsics; the command on a folder of those
views, and on a live RTP H.264 stream of them."""

from __future__ import annotations

import contextlib
import io
import json
import socket
import threading
import time

import cv2
import pytest

from autopilot.bench.calibration import (
    FOCAL_ERROR_MAX_PCT,
    QUICK_OPTIONS,
    REPROJECTION_RMS_MAX_PX,
)
from autopilot.calibration import FrameSource, calibrate_frames, parse_board_spec
from autopilot.cli import EXIT_OK, main
from drivers.calibration import load_calibration

pytestmark = pytest.mark.serial  # a live RTP video source

BOARD = QUICK_OPTIONS.boards[0]


@pytest.fixture(scope="module")
def quick_bench(tmp_path_factory):
    """``autopilot bench calibration --quick --json --save-views DIR``: its result and DIR."""
    views = tmp_path_factory.mktemp("views")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["bench", "calibration", "--quick", "--json", "--save-views", str(views)])
    assert code == EXIT_OK
    return json.loads(printed.getvalue()), views


def test_quick_bench_meets_the_required_accuracy(quick_bench):
    result, _ = quick_bench
    section = result["boards"]["charuco"]
    assert section["board"] == BOARD
    # the figures
    assert result["focal_error_pct"] <= FOCAL_ERROR_MAX_PCT
    assert result["reprojection_rms_px"] <= REPROJECTION_RMS_MAX_PX
    assert all(req["met"] for req in result["required"].values())
    # and what makes them believable: many views, spread over the image and tilted, the
    # blurred ones left out, and the whole lens model close to the truth
    assert section["views_used"] >= 20
    assert section["blurred_rendered"] >= 3
    assert section["blurred_used"] <= 1
    assert section["coverage"]["border_cells_fraction"] >= 0.8
    assert section["coverage"]["tilt_deg_max"] >= 40.0
    assert section["principal_point_error_px"] < 2.0
    assert section["model_p95_error_px"] < 1.0
    truth = result["truth"]
    assert truth["distortion"] == result["camera"]["distortion"]
    assert abs(section["estimate"]["fx"] - truth["fx"]) / truth["fx"] * 100 == pytest.approx(
        section["fx_error_pct"])


def test_the_command_calibrates_the_rendered_views(quick_bench, tmp_path, capsys):
    result, views = quick_bench
    truth = result["truth"]
    out = tmp_path / "front.yaml"
    code = main(["calibrate", str(views / "charuco"), "--board", BOARD, "--out", str(out),
                 "--camera-name", "front"])
    printed = capsys.readouterr().out
    assert code == EXIT_OK
    assert "reprojection RMS" in printed
    for path in (out, tmp_path / "front_ros.yaml"):
        got = load_calibration(path)
        assert (got.width_px, got.height_px) == (result["camera"]["width_px"],
                                                 result["camera"]["height_px"])
        assert abs(got.fx - truth["fx"]) / truth["fx"] * 100 <= FOCAL_ERROR_MAX_PCT
        assert abs(got.fy - truth["fy"]) / truth["fy"] * 100 <= FOCAL_ERROR_MAX_PCT
        assert abs(got.cx - truth["cx"]) < 2.0
        assert abs(got.cy - truth["cy"]) < 2.0
        assert got.distortion[0] == pytest.approx(truth["distortion"][0], abs=0.01)


def _free_udp_port_pair() -> int:
    for _ in range(20):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as a:
            a.bind(("127.0.0.1", 0))
            port = a.getsockname()[1]
            if port % 2 or port >= 65534:
                continue
            try:
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as b:
                    b.bind(("127.0.0.1", port + 1))
            except OSError:
                continue
            return port
    raise RuntimeError("no free pair of UDP ports")


def test_a_live_rtp_stream_is_calibrated(quick_bench):
    """The views streamed as RTP H.264 (as a PX4 camera or 'autopilot sim' sends them) to a
    udp:// source, with a frame limit."""
    from drivers.video import VideoSender

    result, views = quick_bench
    truth = result["truth"]
    images = [cv2.imread(str(p)) for p in sorted((views / "charuco").glob("*.png"))]
    port = _free_udp_port_pair()
    url = f"udp://127.0.0.1:{port}"
    stop = threading.Event()

    def stream() -> None:
        sender = VideoSender(url, images[0].shape[1], images[0].shape[0], 10.0,
                             bitrate_bps=8_000_000, keyframe_interval=10)
        try:
            n = 0
            started = time.monotonic()
            while not stop.is_set():
                # each view held for three frames, so that the newest one read is whole
                sender.send(images[(n // 3) % len(images)], time.monotonic() - started)
                n += 1
                time.sleep(0.04)
        finally:
            sender.close()

    thread = threading.Thread(target=stream, daemon=True)
    thread.start()
    try:
        source = FrameSource(url, max_frames=120, duration_s=25.0)
        assert source.kind == "live"
        calibrated = calibrate_frames(source, parse_board_spec(BOARD))
    finally:
        stop.set()
        thread.join(5.0)
    assert calibrated.frames_read <= 120
    assert len(calibrated.views) >= 12
    intr = calibrated.intrinsics
    # compressed video: a little less precise than the PNG files
    assert abs(intr.fx - truth["fx"]) / truth["fx"] * 100 < 1.0
    assert calibrated.reprojection_rms_px < 0.5
