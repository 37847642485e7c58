"""Vehicle boot time → local time: telemetry bound first, TIMESYNC round trips when there."""

import pytest

from drivers.mavlink.link import BootTimeMapper

OFFSET = 100.0  # local = vehicle + 100 s


def test_telemetry_alone_gives_the_smallest_delay_seen():
    m = BootTimeMapper()
    assert not m.ready
    for vehicle_s, delay in ((1.0, 0.030), (1.02, 0.012), (1.04, 0.020)):
        m.observe(vehicle_s, vehicle_s + OFFSET + delay)
    assert m.to_local(2.0) == pytest.approx(2.0 + OFFSET + 0.012)  # still late by 12 ms


def test_timesync_uses_the_shortest_round_trip_and_overrides_telemetry():
    m = BootTimeMapper(drift_per_s=0.0)
    m.observe(1.0, 1.0 + OFFSET + 0.015)
    # (sent, vehicle time when answered, received); way there 1 ms / 9 ms, way back 1 ms
    m.observe_sync(50.0, 50.0 - OFFSET + 0.009, 50.010)  # asymmetric: 4 ms off
    m.observe_sync(51.0, 51.0 - OFFSET + 0.001, 51.002)  # symmetric, shorter: exact
    m.observe_sync(52.0, 52.0 - OFFSET + 0.006, 52.007)  # longer round trip: ignored
    assert m.round_trip_s == pytest.approx(0.002)
    assert m.to_local(10.0) == pytest.approx(10.0 + OFFSET, abs=1e-9)
    m.observe(11.0, 11.0 + OFFSET + 0.0001)  # telemetry no longer moves it
    assert m.to_local(10.0) == pytest.approx(10.0 + OFFSET, abs=1e-9)


def test_a_rebooted_vehicle_resets_the_mapping():
    m = BootTimeMapper()
    m.observe_sync(50.0, 40.0, 50.002)
    m.observe(40.5, 50.51)
    m.observe(0.5, 60.52)  # boot time jumped back: rebooted
    assert m.to_local(0.5) == pytest.approx(60.52)
