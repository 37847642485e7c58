"""Process and host measurements."""

import subprocess
import sys

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


def test_a_native_crash_in_flight_prints_the_stacks():
    """(configure_for_flight turns on Python's faulthandler: a flight that dies in native
    code says where)"""
    code = ("import ctypes\n"
            "from autopilot.process import configure_for_flight\n"
            "configure_for_flight()\n"
            "def in_flight():\n"
            "    ctypes.string_at(0)\n"
            "in_flight()\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode != 0
    assert "Fatal Python error: Segmentation fault" in out.stderr
    assert "in in_flight" in out.stderr
