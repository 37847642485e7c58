"""A camera received over the network: :class:`VideoSource` decodes on a thread of its own
and hands the newest frame to the event loop, stamped by its :class:`CaptureClock`."""


import asyncio
import contextlib
import logging
import math
import os
import select
import socket
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import numpy as np

from drivers.base import CameraInfo, Frame
from drivers.slots import Broadcast
from drivers.threads import lower_this_thread
from drivers.video.rtcp import Goodbye
from drivers.video.rtp import RtpH264Depacketizer, is_rtcp, rtp_ssrc
from drivers.video.timing import CaptureClock
from drivers.video.urls import address_text, parse_source, rtp_address, url_source

log = logging.getLogger(__name__)

@dataclass
class VideoStats:
    """What a :class:`VideoSource` has received (written by its decoding thread)."""

    #: Frames decoded.
    decoded: int = 0
    #: Frames handed over (not those already stale when decoded).
    frames: int = 0
    #: RTP datagrams taken from the sender it receives from.
    datagrams: int = 0
    #: RTCP datagrams taken.
    rtcp: int = 0
    #: RTP packets that never came (sequence gaps).
    lost_packets: int = 0
    #: Datagrams from other senders, ignored.
    ignored: int = 0
    #: The newest sender ignored (HOST:PORT).
    ignored_from: str | None = None


