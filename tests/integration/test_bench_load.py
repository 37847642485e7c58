"""``autopilot bench load --hogs 0`` end to end: a real-time MAVSDK flight against
``autopilot sim`` with the console watched, every process it started gone afterwards.

Long (--run-long): a real-time flight whose wall time is one to several minutes, depending on
how busy the machine is."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from autopilot.bench import load, load_figures

pytestmark = [
    pytest.mark.serial,  # busy processes against a real-time flight
    pytest.mark.long,
    pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="the bench needs two cores"),
]


def _processes_mentioning(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if text in (entry / "cmdline").read_bytes().decode(errors="replace"):
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def test_one_load_flies_and_leaves_nothing_running(tmp_path):
    result = load.run_bench([0], follow_s=5.0, out=tmp_path)
    assert not _processes_mentioning(str(tmp_path))  # vehicle, autopilot, viewer all ended
    (row,) = result["rows"]
    assert row["hogs"] == 0
    rtf = row["vehicle_real_time_factor"]
    assert rtf is not None, "the vehicle printed no events: it never flew"
    if rtf < load_figures.VEHICLE_REAL_TIME:
        pytest.skip(f"this machine is too busy: the vehicle, on a core of its own, ran at "
                    f"{rtf:.2f}× real time ({row['why']})")
    assert row["completed"], row["why"]
    assert row["tick_ms_p99"] <= result["tick_p99_limit_ms"]
    assert row["latency_ms_p95"] is not None
    assert row["perception_frames"] > 30
    assert row["console_frames_due"] > 0
    assert row["rms_range_error_m"] < 0.3
