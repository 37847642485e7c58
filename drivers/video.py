"""Compressed video in and out: H.264 over RTP on UDP (PX4 / QGroundControl's convention for
port 5600), or anything FFmpeg opens, through PyAV.

* :class:`VideoSender` encodes frames (libx264, ``ultrafast`` / ``zerolatency``, SPS/PPS with
  every keyframe) and sends them as RTP (RFC 6184: single NAL units and FU-A fragments, payload
  type 96), the marker bit on each frame's last packet. The RTP timestamp (90 kHz) is the
  frame's capture time on the sender's clock, so a receiver knows when a frame was taken, not
  only when it arrived: the autopilot's latency figure is checked against the camera's stamps.
* :class:`VideoSource` receives and decodes on a thread of its own and hands the newest frame
  to the event loop with its capture time mapped onto the local clock; frames that are already
  stale when decoded are not converted or handed over. ``udp://@:PORT`` (or ``rtp://``) is RTP
  H.264 as above; any other URL (``rtsp://``, a file, ``/dev/video0``) goes to FFmpeg. It
  decodes only while someone subscribes.
"""

from __future__ import annotations

import asyncio
import logging
import os
import random
import select
import socket
import struct
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterator
from fractions import Fraction
from urllib.parse import urlsplit

import numpy as np

from drivers.base import CameraInfo, Frame
from drivers.slots import Broadcast

log = logging.getLogger(__name__)

RTP_CLOCK_HZ = 90_000
RTP_PAYLOAD_TYPE = 96
_TS_WRAP = 1 << 32
_MAX_PAYLOAD_B = 1400


def _rtp_address(url: str, *, listen: bool) -> tuple[str, int] | None:
    """(host, port) of an RTP URL (``udp://`` or ``rtp://``), None for other URLs."""
    parts = urlsplit(url)
    if parts.scheme not in ("udp", "rtp") or parts.port is None:
        return None
    host = (parts.hostname or "").lstrip("@")
    return (host or ("0.0.0.0" if listen else "127.0.0.1")), parts.port


def split_nal_units(annexb: bytes) -> list[bytes]:
    """The NAL units of an H.264 Annex B byte stream (start codes removed)."""
    units = []
    i, n = 0, len(annexb)
    start = -1
    while i + 2 < n:
        if annexb[i] == 0 and annexb[i + 1] == 0 and annexb[i + 2] == 1:
            if start >= 0:
                end = i - 1 if i > 0 and annexb[i - 1] == 0 else i
                units.append(annexb[start:end])
            i += 3
            start = i
        else:
            i += 1
    if start >= 0 and start < n:
        units.append(annexb[start:])
    return [u for u in units if u]


class RtpH264Packetizer:
    """RFC 6184 packetization (non-interleaved mode)."""

    def __init__(self, ssrc: int | None = None, payload_type: int = RTP_PAYLOAD_TYPE,
                 max_payload_b: int = _MAX_PAYLOAD_B) -> None:
        self.ssrc = random.getrandbits(32) if ssrc is None else ssrc
        self.payload_type = payload_type
        self.max_payload_b = max_payload_b
        self._seq = random.getrandbits(16)

    def _header(self, timestamp: int, marker: bool) -> bytes:
        header = struct.pack("!BBHII", 0x80, (0x80 if marker else 0) | self.payload_type,
                             self._seq, timestamp % _TS_WRAP, self.ssrc)
        self._seq = (self._seq + 1) & 0xFFFF
        return header

    def packets(self, nal_units: list[bytes], timestamp: int) -> Iterator[bytes]:
        for index, nal in enumerate(nal_units):
            last_nal = index == len(nal_units) - 1
            if len(nal) <= self.max_payload_b:
                yield self._header(timestamp, last_nal) + nal
                continue
            indicator = (nal[0] & 0xE0) | 28  # FU-A
            kind = nal[0] & 0x1F
            body = nal[1:]
            chunk = self.max_payload_b - 2
            for offset in range(0, len(body), chunk):
                first, last = offset == 0, offset + chunk >= len(body)
                fu_header = (0x80 if first else 0) | (0x40 if last else 0) | kind
                yield (self._header(timestamp, last_nal and last)
                       + bytes((indicator, fu_header)) + body[offset:offset + chunk])


