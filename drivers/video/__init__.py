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

from drivers.video.rtcp import (
    Goodbye,
    RtcpPacket,
    SenderReport,
    SourceDescription,
    encode_goodbye,
    encode_sender_report,
    encode_source_description,
    ntp_from_unix,
    parse_rtcp,
    unix_from_ntp,
)
from drivers.video.rtp import (
    DEFAULT_HOST,
    FUTURE_TOLERANCE_S,
    MAPPING_STEP_S,
    MAX_PAYLOAD_B,
    NTP_UNIX_OFFSET_S,
    RTCP_INTERVAL_S,
    RTP_CLOCK_HZ,
    RTP_PAYLOAD_TYPE,
    SIM_CNAME,
    SIM_TOOL,
    TS_WRAP,
    TS_WRAP_S,
    RtpH264Depacketizer,
    RtpH264Packetizer,
    is_rtcp,
    rtp_ssrc,
    split_nal_units,
    ts_diff,
)
from drivers.video.sender import (
    VideoSender,
)
from drivers.video.source import (
    VideoSource,
    VideoStats,
    readable,
)
from drivers.video.timing import (
    CaptureClock,
    Stamp,
    TimeSource,
    remember,
)
from drivers.video.urls import (
    FFMPEG_SCHEMES,
    address_text,
    check_video_url,
    parse_source,
    rtp_address,
    url_source,
)

__all__ = [
    "DEFAULT_HOST",
    "FFMPEG_SCHEMES",
    "FUTURE_TOLERANCE_S",
    "MAPPING_STEP_S",
    "MAX_PAYLOAD_B",
    "NTP_UNIX_OFFSET_S",
    "RTCP_INTERVAL_S",
    "RTP_CLOCK_HZ",
    "RTP_PAYLOAD_TYPE",
    "SIM_CNAME",
    "SIM_TOOL",
    "TS_WRAP",
    "TS_WRAP_S",
    "CaptureClock",
    "Goodbye",
    "RtcpPacket",
    "RtpH264Depacketizer",
    "RtpH264Packetizer",
    "SenderReport",
    "SourceDescription",
    "Stamp",
    "TimeSource",
    "VideoSender",
    "VideoSource",
    "VideoStats",
    "address_text",
    "check_video_url",
    "encode_goodbye",
    "encode_sender_report",
    "encode_source_description",
    "is_rtcp",
    "ntp_from_unix",
    "parse_rtcp",
    "parse_source",
    "readable",
    "remember",
    "rtp_address",
    "rtp_ssrc",
    "split_nal_units",
    "ts_diff",
    "unix_from_ntp",
    "url_source",
]
