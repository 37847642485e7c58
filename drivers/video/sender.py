"""The simulated camera as a network camera: :class:`VideoSender` encodes frames to H.264
and sends them as RTP, with RTCP sender reports and a source description."""


import logging
import math
import socket
import time
from collections.abc import Callable
from fractions import Fraction

import numpy as np

from drivers.video.rtcp import (
    SenderReport,
    SourceDescription,
    encode_goodbye,
    encode_sender_report,
    encode_source_description,
)
from drivers.video.rtp import (
    RTCP_INTERVAL_S,
    RTP_CLOCK_HZ,
    SIM_CNAME,
    SIM_TOOL,
    TS_WRAP,
    RtpH264Packetizer,
    split_nal_units,
)
from drivers.video.urls import rtp_address

log = logging.getLogger(__name__)

class VideoSender:
    """Encode BGR frames to H.264 and send them as RTP to ``url`` (``udp://HOST:PORT``, no host:
    127.0.0.1), and RTCP to PORT + 1. Blocking calls: run it on a thread of its own.

    A frame's RTP timestamp is its ``capture_time_s`` (see :meth:`send`) at 90 kHz, plus
    ``rtp_offset_ticks``. The simulator passes capture times on the vehicle's boot clock and
    says so in its source description (``cname`` :data:`SIM_CNAME`), so that a receiver that
    knows the vehicle's clock maps them exactly and no other receiver mistakes them for
    anything else. About once a second (``rtcp_interval_s``) a sender report ties a frame's RTP
    timestamp to the wall clock (``time.time()``) at its capture: ``capture_clock`` is the clock
    capture times are on, read at sending to tell how long ago the frame was captured; without
    it the frame is taken to have been captured as it is sent.

    ``rtcp=False``, and ``rtp_offset_ticks`` with another ``cname``, make it look like a
    third-party camera (tests).
    """

    def __init__(self, url: str, width_px: int, height_px: int, rate_hz: float, *,
                 bitrate_bps: int = 2_000_000, keyframe_interval: int = 30,
                 rtcp: bool = True, cname: str = SIM_CNAME, rtp_offset_ticks: int = 0,
                 capture_clock: Callable[[], float] | None = None,
                 rtcp_interval_s: float = RTCP_INTERVAL_S,
                 drop: Callable[[], bool] | None = None) -> None:
        import av

        address = rtp_address(url)
        if address is None:
            raise ValueError(f"video output {url!r}: expected udp://HOST:PORT (RTP H.264)")
        if rtp_offset_ticks % TS_WRAP and cname == SIM_CNAME:
            raise ValueError(f"video output {url!r}: RTP timestamps offset from the capture "
                             f"clock are not the simulator's convention; give another cname")
        if rtcp and address[1] >= 65535:
            raise ValueError(f"video output {url!r}: RTCP needs the port above {address[1]}")
        self._address = address
        self._rtcp_address = (address[0], address[1] + 1) if rtcp else None
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
        self._cname = cname
        self._rtp_offset_ticks = rtp_offset_ticks
        self._capture_clock = capture_clock
        self._rtcp_interval_s = rtcp_interval_s
        self._next_report_s = -math.inf
        self._last_pts = -1
        self.frames_sent = 0
        self.packets_sent = 0
        self.octets_sent = 0
        self.reports_sent = 0
        #: asked for each RTP packet: True loses it (the simulator's link_loss fault)
        self._drop = drop
        self.packets_dropped = 0

    @property
    def ssrc(self) -> int:
        return self._rtp.ssrc

    def send(self, image: np.ndarray, capture_time_s: float) -> None:
        """Send a frame captured at ``capture_time_s`` (on the clock RTP timestamps follow)."""
        import av

        pts = round(capture_time_s * RTP_CLOCK_HZ)
        if pts <= self._last_pts:
            return  # timestamps must increase
        self._last_pts = pts
        # before the frame itself, so that a receiver knows how to stamp it when it arrives
        if self._rtcp_address is not None and time.monotonic() >= self._next_report_s:
            self._send_report(pts)
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        frame.pts, frame.time_base = pts, Fraction(1, RTP_CLOCK_HZ)
        for packet in self._codec.encode(frame):
            self._send(bytes(packet), packet.pts if packet.pts is not None else pts)
        self.frames_sent += 1

    def _send_report(self, pts: int) -> None:
        wall_s = time.time()
        if self._capture_clock is not None:
            wall_s -= self._capture_clock() - pts / RTP_CLOCK_HZ
        report = SenderReport(self.ssrc, wall_s, (pts + self._rtp_offset_ticks) % TS_WRAP,
                              self.packets_sent, self.octets_sent)
        tool = SIM_TOOL if self._cname == SIM_CNAME else None
        self._sendto(encode_sender_report(report)
                     + encode_source_description(SourceDescription(self.ssrc, self._cname, tool)),
                     self._rtcp_address)
        self._next_report_s = time.monotonic() + self._rtcp_interval_s
        self.reports_sent += 1

    def _send(self, annexb: bytes, pts: int) -> None:
        timestamp = (pts + self._rtp_offset_ticks) % TS_WRAP
        for datagram in self._rtp.packets(split_nal_units(annexb), timestamp):
            if self._drop is not None and self._drop():
                self.packets_dropped += 1
                continue
            self._sendto(datagram, self._address)
            self.packets_sent += 1
            self.octets_sent += len(datagram) - 12

    def _sendto(self, datagram: bytes, address: tuple[str, int]) -> None:
        try:
            self._sock.sendto(datagram, address)
        except OSError as exc:  # nobody listening yet (ICMP), or a full buffer
            log.debug("video: %s", exc)

    def close(self) -> None:
        if self._sock.fileno() < 0:
            return
        if self._rtcp_address is not None and self.frames_sent:
            self._sendto(encode_goodbye(self.ssrc), self._rtcp_address)
        self._sock.close()
