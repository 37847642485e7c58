"""hover_image (seed 000) through the runtime on the lockstep clock: the down camera finds the
generated target on gravel and grass, and the vehicle holds the hover point over it; an image
out of view where the step starts is searched for (climb, expanding square) and found."""

import asyncio
import math

import numpy as np
import pytest

from autopilot.flightlog.log import read_log
from autopilot.flightlog.truth import truth_table
from autopilot.mission import load_mission
from autopilot.replay import replay
from autopilot.run import fly

from .simtools import searched


def test_hover_image_closed_loop_and_replay(tmp_path):
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10"])
    summary = asyncio.run(fly(plan, tmp_path, record_video="down"))
    assert summary["status"] == "completed"
    hover = summary["metrics"]["hover"]
    assert hover["detection_rate"] >= 0.98
    # the shipped (realistic) world: the vehicle holds its GNSS navigation's position to a few
    # centimetres (bench sitl), and that comes on top of the image estimate's error; the
    # issue's 0.05 m target is the bench's over five seeds (docs/benchmarks.md), with room here
    assert hover["rms_horizontal_error_m"] <= 0.08
    assert hover["rms_yaw_error_deg"] <= 2.0
    assert hover["scored_s"] >= 6.0
    assert summary["metrics"]["estimation"]["lost_share"] == 0.0
    # every down-camera frame logged: the replay's detector finds the image in the same frames
    again = replay(tmp_path)
    assert again["frames"]["replayed"] == again["frames"]["in_flight"]
    assert again["metrics"]["hover"]["detection_rate"] == hover["detection_rate"]
    assert again["metrics"]["hover"]["frames_in_view"] == hover["frames_in_view"]
    flown, replayed = summary["metrics"]["estimation"], again["metrics"]["estimation"]
    # (one marginal frame may go the other way on the JPEG: README's "within 1 %")
    assert replayed["at_update"]["estimates"] == pytest.approx(
        flown["at_update"]["estimates"], abs=max(1, 0.01 * flown["at_update"]["estimates"]))
    # (the replay reads the logged JPEGs: points tracked between full detections move by
    # fractions of a pixel with the compression, a few millimetres here)
    assert replayed["rms_position_error_m"] == pytest.approx(flown["rms_position_error_m"],
                                                             rel=0.15, abs=0.003)


@pytest.mark.parametrize(("north_east", "search"), [
    pytest.param((1.2, -1.6), False, marks=pytest.mark.long),  # 2 m: in view at once
    ((-2.0, 3.46), True),  # 4 m: out of view until the search's first ring
    pytest.param((4.0, -3.0), True, marks=pytest.mark.long),  # 5 m: its second ring
])
def test_an_image_2_to_5_m_away_is_found_and_hovered_over(tmp_path, north_east, search):
    n, e = north_east
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=6",
                                        f"scenario.image.north_east_m=[{n}, {e}]"])
    summary = asyncio.run(fly(plan, tmp_path))
    assert summary["status"] == "completed"
    hover = summary["metrics"]["hover"]
    assert hover["rms_horizontal_error_m"] <= 0.08  # (as above)
    assert hover["scored_s"] >= 2.5
    log = read_log(tmp_path / "flight.mcap")
    if search:
        # not found from where it began: it climbed to 4 m and flew out to find it
        assert hover["found_after_s"] > 2.0
        flown = searched(log, "hover_image")
        assert flown["up_m"] == pytest.approx(4.0)
        assert flown["out_m"] > 1.5
    else:
        assert hover["found_after_s"] < 1.0
    # and the vehicle ended over the image (truth), 2 m up
    track = truth_table(log).body("image")
    end = int(np.searchsorted(track.t, summary["metrics"]["steps"][0]["intervals"][0][1]))
    end = min(end, len(track) - 1)
    assert math.hypot(*(track.vehicle_p[end, :2] - track.p[end, :2])) <= 0.10
    assert track.p[end, 2] - track.vehicle_p[end, 2] == pytest.approx(2.0, abs=0.1)


def test_an_image_that_is_not_there_is_not_found_and_the_fallback_lands():
    plan = load_mission("hover_image", ["steps.1.hover_image.duration_s=10",
                                        "scenario.image.north_east_m=[30, 0]",
                                        "steps.1.hover_image.search_timeout_s=6"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "failed"
    assert "image not found in 6 s" in summary["reason"]
