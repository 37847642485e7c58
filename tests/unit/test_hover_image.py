"""The hover_image behaviour: the hover point over the image; the search until it is found;
holding while it is lost, then searching again around it, a bounded number of times."""

import math

import numpy as np
import pytest

from autopilot.behaviors.base import BehaviorInputs, RequestKind, Status
from autopilot.behaviors.hover_image import (
    HoverImage,
    HoverImageParams,
    HoverSettings,
    hover_point,
)
from autopilot.estimation.target import TargetEstimate

from ..factories import vehicle_state


def _image(t, centre=(3.0, 1.0, 0.0), heading=0.5, age=0.0):
    return TargetEstimate(t, np.array(centre, float), np.zeros(3), np.eye(6) * 1e-4, age,
                          False, 20, True, kind="image", heading_rad=heading)


def test_hover_point_is_fixed_to_the_image():
    params = HoverImageParams(duration_s=1, altitude_m=2.0, offset_m=(1.0, 0.5))
    # top to the east: forward is east, right is south
    p = hover_point(np.array([3.0, 1.0, -0.002]), math.pi / 2, params)
    assert p == pytest.approx([3.0 - 0.5, 1.0 + 1.0, -2.002])


def test_searches_hovers_holds_when_lost_searches_again_then_fails():
    params = HoverImageParams(duration_s=30, altitude_m=2.0, yaw_deg=90.0, max_retries=1)
    hover = HoverImage(params, HoverSettings(lost_after_s=0.5, lost_timeout_s=3.0))
    state = vehicle_state(0.0, pos=(0.0, 0.0, -2.0))
    out = hover.activate(BehaviorInputs(0.0, state))
    assert out.requests[0].kind is RequestKind.START_OFFBOARD
    assert out.phase == "searching"
    out = hover.update(BehaviorInputs(0.5, state))
    assert out.phase == "searching"
    assert out.setpoint.position_ned_m == pytest.approx((0.0, 0.0, -4.0))  # up for a wider view
    out = hover.update(BehaviorInputs(1.0, state, target=_image(1.0)))
    assert out.phase == "hovering"
    assert out.setpoint.position_ned_m == pytest.approx((3.0, 1.0, -2.0))
    assert out.setpoint.yaw_rad == pytest.approx(0.5 + math.pi / 2)
    # lost: hold the last hover point; lost for lost_timeout_s: search again around the image
    over = vehicle_state(2.0, pos=(3.0, 1.0, -2.0))
    out = hover.update(BehaviorInputs(2.0, over, target=_image(1.0, age=1.0)))
    assert out.phase == "lost"
    assert out.status is Status.RUNNING
    assert out.setpoint.position_ned_m == pytest.approx((3.0, 1.0, -2.0))
    out = hover.update(BehaviorInputs(3.9, over))
    assert out.phase == "lost"
    out = hover.update(BehaviorInputs(4.1, over))
    assert out.phase == "searching"
    assert out.status is Status.RUNNING
    assert hover.retries == 1
    assert out.setpoint.position_ned_m == pytest.approx((3.0, 1.0, -4.0))
    assert out.setpoint.yaw_rad == pytest.approx(0.5 + math.pi / 2)  # the heading kept
    out = hover.update(BehaviorInputs(6.0, over, target=_image(6.0)))  # found again
    assert out.phase == "hovering"
    out = hover.update(BehaviorInputs(9.5, over))  # lost again: no searches left
    assert out.phase == "lost"
    out = hover.update(BehaviorInputs(9.6, over))
    assert out.status is Status.FAILED
    assert "image lost for 3.6 s (1 searches again)" in out.reason


def test_the_search_times_out_found_or_not_and_the_hover_lasts_from_when_it_was_found():
    params = HoverImageParams(duration_s=5, search_timeout_s=20.0)
    state = vehicle_state(0.0)
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    assert hover.update(BehaviorInputs(19.9, state)).status is Status.RUNNING
    out = hover.update(BehaviorInputs(20.1, state))
    assert out.status is Status.FAILED
    assert "image not found in 20 s" in out.reason
    # found after 12 s of searching: hovers 5 s from then
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    assert hover.update(BehaviorInputs(12.0, state, target=_image(12.0))).phase == "hovering"
    assert hover.update(BehaviorInputs(16.9, state, target=_image(16.9))).status is \
        Status.RUNNING
    assert hover.update(BehaviorInputs(17.0, state, target=_image(17.0))).status is \
        Status.SUCCEEDED
    # lost, searched for again, not found: the search's timeout (the hover's 5 s are over,
    # but not over the image)
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    hover.update(BehaviorInputs(1.0, state, target=_image(1.0)))
    assert hover.update(BehaviorInputs(4.1, state)).phase == "searching"
    assert hover.update(BehaviorInputs(24.0, state)).status is Status.RUNNING
    out = hover.update(BehaviorInputs(24.2, state))
    assert out.status is Status.FAILED
    assert "image lost and not found again in 20 s" in out.reason
    # found again after the 5 s: over it, the hover is over
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    hover.update(BehaviorInputs(1.0, state, target=_image(1.0)))
    hover.update(BehaviorInputs(4.1, state))
    assert hover.update(BehaviorInputs(9.0, state, target=_image(9.0))).status is \
        Status.SUCCEEDED


@pytest.mark.parametrize(("override", "message"), [
    ("steps.1.hover_image.search_altitude_m=0", "search_altitude_m"),
    ("steps.1.hover_image.search_radius_m=-1", "search_radius_m"),
    ("steps.1.hover_image.search_timeout_s=0", "search_timeout_s"),
    ("steps.1.hover_image.search_speed_m_s=20", "search_speed_m_s"),
    ("steps.1.hover_image.max_retries=-1", "max_retries"),
])
def test_bad_search_parameters_are_named(override, message):
    from autopilot.config import ConfigError
    from autopilot.mission import load_mission

    with pytest.raises(ConfigError) as err:
        load_mission("hover_image", [override])
    assert message in str(err.value)


def test_an_image_file_that_cannot_be_read_is_refused_before_flying(tmp_path):
    from autopilot.config import ConfigError
    from autopilot.mission import load_mission

    with pytest.raises(ConfigError, match=r"hover_image\.image.*no such image file"):
        load_mission("hover_image", [f"steps.1.hover_image.image={tmp_path / 'nope.png'}"])
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ConfigError, match="not an image OpenCV can read"):
        load_mission("hover_image", [f"steps.1.hover_image.image={tmp_path / 'text.png'}"])
