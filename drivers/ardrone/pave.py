"""AR.Drone 2.0 video framing (the SDK 2.0 developer guide, 7.3; ARDroneLib's
``video_encapsulation.h``): the PaVE ("Parrot Video Encapsulation") header that precedes each
encoded frame on the drone's video stream, TCP 5555 — built by the simulated AR.Drone's
firmware, read by the driver. No codec here: :mod:`drivers.ardrone.video` encodes and decodes
the payloads.

A packet is a header then ``payload_size`` bytes of payload: one whole frame, Annex B H.264 on
firmware 2.x (``video_codec`` 4), its SPS and PPS before the slice of an IDR frame. The header,
little-endian and packed (``parrot_video_encapsulation_t``, the byte offsets its comments give):

====  ==========================  ====  ==========================  ====  ==================
  0   signature ``PaVE``           20   frame_number (u32)           40   stream_id (u16)
  4   version (u8: 2)              24   timestamp (u32, ms)          42   total_slices (u8)
  5   video_codec (u8)             28   total_chunks (u8)            43   slice_index (u8)
  6   header_size (u16)            29   chunk_index (u8)             44   header1_size (u8)
  8   payload_size (u32)           30   frame_type (u8)              45   header2_size (u8)
 12   encoded_stream_width (u16)   31   control (u8)                 46   reserved2 (2)
 14   encoded_stream_height (u16)  32   stream_byte_position_lw      48   advertised_size
 16   display_width (u16)          36   stream_byte_position_uw      52   reserved3 (12)
 18   display_height (u16)
====  ==========================  ====  ==========================  ====  ==================

``header_size`` is 64 on AR.Drone 2.0 firmware 2.x; some firmware sends 68 (node-ar-drone's
fixtures), so a reader skips ``header_size`` bytes, not 64. The encoded size is the frame's in
whole macroblocks (640 × 368 for a 640 × 360 display: the decoder crops to the display size).
``timestamp`` is the capture time in milliseconds on the drone's clock; ``frame_number``
counts frames in the stream. ``header1_size`` and ``header2_size`` are the SPS's and PPS's
sizes in the payload (0: none); the simulated drone's encoder (:mod:`drivers.ardrone.video`)
counts their start codes in, so that the payload's first ``header1_size`` bytes are the SPS.

A client reads the stream, finds the signature, reads the header and then the payload
(:class:`PaveReader`: any chunking, garbage skipped, absurd sizes refused, a packet cut short
by the next one's header dropped).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, fields
from typing import Literal

SIGNATURE = b"PaVE"
#: ``PAVE_CURRENT_VERSION``
VERSION = 2
#: the header's size on AR.Drone 2.0 firmware 2.x (``sizeof(parrot_video_encapsulation_t)``)
HEADER_SIZE = 64
#: the drone's video stream (TCP on AR.Drone 2.0)
VIDEO_PORT = 5555
#: ``PAVE_STREAM_ID_SUFFIX_H264_360p`` / ``_H264_720p``
STREAM_ID_H264_360P = 1
STREAM_ID_H264_720P = 2
#: a reader's default limits: far above what the drone sends (a 720p I-frame is tens of kB)
MAX_HEADER_SIZE = 1024
MAX_PAYLOAD_SIZE = 4 << 20

#: the fields after the signature, in wire order, and their struct codes
_LAYOUT = (("version", "B"), ("video_codec", "B"), ("header_size", "H"), ("payload_size", "I"),
           ("encoded_stream_width_px", "H"), ("encoded_stream_height_px", "H"),
           ("display_width_px", "H"), ("display_height_px", "H"), ("frame_number", "I"),
           ("timestamp_ms", "I"), ("total_chunks", "B"), ("chunk_index", "B"),
           ("frame_type", "B"), ("control", "B"), ("stream_byte_position_lw", "I"),
           ("stream_byte_position_uw", "I"), ("stream_id", "H"), ("total_slices", "B"),
           ("slice_index", "B"), ("header1_size", "B"), ("header2_size", "B"),
           ("reserved2", "2s"), ("advertised_size", "I"), ("reserved3", "12s"))
_HEADER = struct.Struct("<4s" + "".join(code for _, code in _LAYOUT))
_NAMES = tuple(name for name, _ in _LAYOUT)
_BITS = {"B": 8, "H": 16, "I": 32}
#: what tells a header from the signature's bytes by chance: the signature, version, codec
#: and the two sizes
_PROBE = struct.Struct("<4sBBHI")
assert _HEADER.size == HEADER_SIZE


class PaveError(ValueError):
    """Bytes that are not a PaVE header, or a header that cannot be built."""


class Codec(enum.IntEnum):
    """``parrot_video_encapsulation_codecs_t``."""

    UNKNOWN = 0
    VLIB = 1
    P264 = 2
    MPEG4_VISUAL = 3
    MPEG4_AVC = 4  # H.264: what AR.Drone 2.0 streams


class FrameType(enum.IntEnum):
    """``parrot_video_encapsulation_frametypes_t``."""

    UNKNOWN = 0
    IDR = 1  # SPS and PPS, then an IDR frame
    I = 2  # noqa: E741  (the header's own name)
    P = 3
    HEADERS = 4


class Control(enum.IntFlag):
    """``parrot_video_encapsulation_control_t``."""

    FRAME_DATA = 0  # a frame follows
    FRAME_ADVERTISEMENT = 1 << 0  # no data: a frame announced, sent on another socket later
    LAST_FRAME_IN_STREAM = 1 << 1


@dataclass(frozen=True, slots=True)
class PaveHeader:
    """One PaVE header, its fields in wire order (the C names, with units where they have
    one). ``extension`` is whatever a header longer than 64 bytes carries after them."""

    version: int = VERSION
    video_codec: Codec | int = Codec.MPEG4_AVC
    header_size: int = HEADER_SIZE
    payload_size: int = 0
    encoded_stream_width_px: int = 0
    encoded_stream_height_px: int = 0
    display_width_px: int = 0
    display_height_px: int = 0
    frame_number: int = 0
    timestamp_ms: int = 0
    total_chunks: int = 1
    chunk_index: int = 0
    frame_type: FrameType | int = FrameType.UNKNOWN
    control: int = Control.FRAME_DATA
    stream_byte_position_lw: int = 0
    stream_byte_position_uw: int = 0
    stream_id: int = STREAM_ID_H264_360P
    total_slices: int = 1
    slice_index: int = 0
    header1_size: int = 0
    header2_size: int = 0
    reserved2: bytes = bytes(2)
    advertised_size: int = 0
    reserved3: bytes = bytes(12)
    extension: bytes = b""

    @property
    def stream_byte_position(self) -> int:
        """The payload's byte offset in the encoded stream (both 32-bit words)."""
        return self.stream_byte_position_uw << 32 | self.stream_byte_position_lw

    @property
    def is_key_frame(self) -> bool:
        """Does a decoder start here (an IDR or I-frame's first slice; ARDroneLib's
        ``frameIsIFrame``)?"""
        return self.frame_type in (FrameType.IDR, FrameType.I) and self.slice_index == 0

    @property
    def timestamp_s(self) -> float:
        """The capture time on the drone's clock, in seconds."""
        return self.timestamp_ms / 1000.0


