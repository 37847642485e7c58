"""When a video frame was taken (:class:`~drivers.video.CaptureClock`): the vehicle's boot clock
only for a stream that says it is our simulator's, RTCP sender reports for a camera that sends
them, arrival time less the camera's latency otherwise, and one loud warning, not silently
useless frames, when a stream's own stamps are wrong."""

from __future__ import annotations

import logging
import math
import random

import pytest

from drivers.video import (
    MAPPING_STEP_S,
    RTP_CLOCK_HZ,
    SIM_CNAME,
    SIM_TOOL,
    CaptureClock,
    SenderReport,
    SourceDescription,
    TimeSource,
    encode_goodbye,
    encode_sender_report,
    encode_source_description,
)

pytestmark = pytest.mark.serial  # video timing on the wall clock

WALL_MINUS_LOCAL_S = 1_763_700_000.123  # time.time() − the local monotonic clock
RATE_HZ = 30.0
SSRC = 0x5EED_CAFE


def _ts(seconds: float, start: int = 0) -> int:
    return (start + round(seconds * RTP_CLOCK_HZ)) % (1 << 32)


def _rtcp(ssrc: int, wall_time_s: float, rtp_timestamp: int, cname: str | None = None) -> bytes:
    datagram = encode_sender_report(SenderReport(ssrc, wall_time_s, rtp_timestamp))
    if cname is not None:
        tool = SIM_TOOL if cname == SIM_CNAME else None
        datagram += encode_source_description(SourceDescription(ssrc, cname, tool))
    return datagram


def _warnings(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.levelno >= logging.WARNING]


def test_our_simulator_s_stream_is_read_on_the_vehicle_s_boot_clock():
    vehicle_to_local_s = 100.0
    clock = CaptureClock(to_local=lambda s: s + vehicle_to_local_s, latency_s=0.02)
    first_boot_s = 50.0
    # the simulator's reports carry its wall clock too; the boot clock comes first
    clock.feed_rtcp(_rtcp(SSRC, 0.0, _ts(first_boot_s), SIM_CNAME))
    for k in range(60):
        boot_s = first_boot_s + k / RATE_HZ
        arrival_s = boot_s + vehicle_to_local_s + 0.045
        stamp = clock.stamp(arrival_s, _ts(boot_s), ssrc=SSRC,
                            arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)
        assert stamp.source is TimeSource.VEHICLE_CLOCK
        assert stamp.time_s == pytest.approx(boot_s + vehicle_to_local_s, abs=1e-4)
    assert clock.ours
    assert clock.offset_s == pytest.approx(0.045, abs=1e-4)
    assert clock.counts[TimeSource.VEHICLE_CLOCK] == 60
    assert clock.fallback_reason is None


def test_the_boot_clock_is_unwrapped_past_13_hours():
    clock = CaptureClock(to_local=lambda s: s - 7.0)
    clock.feed_rtcp(encode_source_description(SourceDescription(SSRC, SIM_CNAME)))
    for boot_s in (47_721.0, 47_722.0, 50_000.0, 200_000.0):  # 2^32 / 90 kHz = 47 721.86 s
        stamp = clock.stamp(boot_s - 7.0 + 0.03, _ts(boot_s), ssrc=SSRC)
        assert stamp.source is TimeSource.VEHICLE_CLOCK
        assert stamp.time_s == pytest.approx(boot_s - 7.0, abs=1e-4)


def test_a_stream_that_does_not_say_it_is_ours_is_never_read_on_the_boot_clock():
    """A camera whose RTP clock happens to look like boot time, without RTCP: arrival time."""
    clock = CaptureClock(to_local=lambda s: s, latency_s=0.08)
    for k in range(10):
        arrival_s = 5.0 + k / RATE_HZ + 0.1
        stamp = clock.stamp(arrival_s, _ts(5.0 + k / RATE_HZ), ssrc=SSRC,
                            arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)
        assert stamp == (pytest.approx(arrival_s - 0.08), TimeSource.ARRIVAL)
    assert math.isnan(clock.offset_s)
    assert clock.counts == {TimeSource.VEHICLE_CLOCK: 0, TimeSource.RTCP: 0,
                            TimeSource.ARRIVAL: 10}


