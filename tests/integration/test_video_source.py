"""Network video end to end on loopback: H.264 over RTP (and RTCP) from a
:class:`~drivers.video.VideoSender` to a :class:`~drivers.video.VideoSource`, stamped by the
stream's own clock only when it says what that clock is, and taken from one sender only."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
import threading
import time

import cv2
import numpy as np
import pytest

from drivers.base import CameraInfo, CameraIntrinsics
from drivers.video import TimeSource, VideoSender, VideoSource

pytestmark = pytest.mark.serial  # RTP video on the wall clock

W, H = 320, 240
RATE_HZ = 30.0


def _camera() -> CameraInfo:
    return CameraInfo(name="front", intrinsics=CameraIntrinsics(W, H, 160.0, 160.0, 159.5, 119.5),
                      rotation_body_cam=np.eye(3), position_body_m=np.zeros(3), rate_hz=RATE_HZ)


def _image(k: int) -> np.ndarray:
    """A grey frame with a white square whose position encodes the frame number."""
    img = np.full((H, W, 3), 60, np.uint8)
    x = 10 + (k * 4) % (W - 40)
    img[100:130, x:x + 30] = 255
    return img


def _red(k: int) -> np.ndarray:
    img = np.zeros((H, W, 3), np.uint8)
    img[:, :, 2] = 220
    return img


def _square_x(img: np.ndarray) -> float:
    mask = cv2.inRange(img, (200, 200, 200), (255, 255, 255))
    m = cv2.moments(mask, binaryImage=True)
    return m["m10"] / m["m00"] - 14.5 if m["m00"] else float("nan")


def _is_red(img: np.ndarray) -> bool:
    b, g, r = img.reshape(-1, 3).mean(axis=0)
    return r > 150 and b < 60 and g < 60


def _free_port_pair() -> int:
    """An even port that is free, with the next one up (RTCP) free too."""
    for _ in range(100):
        port = random.randrange(40_000, 60_000, 2)
        with contextlib.ExitStack() as stack:
            try:
                for p in (port, port + 1):
                    sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
                    sock.bind(("127.0.0.1", p))
            except OSError:
                continue
        return port
    raise RuntimeError("no free UDP port pair")


class _Stream:
    """A camera on a thread of its own: ``images(k)`` at 30 Hz, captured on time.monotonic()."""

    def __init__(self, port: int, images=_image, bind: bool = False, **sender_options) -> None:
        self.sender = VideoSender(f"udp://127.0.0.1:{port}", W, H, RATE_HZ, **sender_options)
        if bind:  # to know its address before it sends (a configured source)
            self.sender._sock.bind(("127.0.0.1", 0))
        self.images = images
        self._address: tuple[str, int] | None = None
        self.sent: list[float] = []  # capture times, by frame number
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        if self._address is None:  # bound by its first datagram (to 0.0.0.0), or by ``bind``
            self._address = ("127.0.0.1", self.sender._sock.getsockname()[1])
        return self._address

    def _run(self) -> None:
        k = 0
        while not self._stop.is_set() and k < 600:
            capture_s = time.monotonic()
            self.sender.send(self.images(k), capture_s)
            self.sent.append(round(capture_s * 90_000) / 90_000)
            k += 1
            self._stop.wait(1 / RATE_HZ)

    def start(self) -> _Stream:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        if self.sent:
            _ = self.address  # while it is open
        self.sender.close()


async def _until(condition, timeout_s: float = 10.0) -> None:
    """Poll: what is waited for happens on the source's decoding thread, which sets no event."""
    async with asyncio.timeout(timeout_s):
        while not condition():  # noqa: ASYNC110
            await asyncio.sleep(0.01)


