"""The video path: H.264 encode → MPEG-TS over UDP → decode, with capture timestamps."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time

import cv2
import numpy as np
import pytest

from drivers.base import CameraInfo, CameraIntrinsics
from drivers.video import VideoSender, VideoSource

PORT = 56011
W, H = 320, 240


def _info() -> CameraInfo:
    return CameraInfo(name="front", intrinsics=CameraIntrinsics(W, H, 160.0, 160.0, 159.5,
                                                                 119.5),
                      rotation_body_cam=np.eye(3), position_body_m=np.zeros(3), rate_hz=30.0)


def _image(k: int) -> np.ndarray:
    """A grey frame with a white square whose position encodes the frame number."""
    img = np.full((H, W, 3), 60, np.uint8)
    x = 10 + (k * 4) % (W - 40)
    img[100:130, x:x + 30] = 255
    return img


def _square_x(img: np.ndarray) -> float:
    mask = cv2.inRange(img, (200, 200, 200), (255, 255, 255))
    m = cv2.moments(mask, binaryImage=True)
    return m["m10"] / m["m00"] - 14.5 if m["m00"] else float("nan")


def test_frames_arrive_decoded_with_their_capture_times():
    sent: dict[float, int] = {}
    stop = threading.Event()

    def send() -> None:
        sender = VideoSender(f"udp://127.0.0.1:{PORT}", W, H, 30.0)
        try:
            k = 0
            while not stop.is_set() and k < 300:
                capture = time.monotonic()
                sender.send(_image(k), capture)
                sent[round(capture * 90_000) / 90_000] = k
                k += 1
                time.sleep(1 / 30)
        finally:
            sender.close()

    async def main():
        source = VideoSource(f"udp://@:{PORT}", _info(), to_local=lambda s: s)
        thread = threading.Thread(target=send, daemon=True)
        got = []
        try:
            async with contextlib.aclosing(source.frames()) as frames:
                thread.start()
                async with asyncio.timeout(20.0):
                    async for frame in frames:
                        got.append((frame, time.monotonic()))
                        if len(got) >= 30:
                            break
        finally:
            stop.set()
            thread.join(5.0)
            await source.close()
        for frame, arrived in got:
            k = sent.get(round(frame.time_s * 90_000) / 90_000)
            assert k is not None, f"stamp {frame.time_s} is not a capture time that was sent"
            assert frame.time_s <= arrived
            assert frame.image.shape == (H, W, 3)
            assert _square_x(frame.image) == pytest.approx(10 + (k * 4) % (W - 40), abs=1.5)
        # newest first: frames only go forward in time
        stamps = [f.time_s for f, _ in got]
        assert stamps == sorted(stamps)

    asyncio.run(main())


def test_a_video_file_plays_through_ffmpeg(tmp_path):
    import av

    path = tmp_path / "clip.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=30)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        for k in range(20):
            frame = av.VideoFrame.from_ndarray(_image(k), format="bgr24")
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)

    async def main():
        source = VideoSource(str(path), _info())  # no stamp mapping: arrival times
        got = []
        try:
            async with contextlib.aclosing(source.frames()) as frames:
                async with asyncio.timeout(20.0):
                    async for frame in frames:
                        got.append(frame)
                        if source.decoded >= 20:
                            break
        finally:
            await source.close()
        return got, source.decoded

    started = time.monotonic()
    got, decoded = asyncio.run(main())
    assert decoded == 20
    assert time.monotonic() - started >= 19 / 30  # played at the file's own 30 fps
    assert got  # newest-only hand-over: the frames the loop was there to take
    last = got[-1]
    k = 10 + round((_square_x(last.image) - 10) / 4)  # which frame this is, from its square
    assert 0 <= (k - 10) <= 19
    assert [f.seq for f in got] == sorted(f.seq for f in got)
