"""AR.Drone 2.0 video, both ends of TCP 5555 (framing: :mod:`drivers.ardrone.pave`): the
simulated AR.Drone's camera encodes its frames to H.264 and wraps each in a PaVE header
(:class:`PaveEncoder`); the driver decodes the payloads back to images stamped with the drone's
frame numbers and capture times (:class:`PaveDecoder`). Both are synchronous and own no socket
and no thread: the driver decodes off the event loop, as :mod:`drivers.video.source` does.

What the drone sends, and the encoder imitates: one packet per frame, one slice per frame, no
B-frames (frames leave in capture order, each as soon as it is encoded), an IDR frame with its
SPS and PPS at a fixed interval (about once a second at the drone's 30 fps), P-frames
between. A decoder can start only at a key frame, and a lost frame breaks
every P-frame after it until the next one (ardrone_autonomy, ARDroneLib's TCP stage and the
PyPI clients all wait for it).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import av
import numpy as np

from drivers.ardrone.pave import (
    STREAM_ID_H264_360P,
    Codec,
    Control,
    FrameType,
    PaveHeader,
    build,
)

#: H.264 NAL unit types
_NAL_SLICE = 1
_NAL_IDR = 5
_NAL_SPS = 7
_NAL_PPS = 8
_MACROBLOCK_PX = 16
#: headers a decoder keeps while their frames are inside it (it holds none on this stream)
_IN_FLIGHT = 16


def _nal_units(annexb: bytes) -> list[tuple[int, int]]:
    """(offset of its start code, NAL unit type) of each NAL unit in an Annex B payload."""
    units = []
    at = annexb.find(b"\x00\x00\x01")
    while 0 <= at < len(annexb) - 3:
        start = at - 1 if at > 0 and annexb[at - 1] == 0 else at  # a 4-byte start code
        units.append((start, annexb[at + 3] & 0x1F))
        at = annexb.find(b"\x00\x00\x01", at + 3)
    return units


def _parameter_sets(annexb: bytes) -> tuple[int, int, int]:
    """The sizes of a leading SPS and PPS (start codes included; 0: none) and the number of
    slices in a payload."""
    units = _nal_units(annexb)
    ends = [start for start, _ in units[1:]] + [len(annexb)]
    sizes = [0, 0]
    for index, (start, kind) in enumerate(units[:2]):
        if kind != (_NAL_SPS, _NAL_PPS)[index] or ends[index] - start > 0xFF:
            break  # (the header's fields are a byte each)
        sizes[index] = ends[index] - start
    slices = sum(kind in (_NAL_SLICE, _NAL_IDR) for _, kind in units)
    return sizes[0], sizes[1], slices


class PaveEncoder:
    """BGR frames to PaVE-framed H.264, as the drone's firmware streams them.

    libx264 through PyAV (the approach of :class:`drivers.video.sender.VideoSender`): preset
    ``ultrafast``, tune ``zerolatency`` (no look-ahead, no frame delay), baseline profile, no
    B-frames, one thread (one slice per frame), an IDR frame every ``keyframe_interval``
    frames and never elsewhere (no scene-cut key frames), SPS and PPS before each, Annex B,
    ``bitrate_bps`` on average. The size is each frame's (640 × 360 for the AR.Drone 2.0's
    front camera); a frame of another size starts the stream again at an IDR frame.

    Headers: ``frame_number`` counts from ``first_frame_number``; ``timestamp_ms`` is the
    frame's capture time on the drone's clock; ``frame_type`` IDR or P; the encoded size in
    whole macroblocks and the display size the frame's; the stream byte position the
    payloads' bytes before this one; ``advertised_size`` the payload's size, as the drone sets
    it.
    """

    def __init__(self, rate_hz: float = 30.0, *, keyframe_interval: int = 30,
                 bitrate_bps: int = 1_000_000, first_frame_number: int = 0,
                 stream_id: int = STREAM_ID_H264_360P) -> None:
        if keyframe_interval < 1:
            raise ValueError(f"keyframe_interval {keyframe_interval}: at least 1")
        if not rate_hz > 0:
            raise ValueError(f"rate_hz {rate_hz}: positive expected")
        self.rate_hz = rate_hz
        self.keyframe_interval = keyframe_interval
        self.bitrate_bps = bitrate_bps
        self.stream_id = stream_id
        self._codec: av.VideoCodecContext | None = None
        self._size: tuple[int, int] | None = None  # (width, height) the codec is open for
        self._pts = 0  # frames given to the open codec
        self._next_number = first_frame_number
        self._position = 0  # payload bytes sent
        #: counts
        self.frames = 0
        self.key_frames = 0

    def _open(self, width_px: int, height_px: int) -> None:
        codec = av.CodecContext.create("libx264", "w")
        codec.width, codec.height = width_px, height_px
        codec.pix_fmt = "yuv420p"
        rate = Fraction(self.rate_hz).limit_denominator(1001)
        codec.time_base = 1 / rate
        codec.framerate = rate
        codec.bit_rate = self.bitrate_bps
        codec.thread_count = 1  # x264's sliced threads would cut a frame into slices
        n = self.keyframe_interval
        codec.options = {"preset": "ultrafast", "tune": "zerolatency", "profile": "baseline",
                         "x264-params": f"keyint={n}:min-keyint={n}:scenecut=0:bframes=0:"
                                        "repeat-headers=1:annexb=1"}
        codec.open()
        self._codec, self._size, self._pts = codec, (width_px, height_px), 0

    def encode_packets(self, image: np.ndarray,
                       capture_time_s: float) -> list[tuple[PaveHeader, bytes]]:
        """The packets for ``image`` (BGR, uint8, height × width × 3, even sizes) captured at
        ``capture_time_s`` on the drone's clock: (header, payload), one on this encoder."""
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"a BGR uint8 image expected, not {image.dtype} {image.shape}")
        height_px, width_px = image.shape[:2]
        if width_px % 2 or height_px % 2 or width_px > 0xFFFF or height_px > 0xFFFF:
            raise ValueError(f"a {width_px} × {height_px} image: H.264 4:2:0 needs even sizes")
        if self._size != (width_px, height_px):
            self._open(width_px, height_px)
        assert self._codec is not None
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        frame.pts = self._pts
        self._pts += 1
        timestamp_ms = round(capture_time_s * 1000.0) & 0xFFFFFFFF
        out = []
        for packet in self._codec.encode(frame):
            out.append(self._wrap(bytes(packet), packet.is_keyframe, timestamp_ms))
        self.frames += 1
        return out

    def encode(self, image: np.ndarray, capture_time_s: float) -> bytes:
        """The stream's bytes for ``image`` (see :meth:`encode_packets`): what the drone
        writes to the client's TCP connection."""
        return b"".join(build(header, payload)
                        for header, payload in self.encode_packets(image, capture_time_s))

    def _wrap(self, payload: bytes, key: bool, timestamp_ms: int) -> tuple[PaveHeader, bytes]:
        assert self._size is not None
        width_px, height_px = self._size
        sps_size, pps_size, slices = _parameter_sets(payload)
        header = PaveHeader(
            video_codec=Codec.MPEG4_AVC, payload_size=len(payload),
            encoded_stream_width_px=-(-width_px // _MACROBLOCK_PX) * _MACROBLOCK_PX,
            encoded_stream_height_px=-(-height_px // _MACROBLOCK_PX) * _MACROBLOCK_PX,
            display_width_px=width_px, display_height_px=height_px,
            frame_number=self._next_number & 0xFFFFFFFF, timestamp_ms=timestamp_ms,
            frame_type=FrameType.IDR if key else FrameType.P, control=Control.FRAME_DATA,
            stream_byte_position_lw=self._position & 0xFFFFFFFF,
            stream_byte_position_uw=self._position >> 32 & 0xFFFFFFFF,
            stream_id=self.stream_id, total_slices=max(1, slices), slice_index=0,
            header1_size=sps_size, header2_size=pps_size, advertised_size=len(payload))
        self._next_number += 1
        self._position += len(payload)
        self.key_frames += key
        return header, payload


@dataclass(frozen=True, slots=True)
class DecodedFrame:
    """A frame off the drone's stream: its number in the stream, its capture time on the
    drone's clock (the header's timestamp) and the image (BGR, uint8, the display size)."""

    frame_number: int
    time_s: float
    image: np.ndarray


class PaveDecoder:
    """PaVE packets, ``(header, payload)`` as :class:`~drivers.ardrone.pave.PaveReader`
    gives them, to images (PyAV's H.264 decoder, one thread: a frame out per packet in).

    It starts at the first key frame (IDR, or I with the parameter sets already seen), the
    P-frames before it dropped (:attr:`dropped_before_key`). A gap in the frame numbers (a
    lost packet: :attr:`gaps`) or a payload the decoder refuses (:attr:`decode_errors`)
    sends it back to waiting for a key frame, as ardrone_autonomy does: the P-frames in
    between would decode to smeared images. Packets without video (an advertisement, another
    codec) are skipped (:attr:`skipped`). :meth:`reset` starts over (a new connection).
    """

    def __init__(self) -> None:
        self._codec: av.VideoCodecContext | None = None
        self._awaiting_key = True
        self._last_number: int | None = None
        self._in_flight: dict[int, PaveHeader] = {}
        #: counts
        self.decoded = 0
        self.dropped_before_key = 0
        self.decode_errors = 0
        self.gaps = 0
        self.skipped = 0
        self.reset()

    @property
    def awaiting_key_frame(self) -> bool:
        return self._awaiting_key

    def reset(self) -> None:
        """Forget the stream: a new decoder, waiting for a key frame."""
        codec = av.CodecContext.create("h264", "r")
        codec.thread_count = 1  # frame threads would hold frames back
        codec.open()
        self._codec = codec
        self._awaiting_key = True
        self._last_number = None
        self._in_flight.clear()

    def decode(self, header: PaveHeader, payload: bytes) -> list[DecodedFrame]:
        """The frames this packet completes (none while waiting for a key frame)."""
        if (header.control & Control.FRAME_ADVERTISEMENT or not payload
                or header.video_codec != Codec.MPEG4_AVC):
            self.skipped += 1
            return []
        previous, self._last_number = self._last_number, header.frame_number
        if previous is not None and header.frame_number != (previous + 1) & 0xFFFFFFFF:
            self.gaps += 1
            self._awaiting_key = True
        if self._awaiting_key and not header.is_key_frame:
            self.dropped_before_key += 1
            return []
        assert self._codec is not None
        packet = av.Packet(payload)
        packet.pts = header.frame_number
        self._in_flight[header.frame_number] = header
        if len(self._in_flight) > _IN_FLIGHT:
            del self._in_flight[next(iter(self._in_flight))]
        try:
            frames = self._codec.decode(packet)
        except av.error.FFmpegError:
            self.decode_errors += 1
            self._awaiting_key = True
            return []
        self._awaiting_key = False
        return [self._frame(frame, header) for frame in frames]

    def _frame(self, frame: av.VideoFrame, header: PaveHeader) -> DecodedFrame:
        source = self._in_flight.pop(frame.pts, header) if frame.pts is not None else header
        image = frame.to_ndarray(format="bgr24")
        height_px, width_px = source.display_height_px, source.display_width_px
        if 0 < height_px <= image.shape[0] and 0 < width_px <= image.shape[1]:
            image = image[:height_px, :width_px]  # a stream whose SPS does not crop
        self.decoded += 1
        return DecodedFrame(source.frame_number, source.timestamp_s,
                            np.ascontiguousarray(image))