class VideoSource:
    """Frames decoded from ``url`` for a camera described by ``info``.

    ``udp://[HOST]:PORT[?source=ADDRESS[:PORT]]`` (or ``rtp://``) is RTP H.264 on PORT and RTCP
    on PORT + 1, listening on HOST: none (or ``@``) is 127.0.0.1, ``0.0.0.0`` every interface.
    Datagrams are taken from ``source`` only (the argument, else the URL's; with a port, RTP
    from that port only, RTCP from any port of that host), or else from the first sender heard.
    The sender taken (its address and SSRC) keeps the stream until it says goodbye (RTCP BYE)
    or falls silent for ``relock_after_s``; then the next sender heard takes it (a camera that
    restarts comes back from another port, with another SSRC).

    Frames are stamped by :attr:`timing`, a :class:`CaptureClock` (``to_local``, ``latency_s``
    and ``max_age_s`` are its parameters), on the local clock ``clock``; FFmpeg's streams with
    their arrival time less ``latency_s``. :attr:`stats` counts.
    """

    def __init__(self, url: str, info: CameraInfo, *,
                 to_local: Callable[[float], float] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 open_timeout_s: float = 5.0, latency_s: float = 0.0, max_age_s: float = 2.0,
                 source: str | None = None, relock_after_s: float = 2.0) -> None:
        self.url = url
        self.info = info
        self._rtp = rtp_address(url)
        if self._rtp is not None and source is None:
            source = url_source(url)
        if source is not None and self._rtp is None:
            raise ValueError(f"video {url!r}: a source can be given for udp:// or rtp:// only")
        #: The only sender taken, (host, port or None), if configured.
        self.source = parse_source(source) if source is not None else None
        self._clock = clock
        self._open_timeout_s = open_timeout_s
        self._relock_after_s = relock_after_s
        #: How frames are stamped, and how the newest one was.
        self.timing = CaptureClock(to_local=to_local, latency_s=latency_s, max_age_s=max_age_s,
                                   name=f"video {info.name} ({url})")
        self.stats = VideoStats()
        #: The address RTP is received on (None while not listening).
        self.local_address: tuple[str, int] | None = None
        #: The sender (host, port) frames are taken from (None before the first).
        self.sender: tuple[str, int] | None = None
        self._ssrc: int | None = None
        self._heard_s = -math.inf
        self._depacketizer = RtpH264Depacketizer()
        self._warned_ignored = False
        self._warned_rtcp = False
        self._errors_seen: set[str] = set()
        self._decoding = threading.Lock()  # one decoding thread at a time
        self._broadcast: Broadcast[Frame] = Broadcast(on_first=self._start, on_last=self._stop)
        self._thread: threading.Thread | None = None
        self._stop_flag = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._seq = 0
        self.error: Exception | None = None

    @property
    def decoded(self) -> int:
        return self.stats.decoded

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
        lower_this_thread()  # decoding sheds frames when the CPU is short; telemetry must not
        while not stop.is_set():
            if not self._decoding.acquire(timeout=0.2):
                continue  # the previous thread has not let go of the sockets yet
            failure = None
            try:
                if self._rtp is not None:
                    self._decode_rtp(self._rtp, stop)
                else:
                    self._decode_ffmpeg(stop)
            except Exception as exc:  # stream not there yet, or broken: retry
                failure = exc
            finally:
                self._decoding.release()
            if failure is not None:
                self.error = failure
                self._report(failure)
                stop.wait(0.2)

    def _report(self, exc: Exception) -> None:
        """The first time a failure is seen: a warning; its repeats (retries): debug."""
        text = f"{type(exc).__name__}: {exc}"
        if text in self._errors_seen or len(self._errors_seen) > 32:
            log.debug("%s: %s", self.timing.name, text)
        else:
            self._errors_seen.add(text)
            log.warning("%s: %s (retrying)", self.timing.name, text)

    def _deliver(self, image: np.ndarray, time_s: float) -> None:
        image.flags.writeable = False
        frame = Frame(camera=self.info, time_s=time_s, seq=self._seq, image=image)
        self._seq += 1
        self.stats.frames += 1
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._broadcast.publish, frame)

    def _decode_rtp(self, address: tuple[str, int], stop: threading.Event) -> None:
        import av

        source: tuple[str, int | None] | None = None
        if self.source is not None:  # a name, resolved here: it may block
            source = (socket.gethostbyname(self.source[0]), self.source[1])
        codec = av.CodecContext.create("h264", "r")
        codec.thread_type = "SLICE"  # frame threads would hold frames back
        self._depacketizer.reset()
        with contextlib.ExitStack() as stack:
            rtp = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            rtp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
            rtp.bind(address)
            rtcp = self._open_rtcp(address)
            sockets = [rtp]
            if rtcp is not None:
                stack.enter_context(rtcp)
                sockets.insert(0, rtcp)
            self.local_address = rtp.getsockname()
            stack.callback(setattr, self, "local_address", None)
            while not stop.is_set():
                readable = select.select(sockets, [], [], 0.2)[0]
                if rtcp is not None and rtcp in readable:  # first: it may say how to stamp
                    self._on_rtcp(*rtcp.recvfrom(65536), source)
                if rtp in readable:
                    self._on_rtp(rtp, codec, source)

    def _open_rtcp(self, address: tuple[str, int]) -> socket.socket | None:
        host, port = address
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port + 1))
        except (OSError, OverflowError) as exc:
            sock.close()
            if not self._warned_rtcp:
                self._warned_rtcp = True
                log.warning("%s: cannot receive RTCP on %s:%d (%s): without sender reports, "
                            "frames are stamped with their arrival time − %.3f s",
                            self.timing.name, host, port + 1, exc, self.timing.latency_s)
            return None
        return sock

    def _on_rtp(self, sock: socket.socket, codec,
                source: tuple[str, int | None] | None) -> None:
        import av

        datagram, sender = sock.recvfrom(65536)
        if is_rtcp(datagram):
            self._on_rtcp(datagram, sender, source)
            return
        ssrc = rtp_ssrc(datagram)
        if ssrc is None or not self._take(sender, ssrc, source):
            return
        self.stats.datagrams += 1
        unit = self._depacketizer.push(datagram)
        self.stats.lost_packets = self._depacketizer.lost
        if unit is None:
            return
        timestamp, access_unit = unit
        try:
            frames = codec.decode(av.Packet(access_unit))
        except av.error.InvalidDataError:
            return  # e.g. P-frames before the first keyframe
        stale = self._newer_waiting(sock)  # a newer frame is already waiting: skip this one
        for frame in frames:
            self.stats.decoded += 1
            if stale:
                continue
            image = frame.to_ndarray(format="bgr24")
            arrival_wall_s, arrival_s = time.time(), self._clock()
            stamp = self.timing.stamp(arrival_s, timestamp, ssrc=ssrc,
                                      arrival_wall_s=arrival_wall_s)
            self._deliver(image, stamp.time_s)

    def _take(self, sender: tuple[str, int], ssrc: int,
              source: tuple[str, int | None] | None) -> bool:
        """Whether an RTP datagram from ``sender`` with ``ssrc`` is the stream's."""
        if source is not None and (sender[0] != source[0]
                                   or source[1] not in (None, sender[1])):
            self._ignore(sender, f"not the configured source {address_text(source)}")
            return False
        now_s = time.monotonic()
        if self.sender is not None and (sender, ssrc) != (self.sender, self._ssrc):
            silent_s = now_s - self._heard_s
            if silent_s < self._relock_after_s:
                self._ignore(sender, f"receiving from {address_text(self.sender)}")
                return False
            log.info("%s: %s silent for %.1f s", self.timing.name,
                     address_text(self.sender), silent_s)
            self.sender = None
        if self.sender is None:
            self.sender, self._ssrc = sender, ssrc
            self._depacketizer.reset()
            self.timing.sender = address_text(sender)
            log.info("%s: receiving from %s (SSRC %#010x)", self.timing.name,
                     address_text(sender), ssrc)
        self._heard_s = now_s
        return True

    def _on_rtcp(self, datagram: bytes, sender: tuple[str, int],
                 source: tuple[str, int | None] | None) -> None:
        if source is not None and sender[0] != source[0]:
            self._ignore(sender, f"not the configured source {address_text(source)}")
            return
        if self.sender is not None and sender[0] != self.sender[0]:
            self._ignore(sender, f"receiving from {address_text(self.sender)}")
            return
        self.stats.rtcp += 1
        # before the first RTP datagram, reports of any SSRC are kept: the one that comes
        # with the stream taken is used
        for packet in self.timing.feed_rtcp(datagram):
            if isinstance(packet, Goodbye) and self.sender is not None \
                    and self._ssrc in packet.ssrcs:
                log.info("%s: %s has stopped sending (RTCP BYE)", self.timing.name,
                         address_text(self.sender))
                self.sender = None

    def _ignore(self, sender: tuple[str, int], why: str) -> None:
        self.stats.ignored += 1
        self.stats.ignored_from = address_text(sender)
        if not self._warned_ignored:
            self._warned_ignored = True
            log.warning("%s: ignoring datagrams from %s (%s); further ones are only counted",
                        self.timing.name, address_text(sender), why)

    def _newer_waiting(self, sock: socket.socket) -> bool:
        """Whether a datagram of the sender taken is waiting (those of others that are in
        the way are taken off and ignored: they must not make every frame look stale)."""
        while readable(sock):
            try:
                _, sender = sock.recvfrom(16, socket.MSG_PEEK)
            except OSError:  # a truncated peek is an error on some systems
                return True
            if self.sender is None or sender == self.sender:
                return True
            sock.recvfrom(65536)
            self._ignore(sender, f"receiving from {address_text(self.sender)}")
        return False

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
                self.stats.decoded += 1
                # FFmpeg's timestamps are not capture times on any clock we know: arrival
                image = frame.to_ndarray(format="bgr24")
                self._deliver(image, self.timing.stamp(self._clock()).time_s)
            if os.path.isfile(self.url):
                stop.wait()  # a file ends: no more frames


def readable(sock: socket.socket) -> bool:
    return bool(select.select([sock], [], [], 0.0)[0])
