"""The soak's machinery on a short flight (``autopilot bench soak`` flies the hour): missions
back to back in one process leave no task, thread or file descriptor behind."""

from __future__ import annotations

import asyncio

from autopilot.bench.soak import soak


def test_missions_back_to_back_leave_nothing_behind():
    # (leaks, not figures: the ideal world's land_pad is short enough for two in 20 s)
    result = asyncio.run(soak(20.0, missions=("land_pad",), overrides=["sim.profile=ideal"]))
    assert len(result["runs"]) == 2  # the baseline after the first, the end after the second
    assert all(r["outcome"] == "completed" for r in result["runs"])
    assert result["tasks_ok"]
    assert result["threads_ok"], result["new_threads"]
    assert result["fds_ok"]
    assert result["end"]["tasks"] == 0
    # every run measured its event loop's lag
    assert all(r["loop_lag_p99_ms"] is not None for r in result["runs"])