assert tuple(f.name for f in fields(PaveHeader))[:-1] == _NAMES  # all but the extension


def _known(kind: type[enum.IntEnum], value: int) -> enum.IntEnum | int:
    try:
        return kind(value)
    except ValueError:
        return value


def parse_header(data: bytes | bytearray | memoryview) -> PaveHeader:
    """The header at the start of ``data`` (at least its ``header_size`` bytes)."""
    if len(data) < HEADER_SIZE:
        raise PaveError(f"{len(data)} bytes: shorter than a {HEADER_SIZE}-byte PaVE header")
    signature, *values = _HEADER.unpack_from(data)
    if signature != SIGNATURE:
        raise PaveError(f"signature {bytes(signature)!r}, not {SIGNATURE!r}")
    header = dict(zip(_NAMES, values, strict=True))
    size = header["header_size"]
    if size < HEADER_SIZE:
        raise PaveError(f"header_size {size}: less than the {HEADER_SIZE} bytes of its fields")
    if len(data) < size:
        raise PaveError(f"{len(data)} bytes: shorter than the header's header_size {size}")
    header["video_codec"] = _known(Codec, header["video_codec"])
    header["frame_type"] = _known(FrameType, header["frame_type"])
    return PaveHeader(**header, extension=bytes(data[HEADER_SIZE:size]))