def test_our_stream_before_the_vehicle_clock_is_known_uses_its_sender_reports(caplog):
    clock = CaptureClock(to_local=lambda s: math.inf)  # no telemetry or TIMESYNC yet
    capture_s = 30.0
    clock.feed_rtcp(_rtcp(SSRC, capture_s + WALL_MINUS_LOCAL_S, _ts(12.0), SIM_CNAME))
    stamp = clock.stamp(capture_s + 0.05, _ts(12.0), ssrc=SSRC,
                        arrival_wall_s=capture_s + 0.05 + WALL_MINUS_LOCAL_S)
    assert stamp == (pytest.approx(capture_s, abs=1e-6), TimeSource.RTCP)
    no_reports = CaptureClock(to_local=lambda s: math.inf)
    no_reports.feed_rtcp(encode_source_description(SourceDescription(SSRC, SIM_CNAME)))
    assert no_reports.stamp(1.0, 123, ssrc=SSRC).source is TimeSource.ARRIVAL
    assert not _warnings(caplog)


@pytest.mark.parametrize("rtp_start", [random.getrandbits(32), (1 << 32) - 45_000],
                         ids=["random-start", "wraps-after-half-a-second"])
def test_a_camera_with_sender_reports_and_an_rtp_clock_starting_anywhere(rtp_start, caplog):
    """Its RTP clock starts at a random value (RFC 3550) and wraps past 2^32; each frame's
    capture time on its wall clock, which is ours, comes back on the local clock."""
    rng = random.Random(rtp_start)
    clock = CaptureClock(to_local=lambda s: s, latency_s=0.03)  # to_local: not for a camera
    first_capture_s = 1234.5
    stamps = []
    for k in range(120):  # 4 s: reports at 0, 1, 2, 3 s; the wrap between two of them
        capture_s = first_capture_s + k / RATE_HZ
        rtp = _ts(k / RATE_HZ, rtp_start)
        if k % 30 == 5:  # the first report comes after some frames
            clock.feed_rtcp(_rtcp(SSRC, capture_s + WALL_MINUS_LOCAL_S, rtp,
                                  "camera@192.168.144.25"))
        arrival_s = capture_s + 0.06 + rng.uniform(0.0, 0.03)  # network jitter
        stamp = clock.stamp(arrival_s, rtp, ssrc=SSRC,
                            arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)
        stamps.append((k, capture_s, arrival_s, stamp))
    for k, capture_s, arrival_s, stamp in stamps:
        if k < 5:  # no report yet: arrival less latency
            assert stamp == (pytest.approx(arrival_s - 0.03), TimeSource.ARRIVAL)
        else:
            assert stamp.source is TimeSource.RTCP
            assert stamp.time_s == pytest.approx(capture_s, abs=1e-3)
    assert not clock.ours
    assert not _warnings(caplog)


def test_without_sender_reports_frames_are_stamped_with_arrival_less_latency():
    clock = CaptureClock(latency_s=0.07)
    rtp_start = random.getrandbits(32)
    for k in range(30):
        arrival_s = 10.0 + k / RATE_HZ
        stamp = clock.stamp(arrival_s, _ts(k / RATE_HZ, rtp_start), ssrc=SSRC,
                            arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)
        assert stamp == (pytest.approx(arrival_s - 0.07), TimeSource.ARRIVAL)
    # a stream without RTP timestamps at all (FFmpeg's): the same
    assert clock.stamp(20.0) == (pytest.approx(19.93), TimeSource.ARRIVAL)


@pytest.mark.parametrize(("camera_clock_error_s", "says"),
                         [(3.0, "in the future"), (-10.0, "older than the 2 s pose history")])
def test_a_camera_with_a_wrong_wall_clock_is_reported_once_and_its_frames_still_come(
        camera_clock_error_s, says, caplog):
    clock = CaptureClock(latency_s=0.05, name="video front (udp://@:5600)")
    clock.sender = "10.0.0.2:5004"
    rtp_start = random.getrandbits(32)
    stamps = []
    for k in range(90):
        capture_s = 500.0 + k / RATE_HZ
        rtp = _ts(k / RATE_HZ, rtp_start)
        if k % 30 == 0:
            clock.feed_rtcp(_rtcp(SSRC, capture_s + WALL_MINUS_LOCAL_S + camera_clock_error_s,
                                  rtp, "camera"))
        arrival_s = capture_s + 0.08
        stamps.append((arrival_s, clock.stamp(arrival_s, rtp, ssrc=SSRC,
                                              arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)))
    assert len(stamps) == 90  # every frame is stamped: none is dropped for its stamp
    for arrival_s, stamp in stamps:
        assert stamp == (pytest.approx(arrival_s - 0.05), TimeSource.ARRIVAL)
    (warning,) = _warnings(caplog)
    message = warning.getMessage()
    assert says in message
    assert f"{abs(camera_clock_error_s) - 0.08 * math.copysign(1, camera_clock_error_s):.3f}" \
        in message  # the offset seen
    assert "video front (udp://@:5600)" in message
    assert f"{SSRC:#010x} from 10.0.0.2:5004" in message
    assert "arrival time − 0.050 s" in message  # what it falls back to
    assert "NTP" in message
    assert says in clock.fallback_reason
    assert clock.offset_s == pytest.approx(-camera_clock_error_s + 0.08, abs=1e-6)