async def _receive(source: VideoSource, count: int, start, timeout_s: float = 20.0):
    """``count`` frames from ``source`` with their arrival on time.monotonic(); ``start()`` is
    called once the source listens, and returns the streams to stop at the end."""
    got: list[tuple[object, float]] = []

    async def consume() -> None:
        async with contextlib.aclosing(source.frames()) as frames:
            async for frame in frames:
                got.append((frame, time.monotonic()))
                if len(got) >= count:
                    return

    task = asyncio.get_running_loop().create_task(consume())
    streams: list[_Stream] = []
    try:
        await _until(lambda: source.local_address is not None)
        streams = await start()
        await asyncio.wait_for(task, timeout_s)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        await source.close()  # first: what the streams say as they stop is not heard
        for stream in streams:
            await asyncio.to_thread(stream.stop)
    return got


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_the_simulator_s_frames_arrive_with_their_capture_times_on_the_vehicle_clock(caplog):
    """Its RTP timestamps are the vehicle's clock (here the local one: to_local is identity)
    and its RTCP says so."""
    port = _free_port_pair()
    source = VideoSource(f"udp://@:{port}", _camera(), to_local=lambda s: s, latency_s=0.03)
    streams = []

    async def start():
        streams.append(_Stream(port).start())
        return streams

    got = asyncio.run(_receive(source, 30, start))
    sent = {t: k for k, t in enumerate(streams[0].sent)}
    for frame, arrived_s in got:
        k = sent.get(round(frame.time_s * 90_000) / 90_000)
        assert k is not None, f"stamp {frame.time_s} is not a capture time that was sent"
        assert frame.time_s <= arrived_s
        assert frame.image.shape == (H, W, 3)
        assert _square_x(frame.image) == pytest.approx(10 + (k * 4) % (W - 40), abs=1.5)
    stamps = [f.time_s for f, _ in got]
    assert stamps == sorted(stamps)  # newest only: frames only go forward in time
    assert source.timing.mode is TimeSource.VEHICLE_CLOCK
    assert source.timing.ours
    assert source.stats.rtcp >= 1
    assert source.stats.ignored == 0
    assert not _warnings(caplog)


def test_a_camera_with_rtcp_and_a_random_rtp_start_is_stamped_from_its_wall_clock(caplog):
    port = _free_port_pair()
    source = VideoSource(f"udp://127.0.0.1:{port}", _camera(), to_local=lambda s: s)
    streams = []

    async def start():
        streams.append(_Stream(port, cname="camera@127.0.0.1",
                               rtp_offset_ticks=random.getrandbits(32),
                               capture_clock=time.monotonic).start())
        return streams

    got = asyncio.run(_receive(source, 20, start))
    sent = np.array(streams[0].sent)
    for frame, arrived_s in got:
        k = int(np.argmin(np.abs(sent - frame.time_s)))
        assert frame.time_s == pytest.approx(sent[k], abs=2e-3)  # clocks read µs apart
        assert frame.time_s <= arrived_s
        assert _square_x(frame.image) == pytest.approx(10 + (k * 4) % (W - 40), abs=1.5)
    assert source.timing.mode is TimeSource.RTCP
    assert not source.timing.ours
    assert not _warnings(caplog)


def test_a_camera_without_rtcp_is_stamped_with_arrival_less_its_latency(caplog):
    """Random RTP start, no RTCP: whatever the RTP timestamps say, and even with a vehicle
    clock mapping at hand, only the arrival time and the configured latency are known."""
    port = _free_port_pair()
    latency_s = 0.04
    source = VideoSource(f"udp://@:{port}", _camera(), to_local=lambda s: s,
                         latency_s=latency_s)
    streams = []

    async def start():
        streams.append(_Stream(port, rtcp=False, cname="camera",
                               rtp_offset_ticks=random.getrandbits(32)).start())
        return streams

    got = asyncio.run(_receive(source, 20, start))
    for frame, arrived_s in got:
        # stamped just before the loop took it: arrival − latency, a little earlier
        assert 0.0 <= arrived_s - (frame.time_s + latency_s) < 0.5
        assert not np.isnan(_square_x(frame.image))
    assert source.timing.mode is TimeSource.ARRIVAL
    assert source.timing.counts[TimeSource.ARRIVAL] >= 20
    assert source.timing.counts[TimeSource.VEHICLE_CLOCK] == 0
    assert source.timing.counts[TimeSource.RTCP] == 0
    assert source.stats.rtcp == 0
    assert not _warnings(caplog)


