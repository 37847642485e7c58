"""A goal is refused for what its vehicle lacks (drivers.capabilities.NEEDS), as a mission is
before it flies: a survey's geotagged photos without GNSS, a landing handed to a vehicle with
no precision landing — named in the refusal, before anything is queued."""

from __future__ import annotations

import pytest

from autopilot.goals import GoalError, GoalManager, validate_goal
from autopilot.mission import load_mission
from autopilot.status import MissionStatus

from .test_vehicle_needs import NoGnss, Px4Like


def test_a_goal_needing_what_the_vehicle_lacks_is_refused_naming_it() -> None:
    config = load_mission("standby").config
    goals = GoalManager(config)
    survey = validate_goal({"survey": {"polygon_m": [[0, 0], [10, 0], [10, 10], [0, 10]]}},
                           config)
    with pytest.raises(GoalError) as caught:
        goals.submit(survey, 0.0, MissionStatus.HOVER, True, True, vehicle=NoGnss())
    assert caught.value.status == 409
    assert "global_position" in caught.value.reason
    assert "GNSS" in caught.value.reason
    handed = validate_goal({"land_pad": {"method": "vehicle_precland"}}, config)
    with pytest.raises(GoalError, match="precision_landing"):
        goals.submit(handed, 0.0, MissionStatus.HOVER, True, True, vehicle=NoGnss())
    assert goals.goals == {}  # nothing queued
    assert goals.submit(survey, 0.0, MissionStatus.HOVER, True, True, vehicle=Px4Like()).active
