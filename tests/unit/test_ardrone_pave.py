"""The AR.Drone 2.0's video stream, both sides: the PaVE header against the byte offsets of
ARDroneLib's ``video_encapsulation.h`` and a header seen on the wire (node-ar-drone's fixture),
the stream reader under any chunking, garbage, absurd sizes and packets cut short, the encoder's
headers, and encoder → reader → decoder with synthetic images; then the bytes read the way the
PyPI client ``ardrone`` (0.2.1) reads them."""

import io
import random
import socket
import struct
from dataclasses import fields, replace

import av
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.ardrone import pave
from drivers.ardrone.pave import (
    Codec,
    Control,
    FrameType,
    PaveError,
    PaveHeader,
    PaveReader,
    build,
    parse_header,
)
from drivers.ardrone.video import PaveDecoder, PaveEncoder

WIDTH_PX, HEIGHT_PX = 640, 360
SQUARE_PX = 80
SQUARE_BGR = (40, 60, 230)
STEP_PX = 7


def scene(index: int) -> np.ndarray:
    """A red square moving right across a grey-blue gradient."""
    image = np.empty((HEIGHT_PX, WIDTH_PX, 3), np.uint8)
    image[:] = np.linspace(40, 120, WIDTH_PX, dtype=np.uint8)[None, :, None]
    image[..., 0] = 150
    x = 20 + STEP_PX * index
    image[140:140 + SQUARE_PX, x:x + SQUARE_PX] = SQUARE_BGR
    return image


def square_left_px(image: np.ndarray) -> float:
    red = (image[..., 2] > 180) & (image[..., 0] < 100)
    columns = np.flatnonzero(red.sum(axis=0) > SQUARE_PX // 2)
    return float(columns.min())


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0**2 / mse))


@pytest.fixture(scope="module")
def encoded():
    """45 frames at 30 fps from t = 12.5 s on the drone's clock, a key frame every 10: the
    packets and the stream's bytes."""
    encoder = PaveEncoder(30.0, keyframe_interval=10, first_frame_number=1000)
    packets = []
    for i in range(45):
        packets += encoder.encode_packets(scene(i), 12.5 + i / 30)
    stream = b"".join(build(h, p) for h, p in packets)
    return packets, stream


# -- the header -------------------------------------------------------------------------------

#: node-ar-drone's fixture, the first frame (a real AR.Drone 2.0's P-frame)
WIRE = PaveHeader(version=2, video_codec=4, header_size=64, payload_size=2632,
                  encoded_stream_width_px=640, encoded_stream_height_px=368,
                  display_width_px=640, display_height_px=360, frame_number=17368,
                  timestamp_ms=1792570814, total_chunks=1, chunk_index=0, frame_type=3,
                  control=0, stream_byte_position_lw=72366960, stream_byte_position_uw=0,
                  stream_id=5, total_slices=1, slice_index=0, header1_size=0, header2_size=0,
                  advertised_size=2632)

#: every field a value of its own, at the offset video_encapsulation.h's comments give
OFFSETS = [("version", 4, "B", 2), ("video_codec", 5, "B", 4), ("header_size", 6, "H", 64),
           ("payload_size", 8, "I", 5), ("encoded_stream_width_px", 12, "H", 1280),
           ("encoded_stream_height_px", 14, "H", 736), ("display_width_px", 16, "H", 1279),
           ("display_height_px", 18, "H", 720), ("frame_number", 20, "I", 0x01020304),
           ("timestamp_ms", 24, "I", 0xA1B2C3D4), ("total_chunks", 28, "B", 7),
           ("chunk_index", 29, "B", 6), ("frame_type", 30, "B", 2), ("control", 31, "B", 2),
           ("stream_byte_position_lw", 32, "I", 0x11223344),
           ("stream_byte_position_uw", 36, "I", 0x55667788), ("stream_id", 40, "H", 0x0B0C),
           ("total_slices", 42, "B", 9), ("slice_index", 43, "B", 8),
           ("header1_size", 44, "B", 27), ("header2_size", 45, "B", 13),
           ("reserved2", 46, "2s", b"r2"), ("advertised_size", 48, "I", 0x7FFF0001),
           ("reserved3", 52, "12s", b"reserved-3.."), ]