class RtpH264Depacketizer:
    """Reassembles access units from RTP packets; an access unit with a lost packet is
    dropped (the decoder recovers at the next keyframe)."""

    def __init__(self) -> None:
        self._units: list[bytes] = []
        self._fu: bytearray | None = None
        self._timestamp: int | None = None
        self._next_seq: int | None = None
        self._broken = False
        self.lost = 0

    def push(self, packet: bytes) -> tuple[int, bytes] | None:
        """Feed one datagram; returns ``(rtp_timestamp, annexb_access_unit)`` at a frame's end."""
        if len(packet) < 13 or packet[0] >> 6 != 2:
            return None
        csrc = packet[0] & 0x0F
        marker = bool(packet[1] & 0x80)
        seq, timestamp = struct.unpack_from("!HI", packet, 2)
        offset = 12 + 4 * csrc
        if packet[0] & 0x10:  # header extension
            if len(packet) < offset + 4:
                return None
            offset += 4 + 4 * struct.unpack_from("!H", packet, offset + 2)[0]
        payload = packet[offset:]
        if packet[0] & 0x20 and payload:  # padding
            payload = payload[:-payload[-1]]
        gap = self._next_seq is not None and seq != self._next_seq
        if gap:
            self.lost += (seq - self._next_seq) & 0xFFFF
        self._next_seq = (seq + 1) & 0xFFFF
        if timestamp != self._timestamp:  # a new frame (any unfinished one is dropped)
            self._units, self._fu, self._timestamp, self._broken = [], None, timestamp, gap
        else:
            self._broken = self._broken or gap
        if payload:
            self._add(payload)
        if not marker:
            return None
        units, broken = self._units, self._broken
        self._units, self._fu, self._timestamp, self._broken = [], None, None, False
        if broken or not units:
            return None
        return timestamp, b"".join(b"\x00\x00\x00\x01" + u for u in units)

    def _add(self, payload: bytes) -> None:
        kind = payload[0] & 0x1F
        if 1 <= kind <= 23:
            self._units.append(payload)
        elif kind == 24:  # STAP-A
            i = 1
            while i + 2 <= len(payload):
                size = struct.unpack_from("!H", payload, i)[0]
                self._units.append(payload[i + 2:i + 2 + size])
                i += 2 + size
        elif kind == 28 and len(payload) >= 2:  # FU-A
            start, end = payload[1] & 0x80, payload[1] & 0x40
            if start:
                self._fu = bytearray(((payload[0] & 0xE0) | (payload[1] & 0x1F),))
            if self._fu is None:
                self._broken = True
                return
            self._fu += payload[2:]
            if end:
                self._units.append(bytes(self._fu))
                self._fu = None


