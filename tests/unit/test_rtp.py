"""RTP H.264 packetization (RFC 6184) and reassembly, RTCP packets (RFC 3550), and the
addresses video is received on."""

import struct

import numpy as np
import pytest

from drivers.base import CameraInfo, CameraIntrinsics
from drivers.video import (
    SIM_CNAME,
    SIM_TOOL,
    Goodbye,
    RtpH264Depacketizer,
    RtpH264Packetizer,
    SenderReport,
    SourceDescription,
    VideoSender,
    VideoSource,
    encode_goodbye,
    encode_sender_report,
    encode_source_description,
    parse_rtcp,
    rtp_address,
    split_nal_units,
)

pytestmark = pytest.mark.serial  # RTP on fixed ports

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


# RTCP (RFC 3550 §6): what a receiver needs to know when a frame was taken


def test_sender_report_and_source_description_round_trip_as_one_compound_packet():
    report = SenderReport(ssrc=0x89ABCDEF, wall_time_s=1_763_700_000.123456,
                          rtp_timestamp=0xFFFF_FFF0, packet_count=1234, octet_count=5_678_901)
    description = SourceDescription(0x89ABCDEF, SIM_CNAME, SIM_TOOL)
    datagram = encode_sender_report(report) + encode_source_description(description)
    assert len(datagram) % 4 == 0
    assert datagram[1] == 200  # a compound packet starts with the SR
    sr, sdes = parse_rtcp(datagram)
    assert sr.wall_time_s == pytest.approx(report.wall_time_s, abs=1e-6)  # NTP: 2^-32 s
    assert (sr.ssrc, sr.rtp_timestamp, sr.packet_count, sr.octet_count) == \
        (report.ssrc, report.rtp_timestamp, report.packet_count, report.octet_count)
    assert sdes == description


@pytest.mark.parametrize("wall_time_s", [0.5, 1_000_000_000.0, 2_200_000_000.25])
def test_ntp_timestamps_survive_the_2036_era_rollover(wall_time_s):
    datagram = encode_sender_report(SenderReport(1, wall_time_s, 0))
    assert parse_rtcp(datagram)[0].wall_time_s == pytest.approx(wall_time_s, abs=1e-6)


def test_sdes_items_of_any_length_and_goodbye_round_trip():
    for cname in ("", "a", "abc", "abcd", "camera@192.168.1.5", "é" * 200):
        datagram = encode_source_description(SourceDescription(7, cname))
        assert len(datagram) % 4 == 0
        (parsed,) = parse_rtcp(datagram)
        assert parsed.ssrc == 7
        assert cname.encode()[:255].decode(errors="replace") == parsed.cname
    assert parse_rtcp(encode_goodbye(1, 0xFFFFFFFF)) == [Goodbye((1, 0xFFFFFFFF))]


def test_unknown_rtcp_packets_are_skipped_and_malformed_ones_end_parsing():
    receiver_report = struct.pack("!BBHI", 0x80, 201, 1, 5)  # RR without report blocks
    sdes = encode_source_description(SourceDescription(5, "cam"))
    assert parse_rtcp(receiver_report + sdes) == [SourceDescription(5, "cam")]
    truncated = sdes + encode_sender_report(SenderReport(5, 1.0, 2))[:-4]
    assert parse_rtcp(truncated) == [SourceDescription(5, "cam")]
    assert parse_rtcp(b"") == []
    assert parse_rtcp(b"\x00" * 40) == []  # not version 2


# addresses: loopback unless told otherwise


@pytest.mark.parametrize(("url", "address"), [
    ("udp://@:5600", ("127.0.0.1", 5600)),
    ("udp://:5600", ("127.0.0.1", 5600)),
    ("rtp://@:5004", ("127.0.0.1", 5004)),
    ("udp://0.0.0.0:5600", ("0.0.0.0", 5600)),
    ("udp://@0.0.0.0:5600?source=10.0.0.2", ("0.0.0.0", 5600)),
    ("udp://192.168.1.5:5600", ("192.168.1.5", 5600)),
    ("rtsp://10.0.0.2:8554/live", None),
    ("/dev/video0", None),
])
def test_rtp_urls_bind_loopback_unless_an_address_is_given(url, address):
    assert rtp_address(url) == address


def _camera() -> CameraInfo:
    return CameraInfo("front", CameraIntrinsics(320, 240, 160.0, 160.0, 159.5, 119.5),
                      rotation_body_cam=np.eye(3), position_body_m=np.zeros(3), rate_hz=30.0)


def test_the_video_source_comes_from_the_url_or_the_argument():
    assert VideoSource("udp://@:5600", _camera()).source is None
    assert VideoSource("udp://@:5600?source=10.0.0.2", _camera()).source == ("10.0.0.2", None)
    assert VideoSource("udp://0.0.0.0:5600?source=10.0.0.2:5004",
                       _camera()).source == ("10.0.0.2", 5004)
    assert VideoSource("udp://@:5600?source=10.0.0.2", _camera(),
                       source="camera.local:6000").source == ("camera.local", 6000)
    for bad in ("", ":5004", "10.0.0.2:", "10.0.0.2:x", "10.0.0.2:70000"):
        with pytest.raises(ValueError, match="HOST:PORT"):
            VideoSource("udp://@:5600", _camera(), source=bad)
    with pytest.raises(ValueError, match="udp:// or rtp://"):
        VideoSource("rtsp://10.0.0.2/live", _camera(), source="10.0.0.2")
    with pytest.raises(ValueError, match="latency_s"):
        VideoSource("udp://@:5600", _camera(), latency_s=-0.01)


def test_a_sender_with_an_offset_rtp_clock_may_not_claim_the_simulator_s_convention():
    with pytest.raises(ValueError, match="cname"):
        VideoSender("udp://127.0.0.1:5600", 64, 48, 30.0, rtp_offset_ticks=12345)
    VideoSender("udp://127.0.0.1:5600", 64, 48, 30.0, rtp_offset_ticks=12345,
                cname="camera").close()