def test_every_field_sits_at_ardronelibs_offset():
    header = PaveHeader(**{name: value for name, _, _, value in OFFSETS})
    raw = build(header, b"12345")
    assert len(raw) == 64 + 5
    assert raw[:4] == b"PaVE"
    for name, offset, code, value in OFFSETS:
        assert struct.unpack_from("<" + code, raw, offset)[0] == value, name
    assert raw[64:] == b"12345"
    assert {name for name, *_ in OFFSETS} == {f.name for f in fields(PaveHeader)} - {"extension"}


def test_a_header_seen_on_the_wire_round_trips_with_its_meaning():
    raw = build(WIRE, bytes(2632))
    header = parse_header(raw)
    assert header == WIRE
    assert header.frame_type is FrameType.P
    assert header.video_codec is Codec.MPEG4_AVC
    assert not header.is_key_frame
    assert header.timestamp_s == pytest.approx(1792570.814)
    assert replace(WIRE, frame_type=FrameType.IDR).is_key_frame
    assert not replace(WIRE, frame_type=FrameType.I, slice_index=1).is_key_frame
    assert replace(WIRE, stream_byte_position_uw=2).stream_byte_position == 2 << 32 | 72366960


u8, u16, u32 = (st.integers(0, 2**bits - 1) for bits in (8, 16, 32))


@st.composite
def headers(draw) -> tuple[PaveHeader, bytes]:
    extension = draw(st.binary(max_size=8))
    payload = draw(st.binary(max_size=40))
    widths = {"B": u8, "H": u16, "I": u32}
    values = {name: draw(widths[code] if code in widths else st.binary(
        min_size=int(code[:-1]), max_size=int(code[:-1]))) for name, _, code, _ in OFFSETS}
    values.update(header_size=64 + len(extension), payload_size=len(payload))
    return PaveHeader(**values, extension=extension), payload


@given(headers())
def test_any_header_round_trips_field_for_field(packet):
    header, payload = packet
    raw = build(header, payload)
    assert parse_header(raw) == header
    assert raw[header.header_size:] == payload


def test_what_cannot_be_a_header_is_refused_with_the_reason():
    good = build(WIRE, bytes(2632))
    with pytest.raises(PaveError, match="shorter than a 64-byte"):
        parse_header(good[:63])
    with pytest.raises(PaveError, match="signature"):
        parse_header(b"PaVe" + good[4:])
    with pytest.raises(PaveError, match="header_size 60"):
        parse_header(good[:6] + struct.pack("<H", 60) + good[8:])
    with pytest.raises(PaveError, match="header_size 68"):
        parse_header(good[:6] + struct.pack("<H", 68) + good[8:64])  # its extension missing
    with pytest.raises(PaveError, match="payload_size 2632 for a payload of 3"):
        build(WIRE, b"abc")
    with pytest.raises(PaveError, match="stream_id 65536 does not fit its 16 bits"):
        build(replace(WIRE, stream_id=65536), bytes(2632))
    with pytest.raises(PaveError, match="frame_number -1"):
        build(replace(WIRE, frame_number=-1), bytes(2632))
    with pytest.raises(PaveError, match="reserved3: 12 bytes"):
        build(replace(WIRE, reserved3=b"x"), bytes(2632))
    with pytest.raises(PaveError, match="header_size 64 for 64 bytes of fields and an ext"):
        build(replace(WIRE, extension=b"1234"), bytes(2632))


# -- the stream reader ------------------------------------------------------------------------

