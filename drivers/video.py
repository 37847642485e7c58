"""Compressed video in and out: H.264 over RTP on UDP (PX4 / QGroundControl's convention for
port 5600), or anything FFmpeg opens, through PyAV.

A detection is only as good as the time its frame is said to have been taken: the estimator
places it where the vehicle was at that instant, from a pose history a couple of seconds long.
An RTP timestamp alone does not say when: RFC 3550 has it start at a random value and count on
the sender's own clock, and only RTCP sender reports tie it to the sender's wall clock. So a
frame's capture time comes from the best source the stream offers (:class:`CaptureClock`):

1. our simulator's convention, and only for a stream that says it follows it (RTCP SDES CNAME
   :data:`SIM_CNAME`): the RTP timestamp is the capture time on the vehicle's boot clock, which
   the MAVLink driver maps onto ours with TIMESYNC;
2. RTCP sender reports: the sender's wall clock at an RTP timestamp, which is as good as the
   synchronisation of the two machines' wall clocks (NTP, PTP, GPS);
3. otherwise the arrival time less the camera's latency, measured once and configured.

A camera's clock can be wrong. Capture times after the frame's arrival, or older than the pose
history, would make every detection useless without a word; such a stream gets one loud
warning and arrival times from then on. Frames are never dropped for their stamps.

A companion computer shares its network (a radio's Ethernet bridge, a second camera, a laptop on
the same Wi-Fi), so the receiver listens on 127.0.0.1 unless the URL names an interface, and
takes datagrams from one sender only: the configured one (``?source=HOST[:PORT]``), or else the
first it hears. Others are counted and named once, not mixed into the picture.

* :class:`VideoSender` (the simulator's camera) encodes frames (libx264, ``ultrafast`` /
  ``zerolatency``, SPS/PPS with every keyframe), sends them as RTP (RFC 6184: single NAL units
  and FU-A fragments, payload type 96, the marker bit on each frame's last packet), and RTCP
  sender reports with a source description on the next port up.
* :class:`VideoSource` receives and decodes on a thread of its own and hands the newest frame
  to the event loop, stamped by its :class:`CaptureClock`; frames that are already stale when
  decoded are not converted or handed over. ``udp://`` or ``rtp://`` is RTP H.264 as above;
  any other URL (``rtsp://``, a file, ``/dev/video0``) goes to FFmpeg and is stamped with its
  arrival time less the latency. It decodes only while someone subscribes.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import math
import os
import random
import select
import socket
import struct
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple
from urllib.parse import parse_qs, urlsplit

import numpy as np

from drivers.base import CameraInfo, Frame
from drivers.slots import Broadcast
from drivers.threads import lower_this_thread

log = logging.getLogger(__name__)

RTP_CLOCK_HZ = 90_000
RTP_PAYLOAD_TYPE = 96
_TS_WRAP = 1 << 32
_TS_WRAP_S = _TS_WRAP / RTP_CLOCK_HZ  # 13.3 h
_MAX_PAYLOAD_B = 1400

#: The RTCP SDES CNAME with which a stream says "my RTP timestamps are capture times on the
#: vehicle's boot clock, at 90 kHz" (the simulator's convention). No other stream is read that
#: way: a camera's RTP clock starts wherever it likes.
SIM_CNAME = "autopilot-sim"
#: The SDES TOOL item sent with :data:`SIM_CNAME`, for whoever reads a packet capture.
SIM_TOOL = "autopilot sim: RTP timestamp = capture time on the vehicle boot clock (90 kHz)"

#: The address a receiver listens on, and a sender sends to, when the URL names no host.
DEFAULT_HOST = "127.0.0.1"
#: Time between a sender's RTCP reports: RFC 3550's 5 % of the session bandwidth would allow
#: hundreds a second at 2 Mbit/s; one a second is as fresh as a clock mapping needs.
RTCP_INTERVAL_S = 1.0
#: How far a capture time may lie after the frame's arrival and still be believed (then taken
#: as the arrival time): clock mappings (TIMESYNC, NTP) are good to a few milliseconds.
FUTURE_TOLERANCE_S = 0.005
#: A stream whose stamps were found wrong is believed again only once its RTP → local mapping
#: moves by more than this (a clock stepped, a vehicle rebooted), not for jitter or drift.
MAPPING_STEP_S = 0.05

_NTP_UNIX_OFFSET_S = 2_208_988_800  # from 1900-01-01 (NTP's epoch) to 1970-01-01
_RTCP_SR, _RTCP_SDES, _RTCP_BYE = 200, 202, 203
_SDES_END, _SDES_CNAME, _SDES_TOOL = 0, 1, 6


def _rtp_address(url: str) -> tuple[str, int] | None:
    """(host, port) of an RTP URL (``udp://`` or ``rtp://``), None for other URLs. No host (or
    ``@`` alone, once "every interface" in FFmpeg's spelling) is 127.0.0.1: listening on other
    interfaces, or sending to another machine, is asked for by name."""
    parts = urlsplit(url)
    if parts.scheme not in ("udp", "rtp") or parts.port is None:
        return None
    host = (parts.hostname or "").lstrip("@")
    return host or DEFAULT_HOST, parts.port


#: what FFmpeg is asked to open besides RTP (and files and devices, given as paths)
_FFMPEG_SCHEMES = ("rtsp", "rtsps", "rtmp", "rtmps", "http", "https", "srt", "tcp", "file")


def check_video_url(url: str) -> None:
    """Refuse a video URL that cannot work, before anything opens it (:class:`ValueError`,
    saying what is accepted): RTP needs a port; other streams need a scheme FFmpeg reads;
    anything else must be an existing file or device."""
    parts = urlsplit(url)
    if parts.scheme in ("udp", "rtp"):
        try:
            port = parts.port
        except ValueError:
            port = None
        if port is None:
            raise ValueError(f"{url!r}: RTP video needs a port, e.g. udp://127.0.0.1:5600")
        source = _url_source(url)
        if source is not None:
            _parse_source(source)
        return
    if parts.scheme in _FFMPEG_SCHEMES:
        return
    if "://" in url or not os.path.exists(url):
        raise ValueError(f"{url!r}: expected udp://HOST:PORT (RTP H.264), "
                         f"{', '.join(s + '://' for s in _FFMPEG_SCHEMES[:5])}..., "
                         "or an existing file or device (/dev/video0)")


def _url_source(url: str) -> str | None:
    """The ``source`` option of an RTP URL's query (None without one)."""
    options = parse_qs(urlsplit(url).query, keep_blank_values=True)
    unknown = sorted(set(options) - {"source"})
    if unknown:
        log.warning("video %s: ignoring unknown URL option(s) %s (only 'source' is known)",
                    url, ", ".join(unknown))
    values = options.get("source")
    return values[-1] if values else None


def _parse_source(text: str) -> tuple[str, int | None]:
    """``HOST`` or ``HOST:PORT`` (IPv4 address or name) as (host, port or None)."""
    host, colon, port = text.strip().partition(":")
    if not host or (colon and not (port.isdigit() and 0 < int(port) < 65536)):
        raise ValueError(f"video source {text!r}: expected HOST or HOST:PORT")
    return host, int(port) if port else None


def _address_text(address: tuple[str, int | None]) -> str:
    return address[0] if address[1] is None else f"{address[0]}:{address[1]}"


def _ts_diff(a: int, b: int) -> int:
    """a − b for 32-bit RTP timestamps, through a wrap (valid within ±6.6 h)."""
    return (a - b + (1 << 31)) % _TS_WRAP - (1 << 31)


def _rtp_ssrc(datagram: bytes) -> int | None:
    if len(datagram) < 12 or datagram[0] >> 6 != 2:
        return None
    return struct.unpack_from("!I", datagram, 8)[0]


def _is_rtcp(datagram: bytes) -> bool:
    """RTCP multiplexed onto the RTP port (RFC 5761: packet types 192–223 where RTP has its
    marker bit and payload type)."""
    return len(datagram) >= 8 and datagram[0] >> 6 == 2 and 192 <= datagram[1] <= 223


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
        self.lost = 0
        self.reset()

    def reset(self) -> None:
        """Forget the frame in progress and the sequence (a new stream begins); ``lost`` is
        kept."""
        self._units: list[bytes] = []
        self._fu: bytearray | None = None
        self._timestamp: int | None = None
        self._next_seq: int | None = None
        self._broken = False

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


# --------------------------------------------------------------------------------------------
# RTCP (RFC 3550 §6): sender reports, source descriptions, goodbyes
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SenderReport:
    """An RTCP SR: the sender's wall clock (Unix time; NTP format on the wire) at the instant
    ``rtp_timestamp`` stands for, and what it has sent so far."""

    ssrc: int
    wall_time_s: float
    rtp_timestamp: int
    packet_count: int = 0
    octet_count: int = 0


@dataclass(frozen=True, slots=True)
class SourceDescription:
    """One chunk of an RTCP SDES: who the source with ``ssrc`` is."""

    ssrc: int
    cname: str | None = None
    tool: str | None = None


@dataclass(frozen=True, slots=True)
class Goodbye:
    """An RTCP BYE: these sources have stopped sending."""

    ssrcs: tuple[int, ...]


RtcpPacket = SenderReport | SourceDescription | Goodbye


def _rtcp_packet(packet_type: int, count: int, body: bytes) -> bytes:
    return struct.pack("!BBH", 0x80 | count, packet_type, len(body) // 4) + body


def _ntp_from_unix(wall_time_s: float) -> tuple[int, int]:
    ntp_s = wall_time_s + _NTP_UNIX_OFFSET_S
    seconds = math.floor(ntp_s)
    fraction = min(int((ntp_s - seconds) * (1 << 32)), (1 << 32) - 1)
    return seconds % _TS_WRAP, fraction


def _unix_from_ntp(msw: int, lsw: int) -> float:
    seconds = msw + lsw / (1 << 32)
    if msw < 1 << 31:  # NTP era 1, from 2036-02-07 (RFC 4330 §3)
        seconds += 1 << 32
    return seconds - _NTP_UNIX_OFFSET_S


def encode_sender_report(report: SenderReport) -> bytes:
    """An SR packet without reception report blocks (a sender that receives nothing)."""
    msw, lsw = _ntp_from_unix(report.wall_time_s)
    body = struct.pack("!6I", report.ssrc, msw, lsw, report.rtp_timestamp % _TS_WRAP,
                       report.packet_count % _TS_WRAP, report.octet_count % _TS_WRAP)
    return _rtcp_packet(_RTCP_SR, 0, body)


def encode_source_description(description: SourceDescription) -> bytes:
    """An SDES packet with one chunk (CNAME and TOOL items, each at most 255 bytes)."""
    chunk = bytearray(struct.pack("!I", description.ssrc))
    for kind, text in ((_SDES_CNAME, description.cname), (_SDES_TOOL, description.tool)):
        if text is not None:
            data = text.encode()[:255]
            chunk += bytes((kind, len(data))) + data
    chunk += bytes(4 - len(chunk) % 4)  # the end item, then padding to a 32-bit boundary
    return _rtcp_packet(_RTCP_SDES, 1, bytes(chunk))


def encode_goodbye(*ssrcs: int) -> bytes:
    return _rtcp_packet(_RTCP_BYE, len(ssrcs), b"".join(struct.pack("!I", s) for s in ssrcs))


def parse_rtcp(datagram: bytes) -> list[RtcpPacket]:
    """The SR, SDES and BYE packets of an RTCP compound packet; other types are skipped, and
    parsing stops at the first malformed packet (what came before it is kept)."""
    packets: list[RtcpPacket] = []
    offset = 0
    while offset + 4 <= len(datagram):
        first, packet_type, length = struct.unpack_from("!BBH", datagram, offset)
        end = offset + 4 * (length + 1)
        if first >> 6 != 2 or end > len(datagram):
            break
        count = first & 0x1F
        body = datagram[offset + 4:end]
        if first & 0x20 and body:  # padding, its length in the last octet
            body = body[:max(0, len(body) - body[-1])]
        if packet_type == _RTCP_SR and len(body) >= 24:
            ssrc, msw, lsw, rtp, sent, octets = struct.unpack_from("!6I", body)
            packets.append(SenderReport(ssrc, _unix_from_ntp(msw, lsw), rtp, sent, octets))
        elif packet_type == _RTCP_SDES:
            packets.extend(_parse_sdes(body, count))
        elif packet_type == _RTCP_BYE and len(body) >= 4 * count:
            packets.append(Goodbye(struct.unpack_from(f"!{count}I", body)))
        offset = end
    return packets


def _parse_sdes(body: bytes, count: int) -> list[SourceDescription]:
    chunks = []
    i = 0
    for _ in range(count):
        if i + 4 > len(body):
            break
        ssrc = struct.unpack_from("!I", body, i)[0]
        i += 4
        items: dict[int, str] = {}
        while i + 2 <= len(body) and body[i] != _SDES_END:
            kind, size = body[i], body[i + 1]
            items[kind] = body[i + 2:i + 2 + size].decode(errors="replace")
            i += 2 + size
        i = (i // 4 + 1) * 4  # past the end item and the padding to the next chunk
        chunks.append(SourceDescription(ssrc, items.get(_SDES_CNAME), items.get(_SDES_TOOL)))
    return chunks


# --------------------------------------------------------------------------------------------
# Capture times
# --------------------------------------------------------------------------------------------


class TimeSource(enum.StrEnum):
    """Where a frame's capture time came from."""

    #: The RTP timestamp as vehicle boot time (a stream that says it is our simulator's).
    VEHICLE_CLOCK = "vehicle-clock"
    #: The sender's wall clock, from RTCP sender reports.
    RTCP = "rtcp"
    #: The arrival time less the configured camera latency.
    ARRIVAL = "arrival"


_DESCRIPTION = {
    TimeSource.VEHICLE_CLOCK: ("capture times from the vehicle's boot clock",
                               "is the vehicle clock mapping (TIMESYNC) right?"),
    TimeSource.RTCP: ("capture times from RTCP sender reports (the sender's wall clock)",
                      "is the camera's wall clock synchronised with ours (NTP, PTP)?"),
}


class Stamp(NamedTuple):
    time_s: float
    source: TimeSource


class CaptureClock:
    """Capture times of the frames of one RTP stream on the local clock: from the vehicle's
    boot clock for a stream that says it is our simulator's, else from RTCP sender reports,
    else the arrival time less ``latency_s``. Synchronous and not thread-safe: one decoding
    thread feeds it RTCP datagrams (:meth:`feed_rtcp`) and asks it for each frame's time
    (:meth:`stamp`).

    ``to_local`` maps vehicle boot time (seconds) onto the local clock, as a MAVLink driver's
    ``vehicle_time_to_local`` does; while it returns +inf or NaN (not known yet) the next
    source down is used.

    ``latency_s`` is the camera's latency, from the instant of capture to a decoded frame here,
    for streams whose own stamps are missing or wrong. Measure it once per camera and link:
    point the camera at a screen showing this computer's clock in milliseconds, and compare the
    time shown in frames with their arrival stamps (``latency_s`` 0, a stream without RTCP);
    the mean difference, less the screen's own lag (about one refresh), is the latency. For the
    simulator it is :attr:`offset_s` of a stream that is stamped from the vehicle clock. With 0,
    detections are placed where the vehicle was one latency after the frame was taken.

    ``max_age_s`` is the oldest a capture time may be at arrival: the pose history's length,
    beyond which a frame could not be placed anyway.

    Capture times after their arrival (beyond :data:`FUTURE_TOLERANCE_S`), or older than
    ``max_age_s``, are wrong, whatever made them so: one warning names the stream and the
    offset, and its frames are stamped with their arrival time less ``latency_s`` until its
    mapping changes (by more than :data:`MAPPING_STEP_S`) or a new stream (SSRC) begins. A
    sender clock that is behind ours by less than ``max_age_s`` cannot be told from latency.
    """

    def __init__(self, *, to_local: Callable[[float], float] | None = None,
                 latency_s: float = 0.0, max_age_s: float = 2.0, name: str = "video") -> None:
        if not 0.0 <= latency_s < max_age_s:
            raise ValueError(f"{name}: latency_s must be at least 0 and less than max_age_s "
                             f"({max_age_s:g} s), got {latency_s:g}")
        self.name = name
        self.to_local = to_local
        self.latency_s = latency_s
        self.max_age_s = max_age_s
        #: Who sends the stream, for messages (the receiver fills it in).
        self.sender: str | None = None
        #: The SSRC of the stream being stamped (None before its first frame).
        self.ssrc: int | None = None
        #: Where the newest frame's capture time came from.
        self.mode = TimeSource.ARRIVAL
        #: Frames stamped from each source.
        self.counts: dict[TimeSource, int] = dict.fromkeys(TimeSource, 0)
        #: Arrival − capture time by the stream's own stamps, for the newest frame: the latency
        #: its stamps imply (NaN when it has none).
        self.offset_s = math.nan
        #: Why this stream's own stamps are not used (None while they are, or there are none).
        self.fallback_reason: str | None = None
        self._reports: dict[int, SenderReport] = {}
        self._cnames: dict[int, str] = {}
        self._fallback: tuple[TimeSource, float] | None = None  # (mode, its mapping)
        self._warned = False
        self._last_ts: int | None = None
        self._extended = 0

    @property
    def ours(self) -> bool:
        """The stream says its RTP timestamps are vehicle boot time (:data:`SIM_CNAME`)."""
        return self._cnames.get(self.ssrc) == SIM_CNAME

    def feed_rtcp(self, datagram: bytes) -> list[RtcpPacket]:
        """Take an RTCP compound packet (from the stream's sender); returns what it held."""
        packets = parse_rtcp(datagram)
        for packet in packets:
            if isinstance(packet, SenderReport):
                _remember(self._reports, packet.ssrc, packet)
            elif isinstance(packet, SourceDescription) and packet.cname is not None:
                _remember(self._cnames, packet.ssrc, packet.cname)
            elif isinstance(packet, Goodbye):
                for ssrc in packet.ssrcs:
                    self._reports.pop(ssrc, None)
                    self._cnames.pop(ssrc, None)
        return packets

    def stamp(self, arrival_s: float, rtp_timestamp: int | None = None, *,
              ssrc: int | None = None, arrival_wall_s: float | None = None) -> Stamp:
        """The capture time of a frame decoded at ``arrival_s`` (local clock), when the wall
        clock (``time.time()``) read ``arrival_wall_s``, with this RTP timestamp and SSRC
        (None: the stream has none, e.g. FFmpeg's); and where it came from."""
        arrival = arrival_s - self.latency_s
        if rtp_timestamp is None:
            return self._use(TimeSource.ARRIVAL, arrival, math.nan)
        if ssrc is not None and ssrc != self.ssrc:
            self._new_stream(ssrc)
        extended = self._unwrap(rtp_timestamp)
        mode, capture_s = self._own_stamp(rtp_timestamp, arrival_s, arrival_wall_s)
        if capture_s is None:
            return self._use(TimeSource.ARRIVAL, arrival, math.nan)
        offset_s = arrival_s - capture_s
        # capture time less RTP time: the same for every frame while the mapping holds (no
        # network jitter in it), so it tells a changed mapping from a late frame
        mapping_s = capture_s - extended / RTP_CLOCK_HZ
        retry = self._fallback is not None
        if retry:
            old_mode, old_mapping_s = self._fallback
            if mode is old_mode and abs(mapping_s - old_mapping_s) <= MAPPING_STEP_S:
                return self._use(TimeSource.ARRIVAL, arrival, offset_s)
        problem = self._implausible(offset_s)
        if problem is not None:
            self._fall_back(mode, mapping_s, problem)
            return self._use(TimeSource.ARRIVAL, arrival, offset_s)
        if retry:
            log.info("%s: %s: %s look right again (%.3f s before arrival); using them",
                     self.name, self._stream_text(), _DESCRIPTION[mode][0], offset_s)
            self._fallback, self.fallback_reason = None, None
        return self._use(mode, min(capture_s, arrival_s), offset_s)

    def as_dict(self) -> dict:
        """The state, for logs and summaries."""
        return {"mode": str(self.mode), "counts": {str(k): v for k, v in self.counts.items()},
                "offset_s": self.offset_s, "fallback_reason": self.fallback_reason,
                "ssrc": self.ssrc, "sender": self.sender, "ours": self.ours}

    def _own_stamp(self, rtp_timestamp: int, arrival_s: float,
                   arrival_wall_s: float | None) -> tuple[TimeSource, float | None]:
        """The capture time by the stream's own stamps, and which: (ARRIVAL, None) if none."""
        if self.ours and self.to_local is not None:
            capture_s = self._from_vehicle_clock(rtp_timestamp, arrival_s)
            if capture_s is not None:
                return TimeSource.VEHICLE_CLOCK, capture_s
        report = self._reports.get(self.ssrc)
        if report is not None and arrival_wall_s is not None:
            sender_wall_s = report.wall_time_s + \
                _ts_diff(rtp_timestamp, report.rtp_timestamp) / RTP_CLOCK_HZ
            # the wall clock's offset from the local one, as of this frame (either may be
            # stepped or restarted while we run)
            return TimeSource.RTCP, sender_wall_s - (arrival_wall_s - arrival_s)
        return TimeSource.ARRIVAL, None

    def _from_vehicle_clock(self, rtp_timestamp: int, arrival_s: float) -> float | None:
        sent_s = rtp_timestamp / RTP_CLOCK_HZ
        local_s = self.to_local(sent_s)
        if not math.isfinite(local_s):
            return None  # the vehicle's clock is not known yet
        # 32 bits of a 90 kHz clock hold 13.3 h of boot time, and a stream may begin after a
        # wrap: take the wrap count that puts the capture nearest its arrival
        wraps = round((arrival_s - local_s) / _TS_WRAP_S)
        if wraps:
            local_s = self.to_local(sent_s + wraps * _TS_WRAP_S)
        return local_s if math.isfinite(local_s) else None

    def _unwrap(self, rtp_timestamp: int) -> int:
        if self._last_ts is not None:
            self._extended += _ts_diff(rtp_timestamp, self._last_ts)
        else:
            self._extended = rtp_timestamp
        self._last_ts = rtp_timestamp
        return self._extended

    def _implausible(self, offset_s: float) -> str | None:
        if offset_s < -FUTURE_TOLERANCE_S:
            return f"{-offset_s:.3f} s after their arrival (in the future)"
        if offset_s > self.max_age_s:
            return (f"{offset_s:.3f} s before their arrival (older than the {self.max_age_s:g} s "
                    "pose history)")
        return None

    def _fall_back(self, mode: TimeSource, mapping_s: float, problem: str) -> None:
        self._fallback = (mode, mapping_s)
        what, hint = _DESCRIPTION[mode]
        self.fallback_reason = f"{mode}: {problem}"
        message = ("%s: %s: %s are %s; %s Stamping its frames with their arrival time − %.3f s "
                   "(camera latency) from now on")
        args = (self.name, self._stream_text(), what, problem, hint, self.latency_s)
        if self._warned:
            log.info(message, *args)
        else:  # once per stream: every frame would say the same
            self._warned = True
            log.warning(message, *args)

    def _stream_text(self) -> str:
        ssrc = "stream" if self.ssrc is None else f"stream SSRC {self.ssrc:#010x}"
        return ssrc if self.sender is None else f"{ssrc} from {self.sender}"

    def _new_stream(self, ssrc: int) -> None:
        self.ssrc = ssrc
        self._last_ts = None
        self._fallback, self.fallback_reason, self._warned = None, None, False
        self.offset_s = math.nan

    def _use(self, mode: TimeSource, time_s: float, offset_s: float) -> Stamp:
        self.mode = mode
        self.counts[mode] += 1
        self.offset_s = offset_s
        return Stamp(time_s, mode)


def _remember(table: dict, key, value, size: int = 8) -> None:
    """``table[key] = value``, forgetting the oldest entries beyond ``size`` (a bound on what
    a flood of made-up sources can make us keep)."""
    table.pop(key, None)
    table[key] = value
    while len(table) > size:
        del table[next(iter(table))]


# --------------------------------------------------------------------------------------------
# Sending and receiving
# --------------------------------------------------------------------------------------------


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

        address = _rtp_address(url)
        if address is None:
            raise ValueError(f"video output {url!r}: expected udp://HOST:PORT (RTP H.264)")
        if rtp_offset_ticks % _TS_WRAP and cname == SIM_CNAME:
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
        report = SenderReport(self.ssrc, wall_s, (pts + self._rtp_offset_ticks) % _TS_WRAP,
                              self.packets_sent, self.octets_sent)
        tool = SIM_TOOL if self._cname == SIM_CNAME else None
        self._sendto(encode_sender_report(report)
                     + encode_source_description(SourceDescription(self.ssrc, self._cname, tool)),
                     self._rtcp_address)
        self._next_report_s = time.monotonic() + self._rtcp_interval_s
        self.reports_sent += 1

    def _send(self, annexb: bytes, pts: int) -> None:
        timestamp = (pts + self._rtp_offset_ticks) % _TS_WRAP
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
        self._rtp = _rtp_address(url)
        if self._rtp is not None and source is None:
            source = _url_source(url)
        if source is not None and self._rtp is None:
            raise ValueError(f"video {url!r}: a source can be given for udp:// or rtp:// only")
        #: The only sender taken, (host, port or None), if configured.
        self.source = _parse_source(source) if source is not None else None
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
        if _is_rtcp(datagram):
            self._on_rtcp(datagram, sender, source)
            return
        ssrc = _rtp_ssrc(datagram)
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
            self._ignore(sender, f"not the configured source {_address_text(source)}")
            return False
        now_s = time.monotonic()
        if self.sender is not None and (sender, ssrc) != (self.sender, self._ssrc):
            silent_s = now_s - self._heard_s
            if silent_s < self._relock_after_s:
                self._ignore(sender, f"receiving from {_address_text(self.sender)}")
                return False
            log.info("%s: %s silent for %.1f s", self.timing.name,
                     _address_text(self.sender), silent_s)
            self.sender = None
        if self.sender is None:
            self.sender, self._ssrc = sender, ssrc
            self._depacketizer.reset()
            self.timing.sender = _address_text(sender)
            log.info("%s: receiving from %s (SSRC %#010x)", self.timing.name,
                     _address_text(sender), ssrc)
        self._heard_s = now_s
        return True

    def _on_rtcp(self, datagram: bytes, sender: tuple[str, int],
                 source: tuple[str, int | None] | None) -> None:
        if source is not None and sender[0] != source[0]:
            self._ignore(sender, f"not the configured source {_address_text(source)}")
            return
        if self.sender is not None and sender[0] != self.sender[0]:
            self._ignore(sender, f"receiving from {_address_text(self.sender)}")
            return
        self.stats.rtcp += 1
        # before the first RTP datagram, reports of any SSRC are kept: the one that comes
        # with the stream taken is used
        for packet in self.timing.feed_rtcp(datagram):
            if isinstance(packet, Goodbye) and self.sender is not None \
                    and self._ssrc in packet.ssrcs:
                log.info("%s: %s has stopped sending (RTCP BYE)", self.timing.name,
                         _address_text(self.sender))
                self.sender = None

    def _ignore(self, sender: tuple[str, int], why: str) -> None:
        self.stats.ignored += 1
        self.stats.ignored_from = _address_text(sender)
        if not self._warned_ignored:
            self._warned_ignored = True
            log.warning("%s: ignoring datagrams from %s (%s); further ones are only counted",
                        self.timing.name, _address_text(sender), why)

    def _newer_waiting(self, sock: socket.socket) -> bool:
        """Whether a datagram of the sender taken is waiting (those of others that are in
        the way are taken off and ignored: they must not make every frame look stale)."""
        while _readable(sock):
            try:
                _, sender = sock.recvfrom(16, socket.MSG_PEEK)
            except OSError:  # a truncated peek is an error on some systems
                return True
            if self.sender is None or sender == self.sender:
                return True
            sock.recvfrom(65536)
            self._ignore(sender, f"receiving from {_address_text(self.sender)}")
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


def _readable(sock: socket.socket) -> bool:
    return bool(select.select([sock], [], [], 0.0)[0])
