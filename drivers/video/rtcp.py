"""RTCP (RFC 3550): sender reports, source descriptions and goodbyes, encoded and parsed."""


import math
import struct
from dataclasses import dataclass

from drivers.video.rtp import NTP_UNIX_OFFSET_S, TS_WRAP

#: RTCP packet types and SDES item types (RFC 3550)
_RTCP_SR, _RTCP_SDES, _RTCP_BYE = 200, 202, 203
_SDES_END, _SDES_CNAME, _SDES_TOOL = 0, 1, 6

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


def ntp_from_unix(wall_time_s: float) -> tuple[int, int]:
    ntp_s = wall_time_s + NTP_UNIX_OFFSET_S
    seconds = math.floor(ntp_s)
    fraction = min(int((ntp_s - seconds) * (1 << 32)), (1 << 32) - 1)
    return seconds % TS_WRAP, fraction


def unix_from_ntp(msw: int, lsw: int) -> float:
    seconds = msw + lsw / (1 << 32)
    if msw < 1 << 31:  # NTP era 1, from 2036-02-07 (RFC 4330 §3)
        seconds += 1 << 32
    return seconds - NTP_UNIX_OFFSET_S


def encode_sender_report(report: SenderReport) -> bytes:
    """An SR packet without reception report blocks (a sender that receives nothing)."""
    msw, lsw = ntp_from_unix(report.wall_time_s)
    body = struct.pack("!6I", report.ssrc, msw, lsw, report.rtp_timestamp % TS_WRAP,
                       report.packet_count % TS_WRAP, report.octet_count % TS_WRAP)
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
            packets.append(SenderReport(ssrc, unix_from_ntp(msw, lsw), rtp, sent, octets))
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