def small_packets() -> list[tuple[PaveHeader, bytes]]:
    """An IDR frame, an advertisement (no payload), a 68-byte header (as some firmware sends),
    and a payload holding the signature's bytes (not followed by a header)."""
    base = replace(WIRE, payload_size=0, advertised_size=0)
    return [
        (replace(base, frame_number=1, frame_type=FrameType.IDR, payload_size=30),
         bytes(range(30))),
        (replace(base, frame_number=2, control=Control.FRAME_ADVERTISEMENT,
                 advertised_size=900), b""),
        (replace(base, frame_number=3, header_size=68, extension=b"\x01\x02\x03\x04",
                 payload_size=11), b"hello world"),
        (replace(base, frame_number=4, payload_size=94),
         b"xPaVE" + bytes(70) + b"PaVE" + b"\xff" * 15),
    ]


def stream_of(packets) -> bytes:
    return b"".join(build(h, p) for h, p in packets)


def read_all(chunks, reader: PaveReader | None = None) -> list[tuple[PaveHeader, bytes]]:
    reader = reader or PaveReader()
    out = []
    for chunk in chunks:
        out += reader.feed(chunk)
    return out


def test_the_stream_split_at_every_position_gives_the_same_packets():
    packets = small_packets()
    stream = stream_of(packets)
    for split in range(len(stream) + 1):
        reader = PaveReader()
        assert read_all([stream[:split], stream[split:]], reader) == packets, split
        assert reader.pending_bytes == 0
        assert reader.garbage_bytes == reader.rejected == reader.truncated == 0
    one_by_one = [stream[i:i + 1] for i in range(len(stream))]
    assert read_all(one_by_one) == packets


@given(st.lists(st.integers(1, 200), max_size=40), st.randoms(use_true_random=False))
def test_the_stream_in_any_chunk_sizes_gives_the_same_packets(sizes, rng):
    packets = small_packets() * 2
    stream = stream_of(packets)
    chunks, at = [], 0
    while at < len(stream):
        size = sizes[len(chunks)] if len(chunks) < len(sizes) else rng.randint(1, 500)
        chunks.append(stream[at:at + size])
        at += size
    reader = PaveReader()
    assert read_all(chunks, reader) == packets
    assert reader.packets == len(packets)


garbage = st.binary(max_size=120).filter(lambda b: b"PaVE" not in b)


@given(st.lists(garbage, min_size=5, max_size=5), st.integers(1, 64))
def test_garbage_before_and_between_packets_is_skipped_and_counted(junk, chunk_size):
    packets = small_packets()
    stream = b"".join(j + build(h, p) for j, (h, p) in zip(junk, packets, strict=False))
    stream += junk[-1]
    reader = PaveReader()
    out = read_all([stream[i:i + chunk_size] for i in range(0, len(stream), chunk_size)],
                   reader)
    assert out == packets
    # the trailing garbage: all counted but what may still begin a signature
    assert reader.garbage_bytes + reader.pending_bytes == sum(map(len, junk))
    assert reader.pending_bytes <= 3


def test_absurd_sizes_are_refused_counted_and_said_and_the_next_packet_read():
    packets = small_packets()
    huge = struct.pack("<4sBBHI", b"PaVE", 2, 4, 64, 0xFFFFFFFF) + bytes(52)
    tiny = struct.pack("<4sBBHI", b"PaVE", 2, 4, 12, 10) + bytes(52)
    reader = PaveReader()
    out = reader.feed(huge + build(*packets[0]) + tiny + build(*packets[2]))
    assert out == [packets[0], packets[2]]
    assert reader.rejected == 2
    assert "header_size 12 outside 64 … 1024" in reader.last_rejection
    assert reader.garbage_bytes == 2 * 64
    reader.feed(huge)
    assert "payload_size 4294967295 above the limit of 4194304" in reader.last_rejection


