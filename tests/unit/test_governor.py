"""The load governor: the console's viewers, then perception, yield frames to control while the
event loop runs late, and take them all again once it is on time
(autopilot/runtime/governor.py)."""

from __future__ import annotations

import pytest

from autopilot.config import load_config
from autopilot.runtime.governor import GovernorSettings, LoadGovernor

SETTINGS = GovernorSettings(late_s=0.008, on_time_s=0.003, decrease=0.75, increase=0.04,
                            min_share=0.25, viewer_min_share=0.1)


def taken(governor: LoadGovernor, lane: str, frames: int) -> int:
    return sum(governor.take(lane) for _ in range(frames))


def test_an_on_time_loop_takes_every_frame() -> None:
    g = LoadGovernor(SETTINGS)
    for _ in range(100):
        g.observe_lag(0.001)
    assert taken(g, "front", 300) == 300
    assert taken(g, "console:front", 300) == 300
    assert g.skipped == {}
    assert g.lowest_share == 1.0
    assert g.late_beats == 0


def test_the_viewers_yield_first_and_perception_only_once_they_are_at_their_floor() -> None:
    g = LoadGovernor(SETTINGS)
    g.observe_lag(0.025)  # level 0.75
    assert g.lane_share("console:front") == pytest.approx(0.5)
    assert g.lane_share("front") == 1.0
    assert g.lowest_share == 1.0  # (perception's: untouched so far)
    g.observe_lag(0.030)  # level 0.5625
    assert g.lane_share("console:front") == pytest.approx(0.125)
    assert g.lane_share("down") == 1.0
    g.observe_lag(0.030)  # level 0.42
    assert g.lane_share("console:front") == pytest.approx(0.1)  # its floor
    assert g.lane_share("front") == pytest.approx(0.84375)
    assert g.lowest_share == pytest.approx(0.84375)


def test_late_beats_bring_perception_down_to_its_floor_with_frames_spread_evenly() -> None:
    g = LoadGovernor(SETTINGS)
    for _ in range(50):
        g.observe_lag(0.050)
    assert g.lane_share("front") == pytest.approx(0.25)
    assert g.lowest_share == pytest.approx(0.25)
    pattern = [g.take("front") for _ in range(400)]
    assert pattern[0]  # (the first frame is taken)
    assert sum(pattern) == pytest.approx(100, abs=1)
    assert all(sum(pattern[i:i + 4]) == 1 for i in range(1, 397, 4))  # one in four, evenly
    assert g.skipped["front"] == 400 - sum(pattern)
    assert taken(g, "console:front", 100) == pytest.approx(10, abs=1)


def test_beats_between_the_thresholds_keep_the_level_and_on_time_beats_bring_it_back() -> None:
    g = LoadGovernor(SETTINGS)
    for _ in range(10):
        g.observe_lag(0.1)
    low = g.share
    g.observe_lag(0.005)  # neither late nor on time
    assert g.share == low
    for _ in range(100):
        g.observe_lag(0.0)
    assert g.share == 1.0
    assert g.lane_share("front") == g.lane_share("console:front") == 1.0
    assert g.late_beats == 10


def test_lanes_are_counted_apart() -> None:
    g = LoadGovernor(SETTINGS)
    for _ in range(3):
        g.observe_lag(1.0)  # level 0.42: perception 0.84, viewers 0.1
    a, b = taken(g, "front", 100), taken(g, "down", 100)
    c = taken(g, "console:front", 100)
    assert a == b == pytest.approx(84, abs=1)
    assert c == pytest.approx(10, abs=1)
    assert g.skipped == {"front": 100 - a, "down": 100 - b, "console:front": 100 - c}


def test_from_the_configuration_and_off() -> None:
    cfg = load_config().runtime.yield_to_control
    g = LoadGovernor.from_config(cfg)
    assert g is not None
    assert g.settings.late_s == pytest.approx(cfg.late_ms / 1e3)
    assert g.settings.on_time_s == pytest.approx(cfg.on_time_ms / 1e3)
    assert g.settings.min_share == cfg.min_share
    assert g.settings.viewer_min_share == cfg.viewer_min_share
    assert LoadGovernor.from_config(cfg.model_copy(update={"enabled": False})) is None


def test_on_time_must_be_below_late() -> None:
    with pytest.raises(Exception, match="on_time_ms"):
        load_config(overrides=["runtime.yield_to_control.on_time_ms=9"])
