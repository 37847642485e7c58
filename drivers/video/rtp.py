"""RTP H.264 (RFC 6184): the streams' constants, NAL units into packets and back."""


import random
import struct
from collections.abc import Iterator

RTP_CLOCK_HZ = 90_000
RTP_PAYLOAD_TYPE = 96
TS_WRAP = 1 << 32
TS_WRAP_S = TS_WRAP / RTP_CLOCK_HZ  # 13.3 h
MAX_PAYLOAD_B = 1400

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

NTP_UNIX_OFFSET_S = 2_208_988_800  # from 1900-01-01 (NTP's epoch) to 1970-01-01



def ts_diff(a: int, b: int) -> int:
    """a − b for 32-bit RTP timestamps, through a wrap (valid within ±6.6 h)."""
    return (a - b + (1 << 31)) % TS_WRAP - (1 << 31)


def rtp_ssrc(datagram: bytes) -> int | None:
    if len(datagram) < 12 or datagram[0] >> 6 != 2:
        return None
    return struct.unpack_from("!I", datagram, 8)[0]


def is_rtcp(datagram: bytes) -> bool:
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
                 max_payload_b: int = MAX_PAYLOAD_B) -> None:
        self.ssrc = random.getrandbits(32) if ssrc is None else ssrc
        self.payload_type = payload_type
        self.max_payload_b = max_payload_b
        self._seq = random.getrandbits(16)

    def _header(self, timestamp: int, marker: bool) -> bytes:
        header = struct.pack("!BBHII", 0x80, (0x80 if marker else 0) | self.payload_type,
                             self._seq, timestamp % TS_WRAP, self.ssrc)
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