def test_the_reader_holds_no_more_than_one_packet_whatever_arrives():
    reader = PaveReader(max_payload_size=1000)
    for _ in range(80):  # 5 MiB without a signature
        assert reader.feed(random.Random(1).randbytes(65536).replace(b"PaVE", b"PAVE")) == []
        assert reader.pending_bytes <= 3
    header = replace(WIRE, payload_size=1000, advertised_size=1000)
    reader.feed(build(header, bytes(1000))[:-1])
    assert reader.pending_bytes == 64 + 999
    reader.feed(b"\x00" + bytes(5000))  # that packet, then zeros
    assert reader.packets == 1
    assert reader.pending_bytes <= 3
    over = replace(header, payload_size=1001, advertised_size=1001)
    assert reader.feed(build(over, bytes(1001))) == []
    assert reader.rejected == 1


def test_a_packet_cut_short_anywhere_is_dropped_and_the_next_one_read():
    a, _, c, d = small_packets()
    whole = build(*d)  # (its payload holds the signature's bytes, not followed by a header)
    for cut in range(1, len(whole)):
        reader = PaveReader()
        out = reader.feed(build(*a) + whole[:cut] + build(*c) + build(*a))
        assert out == [a, c, a], cut
        assert reader.pending_bytes == 0
        if cut >= 64:  # its header was all there: the packet was taken and then dropped
            assert reader.truncated == 1
            assert "frame 4 at stream byte" in reader.last_rejection
            assert "cut short by the next header" in reader.last_rejection


def test_a_packet_cut_short_at_the_end_waits_and_a_reset_forgets_it():
    a, _, c, _ = small_packets()
    reader = PaveReader()
    assert reader.feed(build(*a) + build(*c)[:40]) == [a]
    assert reader.pending_bytes == 40
    reader.reset()
    assert reader.pending_bytes == 0
    assert reader.feed(build(*c)) == [c]


# -- the encoder ------------------------------------------------------------------------------

def test_the_encoder_frames_each_picture_as_the_drone_does(encoded):
    packets, _ = encoded
    assert len(packets) == 45  # one packet per frame: no frame held back
    position = 0
    for i, (header, payload) in enumerate(packets):
        assert header.frame_number == 1000 + i
        assert header.timestamp_ms == round((12.5 + i / 30) * 1000)
        key = i % 10 == 0
        assert header.frame_type == (FrameType.IDR if key else FrameType.P), i
        assert (header.encoded_stream_width_px, header.encoded_stream_height_px) == (640, 368)
        assert (header.display_width_px, header.display_height_px) == (640, 360)
        assert (header.version, header.video_codec, header.header_size) == (2, Codec.MPEG4_AVC,
                                                                          64)
        assert header.payload_size == header.advertised_size == len(payload)
        assert (header.total_chunks, header.chunk_index) == (1, 0)
        assert (header.total_slices, header.slice_index, header.control) == (1, 0, 0)
        assert header.stream_byte_position == position
        position += len(payload)
        assert payload.startswith((b"\x00\x00\x00\x01", b"\x00\x00\x01"))
        if key:  # SPS then PPS, their sizes in the header, then SEI or the IDR slice
            sps, pps = header.header1_size, header.header2_size
            assert payload[:5] == b"\x00\x00\x00\x01\x67"
            assert payload[5] == 66  # profile_idc: baseline
            assert payload[sps:sps + 5] == b"\x00\x00\x00\x01\x68"
            rest = payload[sps + pps:]
            code = 4 if rest.startswith(b"\x00\x00\x00\x01") else 3
            assert rest[code - 3:code] == b"\x00\x00\x01"
            assert rest[code] & 0x1F in (5, 6)  # an IDR slice or an SEI
        else:
            assert header.header1_size == header.header2_size == 0


def test_a_frame_of_another_size_starts_the_stream_again_at_a_key_frame():
    encoder = PaveEncoder(keyframe_interval=30)
    types = []
    for i in range(3):
        types += [h.frame_type for h, _ in encoder.encode_packets(scene(i), i / 30)]
    (header, _), = encoder.encode_packets(np.zeros((240, 320, 3), np.uint8), 0.1)
    assert types == [FrameType.IDR, FrameType.P, FrameType.P]
    assert header.frame_type == FrameType.IDR
    assert header.frame_number == 3
    assert (header.display_width_px, header.display_height_px) == (320, 240)
    assert (header.encoded_stream_width_px, header.encoded_stream_height_px) == (320, 240)
    assert (encoder.key_frames, encoder.frames) == (2, 4)


