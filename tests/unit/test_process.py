"""Process and host measurements."""

import pytest

from autopilot import process


def test_steal_meter_reports_the_share_of_cpu_time_stolen_between_samples(monkeypatch):
    samples = iter([(1000, 10), (1400, 30)])  # (all ticks, stolen ticks)
    monkeypatch.setattr(process, "_cpu_ticks", lambda: next(samples))
    assert process.StealMeter().percent() == pytest.approx(5.0)


def test_steal_meter_is_unknown_without_proc_stat(monkeypatch):
    monkeypatch.setattr(process, "_cpu_ticks", lambda: None)
    assert process.StealMeter().percent() is None


def test_cpu_ticks_parse_this_machine():
    ticks = process._cpu_ticks()
    if ticks is None:
        pytest.skip("no /proc/stat here")
    total, stolen = ticks
    assert 0 <= stolen <= total