def test_a_second_sender_is_ignored_and_counted_and_does_not_corrupt_the_first(caplog):
    port = _free_port_pair()
    source = VideoSource(f"udp://@:{port}", _camera())
    streams: list[_Stream] = []

    async def start():
        streams.append(_Stream(port, rtcp=False, cname="camera").start())
        await _until(lambda: source.sender is not None)
        # another camera (or someone else) on the same port, claiming to be the simulator
        streams.append(_Stream(port, images=_red).start())
        await _until(lambda: source.stats.ignored > 20)
        return streams

    got = asyncio.run(_receive(source, 60, start))
    first, second = streams
    assert source.sender == first.address
    assert source.stats.ignored_from == f"127.0.0.1:{second.address[1]}"
    assert source.stats.ignored > 20
    assert all(not _is_red(frame.image) for frame, _ in got)
    assert all(not np.isnan(_square_x(frame.image)) for frame, _ in got[-30:])
    assert source.timing.mode is TimeSource.ARRIVAL  # the second's RTCP did not take over
    ignored = [m for m in _warnings(caplog) if "ignoring datagrams" in m]
    assert ignored == [f"video front (udp://@:{port}): ignoring datagrams from "
                       f"127.0.0.1:{second.address[1]} (receiving from "
                       f"127.0.0.1:{first.address[1]}); further ones are only counted"]


def test_only_the_configured_source_is_taken(caplog):
    port = _free_port_pair()
    streams: list[_Stream] = []
    wanted = _Stream(port, images=_red, bind=True)
    source = VideoSource(f"udp://@:{port}?source=127.0.0.1:{wanted.address[1]}", _camera())

    async def start():
        streams.append(_Stream(port).start())  # first, but not the one configured
        await _until(lambda: source.stats.ignored > 10)
        streams.append(wanted.start())
        return streams

    got = asyncio.run(_receive(source, 10, start))
    assert source.sender == wanted.address
    assert all(_is_red(frame.image) for frame, _ in got)
    assert any("not the configured source" in m for m in _warnings(caplog))


def test_a_sender_that_says_goodbye_is_followed_by_the_next_one():
    """A camera restarts: a new socket (port) and SSRC; its BYE frees the stream at once."""
    port = _free_port_pair()
    source = VideoSource(f"udp://@:{port}", _camera(), relock_after_s=60.0)
    streams: list[_Stream] = []

    async def start():
        before = _Stream(port).start()
        await _until(lambda: source.stats.frames >= 5)
        await asyncio.to_thread(before.stop)  # sends RTCP BYE
        await _until(lambda: source.sender is None, 2.0)
        streams.append(_Stream(port, images=_red).start())
        return streams

    got = asyncio.run(_receive(source, 40, start))
    assert _is_red(got[-1][0].image)
    assert source.sender == streams[0].address


def test_the_default_address_is_loopback():
    port = _free_port_pair()
    source = VideoSource(f"udp://@:{port}", _camera())

    async def start():
        assert source.local_address == ("127.0.0.1", port)
        return [_Stream(port).start()]

    asyncio.run(_receive(source, 1, start))
    assert source.local_address is None  # closed


def test_a_video_file_plays_through_ffmpeg_stamped_at_arrival(tmp_path):
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
        source = VideoSource(str(path), _camera(), latency_s=0.1)
        got = []
        try:
            async with contextlib.aclosing(source.frames()) as frames:
                async with asyncio.timeout(20.0):
                    async for frame in frames:
                        got.append((frame, time.monotonic()))
                        if source.decoded >= 20:
                            break
        finally:
            await source.close()
        return got, source

    started = time.monotonic()
    got, source = asyncio.run(main())
    assert source.decoded == 20
    assert time.monotonic() - started >= 19 / 30  # played at the file's own 30 fps
    assert got  # newest-only hand-over: the frames the loop was there to take
    last = got[-1][0]
    k = 10 + round((_square_x(last.image) - 10) / 4)  # which frame this is, from its square
    assert 0 <= (k - 10) <= 19
    assert [f.seq for f, _ in got] == sorted(f.seq for f, _ in got)
    for frame, arrived_s in got:
        assert 0.0 <= arrived_s - (frame.time_s + 0.1) < 0.5
    assert source.timing.mode is TimeSource.ARRIVAL


