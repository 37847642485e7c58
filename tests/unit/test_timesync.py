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


def test_a_lagging_vehicle_clock_is_followed_not_held_to_its_best_round_trip():
    # a simulated vehicle on a starved CPU: its clock runs at half the local rate. The first
    # exchange has the shortest round trip ever seen; later ones prove its offset wrong.
    m = BootTimeMapper()
    m.observe_sync(10.0, 0.0005, 10.001)
    assert not m.settling
    for i in range(1, 30):
        sent = 10.0 + 0.1 * i
        vehicle_answer = 0.5 * (sent + 0.001 - 10.0)  # answered on the way back
        m.observe_sync(sent, vehicle_answer, sent + 0.002)
        local_now = sent + 0.002
        # the vehicle time just answered maps within one round trip of when it was answered
        assert abs(m.to_local(vehicle_answer) - (sent + 0.001)) <= 0.002 + 1e-9
    assert m.settling  # so the drivers ask ten times a second
    assert local_now > 12.0


def test_telemetry_that_would_arrive_before_its_capture_lowers_a_synced_offset():
    m = BootTimeMapper(drift_per_s=0.0)
    m.observe_sync(50.0, 50.0 - OFFSET + 0.001, 50.010)  # way back slow: offset 4 ms high
    assert m.to_local(60.0 - OFFSET) == pytest.approx(60.004)
    m.observe(60.0 - OFFSET, 60.001)  # arrived 1 ms after capture by the truth
    assert m.to_local(60.0 - OFFSET) == pytest.approx(60.001)
    m.observe(61.0 - OFFSET, 61.003)  # a later, slower sample does not raise it
    assert m.to_local(61.0 - OFFSET) == pytest.approx(61.001)


def test_the_drivers_ask_often_while_the_vehicle_clock_moves():
    from drivers.mavlink import px4

    assert px4.timesync_period_s(100) == 1.0
    assert px4.timesync_period_s(100, settling=True) == 0.1
    assert px4.timesync_period_s(3) == 0.1


def test_an_asymmetric_exchange_moves_a_good_mapping_only_as_far_as_it_proves():
    m = BootTimeMapper(drift_per_s=0.0)
    m.observe_sync(50.0, 50.0 - OFFSET + 0.0015, 50.002)  # 1.5 ms there, 0.5 back: 0.5 ms low
    # way there 0.1 ms, back 30 ms: the offset must be at least OFFSET − 0.1 ms
    m.observe_sync(60.0, 60.0 - OFFSET + 0.0001, 60.0301)
    assert m.to_local(0.0) == pytest.approx(OFFSET - 0.0001, abs=1e-9)  # not its 15 ms midpoint
