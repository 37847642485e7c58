"""In real time, perception and the console yield frames to control while the event loop runs
late (autopilot/runtime/governor.py), end to end: a flight whose every watchdog beat counts as
late (``late_ms`` below any loop's lag) takes a quarter of its frames, still follows, and says
so in its summary. (The load itself is `autopilot bench load`'s: docs/reliability.md.)"""

from __future__ import annotations

import pytest

from .simtools import fly_short

pytestmark = pytest.mark.serial


def test_a_late_loop_takes_a_quarter_of_the_frames_and_still_follows(tmp_path) -> None:
    summary, orphans = fly_short(["runtime.yield_to_control.late_ms=0.001",
                                  "runtime.yield_to_control.on_time_ms=0",
                                  "runtime.yield_to_control.min_share=0.25",
                                  "steps.1.follow_ball.duration_s=12"], tmp_path, realtime=True)
    assert orphans == []
    assert summary["status"] == "completed", summary.get("reason")
    stats = summary["stats"]
    assert stats["lowest_frame_share"] == pytest.approx(0.25)
    assert stats["frames_yielded"].get("front", 0) > 0
    # of the frames the follow step's camera gave, about a quarter were processed
    rate = 30.0
    processed, skipped = stats["frames"], stats["frames_yielded"]["front"]
    assert processed > 0
    assert 0.15 <= processed / (processed + skipped) <= 0.4
    assert summary["metrics"]["follow"]["detection_rate"] >= 0.9
    assert processed + skipped <= 12 * rate * 1.1


def test_lockstep_takes_every_frame(tmp_path) -> None:
    summary, _ = fly_short(["runtime.yield_to_control.late_ms=0.001",
                            "runtime.yield_to_control.on_time_ms=0",
                            "steps.1.follow_ball.duration_s=5"], tmp_path)
    assert summary["status"] == "completed"
    assert summary["stats"]["frames_yielded"] == {}
    assert summary["stats"]["lowest_frame_share"] is None
