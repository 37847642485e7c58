"""When a frame was taken: :class:`CaptureClock` picks the best source a stream offers (the
simulator's convention, RTCP sender reports, or arrival less the camera's latency)."""


import enum
import logging
import math
from collections.abc import Callable
from typing import NamedTuple

from drivers.video.rtcp import Goodbye, RtcpPacket, SenderReport, SourceDescription, parse_rtcp
from drivers.video.rtp import (
    FUTURE_TOLERANCE_S,
    MAPPING_STEP_S,
    RTP_CLOCK_HZ,
    SIM_CNAME,
    TS_WRAP_S,
    ts_diff,
)

log = logging.getLogger(__name__)

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
                remember(self._reports, packet.ssrc, packet)
            elif isinstance(packet, SourceDescription) and packet.cname is not None:
                remember(self._cnames, packet.ssrc, packet.cname)
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
                ts_diff(rtp_timestamp, report.rtp_timestamp) / RTP_CLOCK_HZ
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
        wraps = round((arrival_s - local_s) / TS_WRAP_S)
        if wraps:
            local_s = self.to_local(sent_s + wraps * TS_WRAP_S)
        return local_s if math.isfinite(local_s) else None

    def _unwrap(self, rtp_timestamp: int) -> int:
        if self._last_ts is not None:
            self._extended += ts_diff(rtp_timestamp, self._last_ts)
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


def remember(table: dict, key, value, size: int = 8) -> None:
    """``table[key] = value``, forgetting the oldest entries beyond ``size`` (a bound on what
    a flood of made-up sources can make us keep)."""
    table.pop(key, None)
    table[key] = value
    while len(table) > size:
        del table[next(iter(table))]


# --------------------------------------------------------------------------------------------
# Sending and receiving
# --------------------------------------------------------------------------------------------