class VideoSender:
    """Encode BGR frames to H.264 and send them as RTP to ``url`` (``udp://HOST:PORT``).
    Blocking calls: run it on a thread of its own."""

    def __init__(self, url: str, width_px: int, height_px: int, rate_hz: float, *,
                 bitrate_bps: int = 2_000_000, keyframe_interval: int = 30) -> None:
        import av

        address = _rtp_address(url, listen=False)
        if address is None:
            raise ValueError(f"video output {url!r}: expected udp://HOST:PORT (RTP H.264)")
        self._address = address
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        codec = av.CodecContext.create("libx264", "w")
        codec.width, codec.height = width_px, height_px
        codec.pix_fmt = "yuv420p"
        codec.time_base = Fraction(1, RTP_CLOCK_HZ)
        codec.framerate = Fraction(rate_hz).limit_denominator(1001)
        codec.bit_rate = bitrate_bps
        codec.options = {"preset": "ultrafast", "tune": "zerolatency",
                         "x264-params": f"keyint={keyframe_interval}:bframes=0:"
                                        "repeat-headers=1:annexb=1"}
        codec.open()
        self._codec = codec
        self._rtp = RtpH264Packetizer()
        self._last_pts = -1
        self.frames_sent = 0

    def send(self, image: np.ndarray, capture_time_s: float) -> None:
        import av

        pts = round(capture_time_s * RTP_CLOCK_HZ)
        if pts <= self._last_pts:
            return  # timestamps must increase
        self._last_pts = pts
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        frame.pts, frame.time_base = pts, Fraction(1, RTP_CLOCK_HZ)
        for packet in self._codec.encode(frame):
            self._send(bytes(packet), packet.pts if packet.pts is not None else pts)
        self.frames_sent += 1

    def _send(self, annexb: bytes, pts: int) -> None:
        for datagram in self._rtp.packets(split_nal_units(annexb), pts):
            try:
                self._sock.sendto(datagram, self._address)
            except OSError as exc:  # nobody listening yet (ICMP), or a full buffer
                log.debug("video: %s", exc)

    def close(self) -> None:
        self._sock.close()


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
        self._seq = 0
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
        self._stop_flag = threading.Event()  # its own: an old thread still ending keeps its
        self._thread = threading.Thread(target=self._decode, args=(self._stop_flag,),
                                        name=f"video-{self.info.name}", daemon=True)
        self._thread.start()

    def _stop(self) -> None:
        self._stop_flag.set()

    def _decode(self, stop: threading.Event) -> None:
        rtp = _rtp_address(self.url, listen=True)
        while not stop.is_set():
            try:
                if rtp is not None:
                    self._decode_rtp(rtp, stop)
                else:
                    self._decode_ffmpeg(stop)
            except Exception as exc:  # stream not there yet, or broken: retry
                self.error = exc
                log.debug("video %s: %s", self.url, exc)
                stop.wait(0.2)

    def _deliver(self, image: np.ndarray, sent_s: float | None, arrived_s: float) -> None:
        stamp = arrived_s
        if self._to_local is not None and sent_s is not None:
            stamp = min(self._to_local(sent_s), arrived_s)
        image.flags.writeable = False
        frame = Frame(camera=self.info, time_s=stamp, seq=self._seq, image=image)
        self._seq += 1
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._broadcast.publish, frame)

    def _decode_rtp(self, address: tuple[str, int], stop: threading.Event) -> None:
        import av

        codec = av.CodecContext.create("h264", "r")
        codec.thread_type = "SLICE"  # frame threads would hold frames back
        depacketizer = RtpH264Depacketizer()
        epoch, last_ts = 0, None
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
            sock.bind(address)
            sock.settimeout(0.2)
            while not stop.is_set():
                try:
                    datagram = sock.recv(65536)
                except TimeoutError:
                    continue
                unit = depacketizer.push(datagram)
                if unit is None:
                    continue
                timestamp, access_unit = unit
                if last_ts is not None and timestamp < last_ts and last_ts - timestamp > \
                        _TS_WRAP // 2:
                    epoch += 1  # the 32-bit RTP clock wrapped (every 13.3 h)
                last_ts = timestamp
                sent_s = (timestamp + epoch * _TS_WRAP) / RTP_CLOCK_HZ
                try:
                    frames = codec.decode(av.Packet(access_unit))
                except av.error.InvalidDataError:
                    continue  # e.g. P-frames before the first keyframe
                stale = _readable(sock)  # a newer frame is already waiting: skip this one
                for frame in frames:
                    self.decoded += 1
                    if not stale:
                        self._deliver(frame.to_ndarray(format="bgr24"), sent_s, self._clock())

    def _decode_ffmpeg(self, stop: threading.Event) -> None:
        import av

        options = {"flags": "low_delay", "probesize": "65536", "analyzeduration": "500000"}
        if "://" in self.url:  # a live stream: no input buffering ("nobuffer" breaks files)
            options["fflags"] = "nobuffer"
        if self.url.startswith("rtsp:"):
            options["timeout"] = str(int(self._open_timeout_s * 1e6))
        live = "://" in self.url
        with av.open(self.url, options=options) as container:
            stream = container.streams.video[0]
            stream.thread_type = "SLICE"
            started: tuple[float, float] | None = None  # (local, stream) time of the first frame
            for frame in container.decode(stream):
                if stop.is_set():
                    return
                pts_s = float(frame.pts * frame.time_base) if frame.pts is not None else None
                if not live and pts_s is not None:  # a file plays at its own pace
                    if started is None:
                        started = (self._clock(), pts_s)
                    stop.wait(max(0.0, started[0] + pts_s - started[1] - self._clock()))
                self.decoded += 1
                # these timestamps are not capture times on the vehicle's clock: stamp arrival
                self._deliver(frame.to_ndarray(format="bgr24"), None, self._clock())
            if os.path.isfile(self.url):
                stop.wait()  # a file ends: no more frames


def _readable(sock: socket.socket) -> bool:
    return bool(select.select([sock], [], [], 0.0)[0])
