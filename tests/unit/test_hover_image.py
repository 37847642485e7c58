"""The hover_image behaviour: the hover point over the image, holding while it is not seen,
failing when it stays lost."""

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


def test_hovers_over_the_image_then_holds_when_it_is_lost_then_fails():
    params = HoverImageParams(duration_s=30, altitude_m=2.0, yaw_deg=90.0)
    hover = HoverImage(params, HoverSettings(lost_after_s=0.5, lost_timeout_s=3.0))
    state = vehicle_state(0.0, pos=(0.0, 0.0, -2.0))
    out = hover.activate(BehaviorInputs(0.0, state))
    assert out.requests[0].kind is RequestKind.START_OFFBOARD
    assert out.phase == "searching"
    out = hover.update(BehaviorInputs(1.0, state, target=_image(1.0)))
    assert out.phase == "hovering"
    assert out.setpoint.position_ned_m == pytest.approx((3.0, 1.0, -2.0))
    assert out.setpoint.yaw_rad == pytest.approx(0.5 + math.pi / 2)
    # lost: hold the last hover point; fail once lost for lost_timeout_s
    out = hover.update(BehaviorInputs(2.0, state, target=_image(1.0, age=1.0)))
    assert out.phase == "lost"
    assert out.status is Status.RUNNING
    assert out.setpoint.position_ned_m == pytest.approx((3.0, 1.0, -2.0))
    out = hover.update(BehaviorInputs(4.1, state))
    assert out.status is Status.FAILED
    assert "image lost" in out.reason


def test_an_image_never_found_fails_and_a_long_enough_hover_succeeds():
    params = HoverImageParams(duration_s=5)
    state = vehicle_state(0.0)
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    assert hover.update(BehaviorInputs(2.0, state)).status is Status.RUNNING
    out = hover.update(BehaviorInputs(3.5, state))
    assert out.status is Status.FAILED
    assert "not found" in out.reason
    hover = HoverImage(params, HoverSettings(0.5, 3.0))
    hover.activate(BehaviorInputs(0.0, state))
    assert hover.update(BehaviorInputs(5.0, state, target=_image(5.0))).status is \
        Status.SUCCEEDED


def test_an_image_file_that_cannot_be_read_is_refused_before_flying(tmp_path):
    from autopilot.config import ConfigError
    from autopilot.mission import load_mission

    with pytest.raises(ConfigError, match=r"hover_image\.image.*no such image file"):
        load_mission("hover_image", [f"steps.1.hover_image.image={tmp_path / 'nope.png'}"])
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ConfigError, match="not an image OpenCV can read"):
        load_mission("hover_image", [f"steps.1.hover_image.image={tmp_path / 'text.png'}"])