def test_a_wrong_vehicle_clock_mapping_is_reported_once(caplog):
    clock = CaptureClock(to_local=lambda s: s + 10.0)  # 10 s off: a bad TIMESYNC
    clock.feed_rtcp(encode_source_description(SourceDescription(SSRC, SIM_CNAME)))
    for k in range(30):
        arrival_s = 3.0 + k / RATE_HZ
        stamp = clock.stamp(arrival_s, _ts(arrival_s - 0.04), ssrc=SSRC)
        assert stamp == (pytest.approx(arrival_s), TimeSource.ARRIVAL)
    (warning,) = _warnings(caplog)
    assert "vehicle's boot clock" in warning.getMessage()
    assert "TIMESYNC" in warning.getMessage()


def test_stamps_a_little_after_arrival_are_taken_as_the_arrival_time(caplog):
    clock = CaptureClock()
    clock.feed_rtcp(_rtcp(SSRC, 100.0 + WALL_MINUS_LOCAL_S, 0, "camera"))
    stamp = clock.stamp(99.998, 0, ssrc=SSRC, arrival_wall_s=99.998 + WALL_MINUS_LOCAL_S)
    assert stamp == (pytest.approx(99.998), TimeSource.RTCP)  # 2 ms: within clock accuracy
    assert not _warnings(caplog)


def test_a_corrected_clock_or_a_new_stream_is_judged_afresh(caplog):
    clock = CaptureClock(latency_s=0.05)

    def frame(k: int, ssrc: int = SSRC):
        arrival_s = 10.0 + k / RATE_HZ + 0.05
        return clock.stamp(arrival_s, _ts(k / RATE_HZ), ssrc=ssrc,
                           arrival_wall_s=arrival_s + WALL_MINUS_LOCAL_S)

    clock.feed_rtcp(_rtcp(SSRC, 10.0 + WALL_MINUS_LOCAL_S - 60.0, 0, "camera"))  # a minute slow
    assert frame(0).source is TimeSource.ARRIVAL
    # a report that moves the mapping by less than MAPPING_STEP_S is the same wrong clock
    clock.feed_rtcp(_rtcp(SSRC, 10.0 + WALL_MINUS_LOCAL_S - 60.0 + MAPPING_STEP_S / 2, 0))
    assert frame(1).source is TimeSource.ARRIVAL
    # the camera's clock is set (NTP): its stamps are used again
    clock.feed_rtcp(_rtcp(SSRC, 10.0 + WALL_MINUS_LOCAL_S, 0))
    assert frame(2) == (pytest.approx(10.0 + 2 / RATE_HZ), TimeSource.RTCP)
    assert clock.fallback_reason is None
    assert len(_warnings(caplog)) == 1
    # the camera restarts (a new SSRC) with its clock wrong again: one more warning
    clock.feed_rtcp(encode_goodbye(SSRC))
    clock.feed_rtcp(_rtcp(SSRC + 1, 10.0 + WALL_MINUS_LOCAL_S + 5.0, 0, "camera"))
    assert frame(3, SSRC + 1).source is TimeSource.ARRIVAL
    assert frame(4, SSRC + 1).source is TimeSource.ARRIVAL
    assert len(_warnings(caplog)) == 2


def test_the_latency_must_fit_in_the_pose_history():
    for latency_s in (-0.01, 2.0, 5.0):
        with pytest.raises(ValueError, match="latency_s"):
            CaptureClock(latency_s=latency_s)
    assert CaptureClock(latency_s=0.5, max_age_s=3.0).latency_s == 0.5
