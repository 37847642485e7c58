"""hover_image (seed 000) through the runtime on the lockstep clock: the down camera finds the
generated target on gravel and grass, and the vehicle holds the hover point over it."""

import asyncio

import pytest

from autopilot.mission import load_mission
from autopilot.replay import replay
from autopilot.run import fly


def test_hover_image_closed_loop_and_replay(tmp_path):
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10"])
    summary = asyncio.run(fly(plan, tmp_path, record_video="down"))
    assert summary["status"] == "completed"
    hover = summary["metrics"]["hover"]
    assert hover["detection_rate"] >= 0.98
    assert hover["rms_horizontal_error_m"] <= 0.05
    assert hover["rms_yaw_error_deg"] <= 2.0
    assert hover["scored_s"] >= 6.0
    assert summary["metrics"]["estimation"]["lost_share"] == 0.0
    # every down-camera frame logged: the replay's detector finds the image in the same frames
    again = replay(tmp_path)
    assert again["frames"]["replayed"] == again["frames"]["in_flight"]
    assert again["metrics"]["hover"]["detection_rate"] == hover["detection_rate"]
    assert again["metrics"]["hover"]["frames_in_view"] == hover["frames_in_view"]
    flown, replayed = summary["metrics"]["estimation"], again["metrics"]["estimation"]
    assert replayed["at_update"]["estimates"] == flown["at_update"]["estimates"]
    # (the replay reads the logged JPEGs: points tracked between full detections move by
    # fractions of a pixel with the compression, a few millimetres here)
    assert replayed["rms_position_error_m"] == pytest.approx(flown["rms_position_error_m"],
                                                             rel=0.15, abs=0.003)


def test_an_image_that_is_not_there_is_not_found_and_the_fallback_lands():
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10",
                                        "scenario.image.north_east_m=[30, 0]",
                                        "control.follow.lost_timeout_s=2"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "failed"
    assert "image not found" in summary["reason"]