@pytest.mark.parametrize("image", [np.zeros((360, 640, 3), np.float32),
                                   np.zeros((360, 640), np.uint8),
                                   np.zeros((361, 640, 3), np.uint8)])
def test_the_encoder_refuses_what_is_not_an_even_sized_bgr_image(image):
    with pytest.raises(ValueError, match=r"BGR uint8|even sizes"):
        PaveEncoder().encode(image, 0.0)


# -- encoder → reader → decoder ---------------------------------------------------------------

def test_the_pictures_come_back_numbered_stamped_and_alike(encoded):
    _, stream = encoded
    rng = random.Random(33)
    reader, decoder = PaveReader(), PaveDecoder()
    frames, at = [], 0
    while at < len(stream):
        size = rng.randint(1, 3000)
        for header, payload in reader.feed(stream[at:at + size]):
            frames += decoder.decode(header, payload)
        at += size
    assert [f.frame_number for f in frames] == list(range(1000, 1045))
    assert [f.time_s for f in frames] == pytest.approx([12.5 + i / 30 for i in range(45)],
                                                        abs=0.0006)
    for i, frame in enumerate(frames):
        assert frame.image.shape == (360, 640, 3)
        assert frame.image.dtype == np.uint8
        assert psnr_db(frame.image, scene(i)) > 30, i
        assert square_left_px(frame.image) == pytest.approx(20 + STEP_PX * i, abs=1), i
    assert decoder.decoded == 45
    assert decoder.dropped_before_key == decoder.decode_errors == decoder.gaps == 0


def test_a_decoder_joining_mid_stream_waits_for_the_key_frame(encoded):
    packets, _ = encoded
    decoder = PaveDecoder()
    frames = [f for h, p in packets[3:] for f in decoder.decode(h, p)]
    assert frames[0].frame_number == 1010  # the P-frames 1003 … 1009 dropped
    assert decoder.dropped_before_key == 7
    assert decoder.decode_errors == 0
    assert [f.frame_number for f in frames] == list(range(1010, 1045))
    assert psnr_db(frames[0].image, scene(10)) > 30


def test_a_lost_packet_drops_the_frames_after_it_until_the_next_key_frame(encoded):
    packets, _ = encoded
    decoder = PaveDecoder()
    frames = [f for h, p in packets[:13] + packets[14:] for f in decoder.decode(h, p)]
    numbers = [f.frame_number for f in frames]
    assert numbers == list(range(1000, 1013)) + list(range(1020, 1045))
    assert (decoder.gaps, decoder.dropped_before_key, decoder.decode_errors) == (1, 6, 0)
    for frame in frames:
        assert psnr_db(frame.image, scene(frame.frame_number - 1000)) > 30


def test_a_packet_cut_short_in_the_stream_costs_the_rest_of_its_gop(encoded):
    _, stream = encoded
    packets, _ = encoded
    cut_at = sum(64 + h.payload_size for h, _ in packets[:25]) + 64 + 20  # inside frame 1025
    reader, decoder = PaveReader(), PaveDecoder()
    frames = [f for h, p in reader.feed(stream[:cut_at] + stream[cut_at + 50:])
              for f in decoder.decode(h, p)]
    assert reader.truncated == 1
    assert [f.frame_number for f in frames] == list(range(1000, 1025)) + list(range(1030, 1045))