def build(header: PaveHeader, payload: bytes) -> bytes:
    """A packet as the drone sends it: ``header`` (its ``payload_size`` that of ``payload``,
    its ``header_size`` 64 plus its extension's) and ``payload``."""
    if header.payload_size != len(payload):
        raise PaveError(f"payload_size {header.payload_size} for a payload of "
                        f"{len(payload)} bytes")
    if header.header_size != HEADER_SIZE + len(header.extension):
        raise PaveError(f"header_size {header.header_size} for {HEADER_SIZE} bytes of fields "
                        f"and an extension of {len(header.extension)}")
    values = [getattr(header, name) for name, _ in _LAYOUT]
    for (name, code), value in zip(_LAYOUT, values, strict=True):
        if code.endswith("s"):
            if not isinstance(value, bytes) or len(value) != int(code[:-1]):
                raise PaveError(f"{name}: {code[:-1]} bytes expected, not {value!r}")
        elif not 0 <= int(value) < 1 << _BITS[code]:
            raise PaveError(f"{name} {value} does not fit its {_BITS[code]} bits")
    return _HEADER.pack(SIGNATURE, *values) + header.extension + payload


class PaveReader:
    """PaVE packets out of a byte stream as it arrives (TCP delivers it in any chunks).

    ``feed(data)`` returns the packets completed, ``(header, payload)``, in order. Bytes before
    a signature are skipped (:attr:`garbage_bytes`); a header whose sizes are absurd
    (``header_size`` outside 64 … ``max_header_size``, ``payload_size`` above
    ``max_payload_size``) is refused (:attr:`rejected`, :attr:`last_rejection` says why) and
    the search goes on after its signature. A valid header found inside a packet (the same
    version and codec, sizes within the limits) means the packet was cut short — its sender
    restarted, or a relay lost bytes — and it is dropped (:attr:`truncated`); the bytes
    ``PaVE`` inside a payload followed by no such header are payload (a packet whose last 11
    bytes hold them waits for the bytes after it, to tell). What is held between calls is at
    most one packet's header and payload, so memory stays bounded by the limits whatever
    arrives. :meth:`reset` forgets a partial packet (a new connection).
    """

    def __init__(self, *, max_header_size: int = MAX_HEADER_SIZE,
                 max_payload_size: int = MAX_PAYLOAD_SIZE) -> None:
        if max_header_size < HEADER_SIZE:
            raise ValueError(f"max_header_size {max_header_size}: at least {HEADER_SIZE}")
        self.max_header_size = max_header_size
        self.max_payload_size = max_payload_size
        self._buffer = bytearray()
        self._header: PaveHeader | None = None  # the packet being read, its header parsed
        self._scan_from = 0  # where the search for a header inside its payload goes on
        self._offset = 0  # the stream position of the buffer's first byte
        #: counts, for the driver's statistics
        self.packets = 0
        self.garbage_bytes = 0
        self.rejected = 0
        self.truncated = 0
        #: why the last header was refused or packet dropped (None: none yet)
        self.last_rejection: str | None = None

    @property
    def pending_bytes(self) -> int:
        """Bytes held: a packet not yet complete, or what may begin a signature."""
        return len(self._buffer)

    def reset(self) -> None:
        """Drop what is held (the stream starts again: a new connection)."""
        self._offset += len(self._buffer)
        self._buffer.clear()
        self._header = None

    def feed(self, data: bytes | bytearray | memoryview) -> list[tuple[PaveHeader, bytes]]:
        """The packets that ``data``, the stream's next bytes, completes."""
        self._buffer += data
        out: list[tuple[PaveHeader, bytes]] = []
        start = 0  # consumed up to here (cut from the buffer once, at the end)
        try:
            while True:
                if self._header is None:
                    start = self._find_header(start)
                    if self._header is None:
                        break
                header = self._header
                status = self._complete(start)
                if status == "wait":
                    break
                if status == "cut":
                    start = self._scan_from  # at the header that cut it short
                else:
                    end = start + header.header_size + header.payload_size
                    with memoryview(self._buffer) as view:
                        out.append((header, bytes(view[start + header.header_size:end])))
                    self.packets += 1
                    start = end
                self._header = None
        finally:
            del self._buffer[:start]
            self._offset += start
            self._scan_from -= start
        return out

    def _find_header(self, start: int) -> int:
        """Skip to the next plausible header from ``start``; parse it into ``_header`` if it
        is all there. Returns the new start."""
        buffer = self._buffer
        while True:
            found = buffer.find(SIGNATURE, start)
            if found < 0:
                keep = max(start, len(buffer) - (len(SIGNATURE) - 1))  # a signature's start?
                self.garbage_bytes += keep - start
                return keep
            self.garbage_bytes += found - start
            start = found
            if len(buffer) - start < HEADER_SIZE:
                return start
            problem = self._implausible(start)
            if problem is None:
                size = struct.unpack_from("<H", buffer, start + 6)[0]
                if len(buffer) - start < size:
                    return start
                self._header = parse_header(bytes(buffer[start:start + size]))
                # from its own signature on: a packet cut inside its header has the next
                # one's signature within those 64 bytes
                self._scan_from = start + len(SIGNATURE)
                return start
            self.rejected += 1
            self.last_rejection = f"PaVE header at stream byte {self._offset + start}: {problem}"
            self.garbage_bytes += 1
            start += 1

    def _implausible(self, at: int, like: PaveHeader | None = None) -> str | None:
        """Why the bytes at ``at``, the signature then at least the sizes, are not a header
        (None: they may be)."""
        _, version, codec, size, payload_size = _PROBE.unpack_from(self._buffer, at)
        if not HEADER_SIZE <= size <= self.max_header_size:
            return f"header_size {size} outside {HEADER_SIZE} … {self.max_header_size}"
        if payload_size > self.max_payload_size:
            return f"payload_size {payload_size} above the limit of {self.max_payload_size}"
        if like is not None and (version != like.version or codec != like.video_codec):
            return "another version or codec"
        return None

    def _complete(self, start: int) -> Literal["wait", "cut", "done"]:
        """Is the packet whose header is at ``start`` all there ("done"), not yet ("wait"),
        or cut short by a header inside its payload, at ``_scan_from`` ("cut")?"""
        header = self._header
        assert header is not None
        buffer = self._buffer
        end = start + header.header_size + header.payload_size
        while True:  # a signature that begins inside the packet
            found = buffer.find(SIGNATURE, self._scan_from,
                                min(len(buffer), end + len(SIGNATURE) - 1))
            if found < 0:
                break
            if len(buffer) - found < _PROBE.size:
                self._scan_from = found
                return "wait"  # a header? (rare inside H.264: wait for its sizes)
            if self._implausible(found, like=header) is None:
                self.truncated += 1
                self.last_rejection = (f"frame {header.frame_number} at stream byte "
                                       f"{self._offset + start}: cut short by the next "
                                       f"header after {found - start} of its "
                                       f"{end - start} bytes")
                self._scan_from = found
                return "cut"
            self._scan_from = found + 1
        if len(buffer) < end + len(SIGNATURE) - 1:
            self._scan_from = max(self._scan_from, len(buffer) - (len(SIGNATURE) - 1))
        if len(buffer) < end:
            return "wait"
        return "done"
