"""The simulated flight stack's rangefinder (drivers.sim.flight.range_gate): an outlier never
reaches the land detector or the navigator — the prediction stands in — while a real change of
the ground (readings that agree, for a while) is taken, and no reading stays no reading."""

from __future__ import annotations

import math

import pytest

from drivers.sim.flight.range_gate import PERSIST_S, RangeGate


def test_an_outlier_under_a_vehicle_on_the_ground_is_set_aside() -> None:
    gate = RangeGate()
    # on the ground: below the sensor's minimum range (NaN), then a missed return (its 12 m)
    assert math.isnan(gate.update(0.0, math.nan, 0.0, 0.05))
    assert gate.update(0.02, 12.0, 0.0, 0.05) == pytest.approx(0.05)
    assert math.isnan(gate.update(0.04, math.nan, 0.0, 0.05))
    # outliers far apart never add up to a change of the ground
    for k in range(50):
        assert gate.update(0.1 + k, 12.0, 0.0, 0.05) < 1.0
    assert gate.rejected == 51


def test_readings_follow_the_vehicle_and_a_short_outlier_is_bridged() -> None:
    gate = RangeGate()
    t, h = 0.0, 2.0
    for _ in range(20):  # climbing at 1 m/s (NED: vz = -1)
        t, h = t + 0.02, h + 0.02
        assert gate.update(t, h, -1.0, h) == pytest.approx(h)
    got = gate.update(t + 0.02, 0.3, -1.0, h)  # debris: a short reading
    assert got == pytest.approx(h + 0.02)  # the prediction stands in


def test_a_real_step_of_the_ground_is_taken_once_it_persists() -> None:
    gate = RangeGate()
    t = 0.0
    for _ in range(10):
        t += 0.02
        gate.update(t, 3.0, 0.0, 3.0)
    # over a 1.2 m deck: 1.8 m from now on
    first = t + 0.02
    while t < first + PERSIST_S - 0.03:
        t += 0.02
        assert gate.update(t, 1.8, 0.0, 3.0) == pytest.approx(3.0)
    t += 0.04
    assert gate.update(t, 1.8, 0.0, 3.0) == pytest.approx(1.8)
    assert gate.update(t + 0.02, 1.81, 0.0, 3.0) == pytest.approx(1.81)
