"""Plugins' kinds through entry points (autopilot/plugins.py), target kinds' sections, and the
capability protocols a driver implements (drivers/capabilities.py)."""

from __future__ import annotations

import asyncio
from importlib.metadata import EntryPoint
from types import SimpleNamespace

import pytest
from pydantic import BaseModel, ConfigDict

from autopilot import plugins
from autopilot.config import ConfigError
from autopilot.targets import TARGET_KINDS, TargetKind


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    size_m: float = 1.0


KIND = TargetKind("unit_test_target", scenario=_Section, settings=_Section)


@pytest.fixture
def fresh_plugins(monkeypatch):
    """load_plugins as on a first import, with these entry points installed."""
    def install(points: list[EntryPoint]) -> None:
        monkeypatch.setattr(plugins, "_state", {"loaded": False})
        monkeypatch.setattr(plugins, "_errors", [])
        monkeypatch.setattr(plugins, "LOADED", [])
        monkeypatch.setattr(plugins, "entry_points",
                            lambda group: [p for p in points if p.group == group])
        plugins.load_plugins()
    yield install
    TARGET_KINDS.pop(KIND.name, None)


def test_a_plugins_target_kind_is_registered_and_a_broken_one_reported(fresh_plugins):
    fresh_plugins([
        EntryPoint("good", f"{__name__}:KIND", "autopilot.targets"),
        EntryPoint("missing", "no_such_module_here:X", "autopilot.targets"),
        EntryPoint("wrong", f"{__name__}:_Section", "autopilot.steps")])
    assert TARGET_KINDS["unit_test_target"] is KIND
    errors = plugins.plugin_errors()
    assert len(errors) == 2
    assert any("missing = no_such_module_here:X" in e and "ModuleNotFoundError" in e
               for e in errors)
    assert any("expected a StepKind" in e for e in errors)


def test_a_target_kinds_sections_are_validated_where_they_are_written(fresh_plugins, tmp_path):
    from autopilot.mission import load_mission

    fresh_plugins([EntryPoint("good", f"{__name__}:KIND", "autopilot.targets")])
    mission = tmp_path / "m.yaml"
    mission.write_text("name: m\nsteps:\n  - takeoff: {}\nscenario:\n  unit_test_target:\n"
                       "    size_m: 2\n")
    plan = load_mission(str(mission))
    assert plan.mission.scenario.targets()["unit_test_target"].size_m == 2.0
    assert plan.config.targets["unit_test_target"].size_m == 1.0  # its settings' defaults
    mission.write_text("name: m\nsteps:\n  - takeoff: {}\nscenario:\n  unit_test_target:\n"
                       "    size: 2\n  unit_test_targt: {}\n")
    with pytest.raises(ConfigError) as caught:
        load_mission(str(mission))
    text = str(caught.value)
    assert "m.yaml:6: scenario.unit_test_target.size: unknown key" in text, text


def test_an_unknown_scenario_key_suggests_the_registered_ones(fresh_plugins, tmp_path):
    from autopilot.mission import load_mission

    fresh_plugins([EntryPoint("good", f"{__name__}:KIND", "autopilot.targets")])
    mission = tmp_path / "m.yaml"
    mission.write_text("name: m\nsteps:\n  - takeoff: {}\nscenario:\n  unit_test_targt: {}\n")
    with pytest.raises(ConfigError) as caught:
        load_mission(str(mission))
    assert "m.yaml:5: scenario.unit_test_targt: unknown key (did you mean " \
        "'unit_test_target'?)" in str(caught.value)


def test_a_precision_landing_is_refused_by_a_vehicle_without_it():
    from autopilot.behaviors.base import RequestKind, VehicleRequest
    from autopilot.runtime.commands import VehicleCommands
    from drivers.base import CommandDenied
    from drivers.capabilities import PrecisionLanding

    class Plain:  # a vehicle without the capability
        async def land(self) -> None: ...

    class WithIt(Plain):
        async def precision_land(self) -> None: ...

        async def send_landing_target(self, target) -> None: ...

    assert not isinstance(Plain(), PrecisionLanding)
    assert isinstance(WithIt(), PrecisionLanding)
    hub = SimpleNamespace(emit=lambda event: None)
    flight = SimpleNamespace(vehicle=Plain(), events=hub, state=None,
                             clock=SimpleNamespace(now=lambda: 0.0))
    commands = VehicleCommands(flight, SimpleNamespace(event=lambda *a: None), None)
    with pytest.raises(CommandDenied, match="no precision landing"):
        asyncio.run(commands.perform(VehicleRequest(RequestKind.PRECISION_LAND)))
