"""What MAVSDK is shown of the streams the MAVSDK driver reads itself: each kind at most
MAVSDK_STREAM_HZ, every other kind untouched (drivers/mavlink/mavsdk_driver.py)."""

from __future__ import annotations

from drivers.mavlink.mavsdk_driver import MAVSDK_STREAM_HZ, MAVSDK_THINNED, StreamThinner


def test_px4_rates_reach_mavsdk_thinned_and_the_rest_whole() -> None:
    thinner = StreamThinner(MAVSDK_THINNED, MAVSDK_STREAM_HZ)
    passed: dict[str, int] = {}
    for i in range(1000):  # 10 s at 100 Hz ticks
        t = i * 0.01
        for kind, every in (("ATTITUDE_QUATERNION", 2), ("LOCAL_POSITION_NED", 3),
                            ("HEARTBEAT", 100), ("COMMAND_ACK", 7), ("SYS_STATUS", 20)):
            if i % every == 0 and thinner.passes(kind, t):
                passed[kind] = passed.get(kind, 0) + 1
    assert 35 <= passed["ATTITUDE_QUATERNION"] <= 41  # 50 Hz in, about 4 Hz out
    assert 35 <= passed["LOCAL_POSITION_NED"] <= 41
    assert passed["HEARTBEAT"] == 10
    assert passed["SYS_STATUS"] == 50
    assert passed["COMMAND_ACK"] == len(range(0, 1000, 7))
    assert thinner.held_back == 500 + 334 - passed["ATTITUDE_QUATERNION"] \
        - passed["LOCAL_POSITION_NED"]


def test_the_first_of_each_kind_passes_and_a_clock_gone_back_restarts() -> None:
    thinner = StreamThinner(frozenset({"ATTITUDE"}), 4.0)
    assert thinner.passes("ATTITUDE", 100.0)
    assert not thinner.passes("ATTITUDE", 100.1)
    assert thinner.passes("ATTITUDE", 100.26)
    assert thinner.passes("ATTITUDE", 3.0)  # the clock restarted (a new run's)
    assert not thinner.passes("ATTITUDE", 3.1)


def test_mavsdk_still_sees_what_its_health_and_calls_are_made_of() -> None:
    # MAVSDK's health (local position ok) and command acks come from these: never thinned
    # beyond the rate above, and the acknowledgements and status never at all
    assert "LOCAL_POSITION_NED" in MAVSDK_THINNED
    assert MAVSDK_STREAM_HZ >= 1.0
    assert not MAVSDK_THINNED & {"HEARTBEAT", "SYS_STATUS", "COMMAND_ACK", "EXTENDED_SYS_STATE",
                                 "BATTERY_STATUS", "DISTANCE_SENSOR", "STATUSTEXT",
                                 "HOME_POSITION", "PARAM_VALUE", "MISSION_ACK", "TIMESYNC"}
