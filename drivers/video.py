"""Compressed video in and out: H.264 in MPEG-TS over UDP (or any stream FFmpeg opens), PyAV.

* :class:`VideoSender` encodes frames (libx264, ``ultrafast`` / ``zerolatency``) into MPEG-TS on
  UDP, as PX4's simulated cameras stream to port 5600. Each frame's presentation timestamp is
  its capture time on the sender's clock (90 kHz, MPEG-TS's own clock), so a receiver knows
  when a frame was taken, not only when it arrived: the autopilot's latency figure can be
  checked against the camera's own stamps.
* :class:`VideoSource` decodes a stream (``udp://@:5600``, ``rtsp://…``, a file, a V4L2 device)
  on a thread of its own, keeps only the newest frame, and hands frames to the event loop with
  their capture time mapped onto the local clock. It decodes only while someone subscribes.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable
from fractions import Fraction

import numpy as np

from drivers.base import CameraInfo, Frame
from drivers.slots import Broadcast

log = logging.getLogger(__name__)

PTS_HZ = 90_000
TIME_BASE = Fraction(1, PTS_HZ)
_PTS_WRAP = 1 << 33  # MPEG-TS timestamps are 33-bit


class VideoSender:
    """Encode BGR frames to H.264 and send them as MPEG-TS to ``url`` (blocking calls: run it
    on a thread of its own)."""

    def __init__(self, url: str, width_px: int, height_px: int, rate_hz: float, *,
                 bitrate_bps: int = 2_000_000, keyframe_interval: int = 30) -> None:
        import av

        target = url if "pkt_size" in url else f"{url}{'&' if '?' in url else '?'}pkt_size=1316"
        self._container = av.open(target, mode="w", format="mpegts", options={
            "max_delay": "0", "flush_packets": "1", "mpegts_copyts": "1"})
        stream = self._container.add_stream("libx264", rate=Fraction(rate_hz).limit_denominator(
            1001))
        stream.width, stream.height = width_px, height_px
        stream.pix_fmt = "yuv420p"
        stream.bit_rate = bitrate_bps
        stream.time_base = TIME_BASE
        stream.codec_context.time_base = TIME_BASE
        stream.options = {"preset": "ultrafast", "tune": "zerolatency",
                          "g": str(keyframe_interval), "bf": "0"}
        self._stream = stream
        self._last_pts = -1
        self.frames_sent = 0

    def send(self, image: np.ndarray, capture_time_s: float) -> None:
        import av

        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        pts = round(capture_time_s * PTS_HZ)
        if pts <= self._last_pts:
            return  # timestamps must increase
        frame.pts, frame.time_base = pts, TIME_BASE
        self._last_pts = pts
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self.frames_sent += 1

    def close(self) -> None:
        with contextlib.suppress(Exception):
            for packet in self._stream.encode(None):
                self._container.mux(packet)
        self._container.close()


class VideoSource:
    """Frames decoded from ``url`` for a camera described by ``info``.

    ``to_local`` maps the stream's capture timestamps (seconds on the sender's clock) onto the
    local clock; with None, frames are stamped with their arrival time instead (a stream
    that carries no usable timestamps).
    """

    def __init__(self, url: str, info: CameraInfo, *,
                 to_local: Callable[[float], float] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 open_timeout_s: float = 5.0) -> None:
        self.url = url
        self.info = info
        self._to_local = to_local
        self._clock = clock
        self._open_timeout_s = open_timeout_s
        self._broadcast: Broadcast[Frame] = Broadcast(on_first=self._start, on_last=self._stop)
        self._thread: threading.Thread | None = None
        self._stop_flag = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self.decoded = 0
        self.error: Exception | None = None

    def frames(self) -> AsyncIterator[Frame]:
        self._loop = asyncio.get_running_loop()
        return self._broadcast.subscribe()

    async def close(self) -> None:
        self._stop()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
            self._thread = None
        self._broadcast.close(None)

    def _start(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            return
        self._stop_flag.clear()
        self._thread = threading.Thread(target=self._decode, name=f"video-{self.info.name}",
                                        daemon=True)
        self._thread.start()

    def _stop(self) -> None:
        self._stop_flag.set()

    def _options(self) -> dict[str, str]:
        options = {"fflags": "nobuffer", "flags": "low_delay", "probesize": "65536",
                   "analyzeduration": "500000"}
        if self.url.startswith("udp:"):
            options.update({"overrun_nonfatal": "1", "fifo_size": "50000",
                            "timeout": str(int(self._open_timeout_s * 1e6))})
        elif self.url.startswith(("rtsp:", "rtp:")):
            options["timeout"] = str(int(self._open_timeout_s * 1e6))
        return options

    def _decode(self) -> None:
        import av

        seq = 0
        while not self._stop_flag.is_set():
            try:
                with av.open(self.url, options=self._options()) as container:
                    stream = container.streams.video[0]
                    stream.thread_type = "SLICE"
                    for frame in container.decode(stream):
                        if self._stop_flag.is_set():
                            return
                        arrived = self._clock()
                        image = frame.to_ndarray(format="bgr24")
                        image.flags.writeable = False
                        stamp = arrived
                        if self._to_local is not None and frame.pts is not None:
                            sent_s = (frame.pts % _PTS_WRAP) * float(frame.time_base)
                            stamp = min(self._to_local(sent_s), arrived)
                        self.decoded += 1
                        out = Frame(camera=self.info, time_s=stamp, seq=seq, image=image)
                        seq += 1
                        if self._loop is not None:
                            self._loop.call_soon_threadsafe(self._broadcast.publish, out)
            except Exception as exc:  # stream not there yet, timed out, or broken: retry
                self.error = exc
                log.debug("video %s: %s", self.url, exc)
                self._stop_flag.wait(0.2)
