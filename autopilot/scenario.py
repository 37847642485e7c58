"""Turns a mission's ``scenario:`` section into the simulated world: each target kind's section
built by its kind (:mod:`autopilot.targets`, in the order the kinds were registered), the wind,
the faults and the seed. Simulator only; a real vehicle ignores scenarios."""

from __future__ import annotations

from typing import TYPE_CHECKING

from autopilot.mission import Scenario
from autopilot.targets import World, target_kind
from drivers.sim.config import SimConfig

if TYPE_CHECKING:
    from autopilot.config import AppConfig
    from drivers.sim.scenario import ScenarioObject


def build_world(scenario: Scenario | None, sim: SimConfig, config: AppConfig | None = None
                ) -> tuple[SimConfig, list[ScenarioObject]]:
    """The simulator configuration (seed and wind from the scenario, and what the target kinds
    change in it) and the scenario objects. ``config``: the autopilot's configuration, what it
    knows of the targets (a scenario's rover is built to match it unless it says otherwise).
    Cameras that report a fitted calibration are pointed at it
    (:mod:`autopilot.sim_calibration`: fitted once, then cached)."""
    from autopilot.sim_calibration import with_fitted_calibrations

    sim = with_fitted_calibrations(sim)
    if scenario is None:
        return sim, []
    wind = sim.wind.model_copy(update={"gust_mps": scenario.wind.gust_mps,
                                       "steady_ned_m_s": scenario.wind.steady_ned_m_s})
    world = World(scenario, sim.model_copy(update={"seed": scenario.seed, "wind": wind,
                                                    "faults": list(scenario.faults)}), config)
    for name, section in scenario.targets().items():
        kind = target_kind(name)
        if kind.build is not None:
            world.objects += kind.build(section, world)
    return world.sim, world.objects