def test_garbage_in_the_stream_is_survived():
    """RTP/H.264 garbage (Hypothesis) from the very sender the source took: random bytes, RTP
    headers with random payloads and sequence jumps, cut and corrupted NAL units, RTCP noise,
    oversized datagrams. The source decodes on, frames keep arriving, and what follows the
    garbage is the stream's own picture again."""
    import struct

    from hypothesis import given, settings
    from hypothesis import strategies as st

    port = _free_port_pair()
    source = VideoSource(f"udp://@:{port}", _camera())
    streams: list[_Stream] = []
    thrown = [0]

    def rtp(pt: int, seq: int, ts: int, ssrc: int, payload: bytes, marker: bool) -> bytes:
        return struct.pack("!BBHII", 0x80, (0x80 if marker else 0) | (pt & 0x7F), seq & 0xFFFF,
                           ts & 0xFFFFFFFF, ssrc & 0xFFFFFFFF) + payload

    nal = st.one_of(
        st.binary(max_size=1400),
        st.builds(lambda kind, body: bytes([kind]) + body,
                  st.sampled_from([0x65, 0x41, 0x67, 0x68, 0x7C, 0x78, 0x06, 0x1F]),
                  st.binary(max_size=1200)))
    datagrams = st.one_of(
        st.binary(max_size=1500),
        st.builds(rtp, st.sampled_from([96, 97, 0, 127]), st.integers(0, 70000),
                  st.integers(0, 2 ** 32), st.integers(0, 2 ** 32), nal, st.booleans()),
        st.just(b"\x80\xc8" + b"\x00" * 6),  # a cut RTCP sender report
        st.just(b"\x80" * 9000))

    @settings(deadline=None, max_examples=200, derandomize=True)
    @given(datagrams)
    def throw(datagram):
        sock = streams[0].sender._sock
        with contextlib.suppress(OSError):
            sock.sendto(datagram, ("127.0.0.1", port))
            thrown[0] += 1

    async def start():
        streams.append(_Stream(port).start())
        await _until(lambda: source.sender is not None)
        await asyncio.to_thread(throw)
        return streams

    got = asyncio.run(_receive(source, 200, start, timeout_s=40.0))
    assert thrown[0] >= 150
    assert len(got) == 200
    # after the garbage, the stream's own pictures again (the square where it belongs)
    assert all(not np.isnan(_square_x(frame.image)) for frame, _ in got[-20:])


def test_lost_rtp_packets_are_not_sent():
    """The simulator's link_loss fault (``video_fraction``) loses RTP packets at the sender:
    each one it is asked about and told to drop never reaches the wire."""
    port = _free_port_pair()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as listener:
        listener.bind(("127.0.0.1", port))
        listener.settimeout(0.2)
        decisions = iter([False, True] * 10_000)  # every second packet lost
        sender = VideoSender(f"udp://127.0.0.1:{port}", W, H, RATE_HZ, rtcp=False,
                             drop=lambda: next(decisions))
        try:
            for k in range(10):
                sender.send(_image(k), 1.0 + k / RATE_HZ)
            received = 0
            with contextlib.suppress(TimeoutError):
                while True:
                    listener.recv(65536)
                    received += 1
        finally:
            sender.close()
    assert sender.packets_dropped > 0
    assert received == sender.packets_sent
    assert sender.packets_sent == sender.packets_dropped or \
        abs(sender.packets_sent - sender.packets_dropped) <= 1
