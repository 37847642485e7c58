"""What a mission's steps need of their vehicle (StepKind.needs, drivers.capabilities.NEEDS):
a vehicle that lacks it is refused before anything opens or flies, with the step and the
capability named."""

from __future__ import annotations

import pytest

from autopilot.config import ConfigError
from autopilot.mission import load_mission
from autopilot.run import check_vehicle_can_fly
from drivers.capabilities import lacks


class NoGnss:
    """A vehicle as the AR.Drone is: no global position, no precision landing, no rover."""

    has_global_position = False


class Px4Like:
    has_global_position = True

    async def precision_land(self) -> None: ...

    async def send_landing_target(self, target) -> None: ...

    def rover_states(self, buffer: int = 8): ...


def test_a_survey_is_refused_on_a_vehicle_without_gnss() -> None:
    plan = load_mission("survey")
    with pytest.raises(ConfigError) as caught:
        check_vehicle_can_fly(plan, NoGnss())
    text = str(caught.value)
    assert "steps[1].survey" in text
    assert "global_position" in text
    assert "GNSS" in text
    check_vehicle_can_fly(plan, Px4Like())  # a vehicle with GNSS flies it


def test_an_orbit_needs_gnss_only_for_its_photos() -> None:
    with pytest.raises(ConfigError, match=r"steps\[1\]\.orbit"):
        check_vehicle_can_fly(load_mission("orbit"), NoGnss())
    check_vehicle_can_fly(load_mission("orbit", ["steps.1.orbit.images=0"]), NoGnss())


def test_the_camera_missions_need_nothing_more() -> None:
    for name in ("follow_ball", "follow_marker", "hover_image", "land_pad"):
        check_vehicle_can_fly(load_mission(name), NoGnss())


def test_px4_precision_landing_and_the_rover_are_needs_too() -> None:
    plan = load_mission("land_pad", ["steps.1.land_pad.method=px4_precland"])
    with pytest.raises(ConfigError, match="precision_landing"):
        check_vehicle_can_fly(plan, NoGnss())
    check_vehicle_can_fly(plan, Px4Like())
    with pytest.raises(ConfigError, match="rover_link"):
        check_vehicle_can_fly(load_mission("land_on_rover"), NoGnss())
    assert lacks(Px4Like(), ("global_position", "precision_landing", "rover_link")) == []