def test_a_payload_the_decoder_refuses_is_counted_and_it_waits_again(encoded):
    packets, _ = encoded
    junk = random.Random(5).randbytes(400)
    decoder = PaveDecoder()
    as_idr = replace(packets[0][0], payload_size=405)
    assert decoder.decode(as_idr, b"\x00\x00\x00\x01\x65" + junk) == []  # before any SPS
    assert decoder.decode_errors == 1
    assert decoder.awaiting_key_frame
    decoder.reset()
    assert len([f for h, p in packets[:3] for f in decoder.decode(h, p)]) == 3
    as_p = replace(packets[3][0], payload_size=405)
    assert decoder.decode(as_p, b"\x00\x00\x00\x01\x41" + junk) == []
    assert decoder.decode_errors == 2
    later = [f for h, p in packets[4:11] for f in decoder.decode(h, p)]
    assert [f.frame_number for f in later] == [1010]  # 1004 … 1009 dropped: they need 1003
    assert (decoder.gaps, decoder.dropped_before_key) == (0, 6)
    assert psnr_db(later[0].image, scene(10)) > 30
    advert = replace(packets[11][0], control=Control.FRAME_ADVERTISEMENT, payload_size=0)
    assert decoder.decode(advert, b"") == []
    assert decoder.skipped == 1


# -- a PyPI client ----------------------------------------------------------------------------

class _Socket:
    """What the client asks of its TCP socket: ``recv(n, MSG_WAITALL)``."""

    def __init__(self, data: bytes) -> None:
        self._data = io.BytesIO(data)

    def recv(self, size: int, flags: int = 0) -> bytes:
        assert flags == socket.MSG_WAITALL
        return self._data.read(size)


#: ``struct PaVE`` of ardrone's video.c, packed
_ARDRONE_PAVE = struct.Struct("<4sBBHIHHHHIIBBBBIIHBBBB2sI12s")


def ardrone_client_images(sock: _Socket) -> tuple[list[np.ndarray], int]:
    """The PyPI package ``ardrone`` 0.2.1's reading, step for step: ``ardrone/network.py``'s
    loop (12 bytes, the signature checked, then the rest of the header and the payload by the
    header's sizes) and ``ardrone/video.c``'s ``decode`` (the header's sizes checked against
    the packet, the payload to an H.264 decoder kept across packets — libavcodec's defaults,
    one thread — a frame required from every packet, else ``DecodeError``, which the loop
    ignores). The images (RGB) and the DecodeErrors."""
    codec = av.CodecContext.create("h264", "r")
    codec.thread_count = 1
    images, errors = [], 0
    while True:
        data = sock.recv(12, socket.MSG_WAITALL)
        if len(data) != 12:
            break  # (the client's loop waits on select; the test's stream has ended)
        sig_p, sig_a, sig_v, sig_e, _version, _codec, header, payload = struct.unpack(
            "4cBBHI", data)
        if sig_p != b"P" or sig_a != b"a" or sig_v != b"V" or sig_e != b"E":
            continue
        data += sock.recv(header - 12 + payload, socket.MSG_WAITALL)
        pave_ = _ARDRONE_PAVE.unpack_from(data)
        header_size, payload_size = pave_[3], pave_[4]
        if pave_[0] != b"PaVE" or header_size + payload_size != len(data):
            errors += 1
            continue
        try:
            frames = codec.decode(av.Packet(data[header_size:header_size + payload_size]))
        except av.error.FFmpegError:
            frames = []
        if not frames:
            errors += 1
            continue
        rgb = frames[0].reformat(format="rgb24")
        images.append(rgb.to_ndarray())
    return images, errors


def test_the_ardrone_client_reads_our_stream_a_picture_per_packet(encoded):
    _, stream = encoded
    images, errors = ardrone_client_images(_Socket(stream))
    assert errors == 0
    assert len(images) == 45
    for i, rgb in enumerate(images):
        assert psnr_db(rgb[..., ::-1], scene(i)) > 30, i


def test_the_clients_header_struct_is_ours():
    assert _ARDRONE_PAVE.size == pave.HEADER_SIZE
    raw = build(WIRE, bytes(2632))
    assert _ARDRONE_PAVE.unpack_from(raw)[1:] == tuple(
        getattr(WIRE, f.name) for f in fields(PaveHeader))[:-1]
