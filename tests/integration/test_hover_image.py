"""hover_image (seed 000) through the runtime on the lockstep clock: the down camera finds the
generated target on gravel and grass, and the vehicle holds the hover point over it."""

import asyncio

from autopilot.mission import load_mission
from autopilot.run import fly


def test_hover_image_closed_loop():
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "completed"
    hover = summary["metrics"]["hover"]
    assert hover["detection_rate"] >= 0.98
    assert hover["rms_horizontal_error_m"] <= 0.05
    assert hover["rms_yaw_error_deg"] <= 2.0
    assert hover["scored_s"] >= 6.0
    assert summary["metrics"]["estimation"]["lost_share"] == 0.0


def test_an_image_that_is_not_there_is_not_found_and_the_fallback_lands():
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10",
                                        "scenario.image.north_east_m=[30, 0]",
                                        "control.follow.lost_timeout_s=2"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "failed"
    assert "image not found" in summary["reason"]
