"""RTP H.264 packetization (RFC 6184) and reassembly."""

import struct

from drivers.video import RtpH264Depacketizer, RtpH264Packetizer, split_nal_units

SPS = bytes([0x67, 1, 2, 3])
PPS = bytes([0x68, 4, 5])
IDR = bytes([0x65]) + bytes(range(256)) * 20  # 5 kB: fragmented


def _annexb(*units: bytes) -> bytes:
    return b"".join(b"\x00\x00\x00\x01" + u for u in units)


def test_split_nal_units_handles_3_and_4_byte_start_codes():
    stream = b"\x00\x00\x00\x01" + SPS + b"\x00\x00\x01" + PPS + b"\x00\x00\x01" + IDR
    assert split_nal_units(stream) == [SPS, PPS, IDR]


def test_access_unit_round_trip_with_fragmentation_and_marker_on_the_last_packet():
    packets = list(RtpH264Packetizer(ssrc=7, max_payload_b=1000).packets([SPS, PPS, IDR],
                                                                          123456))
    assert len(packets) > 3
    markers = [bool(p[1] & 0x80) for p in packets]
    assert markers == [False] * (len(packets) - 1) + [True]
    assert all(struct.unpack_from("!I", p, 4)[0] == 123456 for p in packets)
    assert all(len(p) <= 12 + 1000 for p in packets)
    depack = RtpH264Depacketizer()
    results = [depack.push(p) for p in packets]
    assert results[:-1] == [None] * (len(packets) - 1)
    assert results[-1] == (123456, _annexb(SPS, PPS, IDR))


def test_an_access_unit_with_a_lost_packet_is_dropped_and_the_next_one_delivered():
    rtp = RtpH264Packetizer(ssrc=7, max_payload_b=1000)
    first = list(rtp.packets([IDR], 1000))
    second = list(rtp.packets([bytes([0x41, 9, 9, 9])], 4000))
    depack = RtpH264Depacketizer()
    got = [depack.push(p) for p in first[:2] + first[3:] + second]
    assert [g for g in got if g is not None] == [(4000, _annexb(bytes([0x41, 9, 9, 9])))]
    assert depack.lost == 1


def test_stap_a_aggregates_are_unpacked():
    payload = bytes([24]) + struct.pack("!H", len(SPS)) + SPS + struct.pack("!H", len(PPS)) + PPS
    packet = struct.pack("!BBHII", 0x80, 0x80 | 96, 1, 90, 5) + payload
    assert RtpH264Depacketizer().push(packet) == (90, _annexb(SPS, PPS))


def test_garbage_is_ignored():
    depack = RtpH264Depacketizer()
    assert depack.push(b"") is None
    assert depack.push(b"\x00" * 40) is None  # not RTP version 2
