"""A landing handed to the vehicle lands on the target or not at all: ArduCopter's LAND lands
on the companion's LANDING_TARGET only with PLND_ENABLED and PLND_TYPE 1 (PLND_ENABLED is 0 by
default), so its profile reads both and refuses otherwise, naming them; a mission that hands
a landing to such a vehicle is refused once connected, before anything flies."""

from __future__ import annotations

import asyncio
import dataclasses

import pytest

from autopilot.config import ConfigError
from autopilot.mission import load_mission
from autopilot.run import check_vehicle_settings
from drivers.base import CommandDenied, CommandTimeout, FlightMode
from drivers.capabilities import LandingSettings, settings_problem
from drivers.mavlink.firmware import ArduCopterProfile, Px4Profile


class Vehicle:
    """What a driver gives the profile: its parameters (a missing one: KeyError) and a mode
    switch that records what it was asked."""

    def __init__(self, **params: float) -> None:
        self.params = params
        self.reads: list[str] = []
        self.modes: list[FlightMode] = []

    async def get_param(self, name: str) -> float:
        self.reads.append(name)
        if isinstance(self.params.get(name), Exception):
            raise self.params[name]
        return self.params[name]

    async def set_mode(self, mode: FlightMode) -> None:
        self.modes.append(mode)

    async def command(self, name: str, command: int, *params: float) -> None:
        raise AssertionError(f"no command expected: {name}")


def land(profile, vehicle: Vehicle) -> None:
    asyncio.run(profile.precision_land(vehicle.command, vehicle.set_mode, vehicle.get_param))


def problem(profile, vehicle: Vehicle) -> str | None:
    return asyncio.run(profile.precision_landing_problem(vehicle.get_param))


def test_arducopter_with_plnd_on_for_a_companion_lands_in_land() -> None:
    v = Vehicle(PLND_ENABLED=1.0, PLND_TYPE=1.0)
    assert problem(ArduCopterProfile(), v) is None
    land(ArduCopterProfile(), v)
    assert v.modes == [FlightMode.LAND]
    assert {"PLND_ENABLED", "PLND_TYPE"} <= set(v.reads)
    # older firmware's PLND_ENABLED 2 ("enabled, strict") is on too
    assert problem(ArduCopterProfile(), Vehicle(PLND_ENABLED=2.0, PLND_TYPE=1.0)) is None


def test_arducopter_defaults_refuse_naming_plnd_enabled() -> None:
    v = Vehicle(PLND_ENABLED=0.0, PLND_TYPE=0.0)  # ArduCopter's defaults
    with pytest.raises(CommandDenied) as caught:
        land(ArduCopterProfile(), v)
    assert v.modes == []  # no LAND: it would land wherever the vehicle is
    text = str(caught.value)
    assert "PLND_ENABLED is 0" in text
    assert "PLND_TYPE 1" in text  # (what to set)
    assert "method: ours" in text  # (or what to fly instead)


def test_another_plnd_type_is_refused_naming_it() -> None:
    for kind in (0.0, 2.0, 3.0, 4.0):  # none, IRLock, SITL_Gazebo, SITL
        text = problem(ArduCopterProfile(), Vehicle(PLND_ENABLED=1.0, PLND_TYPE=kind))
        assert text is not None
        assert f"PLND_TYPE is {int(kind)}, not 1" in text


def test_unanswered_plnd_parameters_are_a_problem() -> None:
    """A firmware built without AC_PrecLand has no PLND_* (the read times out or fails)."""
    assert "PLND_ENABLED not read" in problem(ArduCopterProfile(), Vehicle())
    v = Vehicle(PLND_ENABLED=CommandTimeout("PLND_ENABLED", 2.0), PLND_TYPE=1.0)
    assert "PLND_ENABLED not read" in problem(ArduCopterProfile(), v)
    v = Vehicle(PLND_ENABLED=1.0)
    assert "PLND_TYPE not read" in problem(ArduCopterProfile(), v)


def test_px4_reads_nothing_and_enters_precland() -> None:
    v = Vehicle()
    assert problem(Px4Profile(), v) is None
    land(Px4Profile(), v)
    assert v.modes == [FlightMode.PRECLAND]
    assert v.reads == []


class Connected:
    """A connected vehicle whose precision landing its settings may deny."""

    def __init__(self, answer: str | None) -> None:
        self.answer = answer
        self.asked = 0

    async def precision_landing_problem(self) -> str | None:
        self.asked += 1
        return self.answer


def test_a_mission_handing_a_landing_to_a_vehicle_that_would_not_is_refused() -> None:
    plan = load_mission("land_pad", ["steps.1.land_pad.method=vehicle_precland"])
    vehicle = Connected("PLND_ENABLED is 0: …")
    assert isinstance(vehicle, LandingSettings)
    with pytest.raises(ConfigError) as caught:
        asyncio.run(check_vehicle_settings(plan, vehicle))
    text = str(caught.value)
    assert "steps[1].land_pad" in text
    assert "PLND_ENABLED is 0" in text
    assert "land_pad.yaml" in text  # (the mission file)
    asyncio.run(check_vehicle_settings(plan, Connected(None)))  # its settings allow it


def test_each_need_is_asked_once_and_only_when_a_step_has_it() -> None:
    plan = load_mission("land_pad", ["steps.1.land_pad.method=vehicle_precland"])
    two = dataclasses.replace(plan, steps=(*plan.steps, plan.steps[1]))
    vehicle = Connected(None)
    asyncio.run(check_vehicle_settings(two, vehicle))
    assert vehicle.asked == 1
    ours = Connected("never asked")
    asyncio.run(check_vehicle_settings(load_mission("land_pad"), ours))  # method: ours
    assert ours.asked == 0
    # a vehicle that cannot say (no LandingSettings) is not refused for it
    assert asyncio.run(settings_problem(object(), "precision_landing")) is None
