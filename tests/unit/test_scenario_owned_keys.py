"""A mission's scenario sets the simulator's seed and wind (every shipped mission has both):
a ``--set`` of ``sim.seed`` or ``sim.wind.*`` used to be laid under it and fly as if never
given. Now it flies as given, unless the scenario's own key is set on the command line too."""

from __future__ import annotations

from autopilot.mission import load_mission
from autopilot.scenario import build_world


def test_sim_wind_and_seed_on_the_command_line_fly_as_given() -> None:
    plan = load_mission("follow_ball", ["sim.wind.gust_mps=1.0", "sim.seed=7",
                                        "sim.wind.steady_ned_m_s=[0,3,0]"])
    scenario = plan.mission.scenario  # (what build_world lays over the configuration's)
    assert scenario.wind.gust_mps == 1.0
    assert tuple(scenario.wind.steady_ned_m_s) == (0.0, 3.0, 0.0)
    assert scenario.seed == 7


def test_the_scenario_key_on_the_command_line_is_the_one_that_counts() -> None:
    plan = load_mission("follow_ball", ["sim.wind.gust_mps=1.0", "scenario.wind.gust_mps=0.5"])
    assert plan.mission.scenario.wind.gust_mps == 0.5


def test_without_them_the_mission_s_scenario_flies() -> None:
    plan = load_mission("follow_ball", ["scenario.seed=3", "sim.profile=ideal"])
    sim, _ = build_world(plan.mission.scenario, plan.config.sim, plan.config)
    assert sim.seed == 3
    assert sim.wind.gust_mps == plan.mission.scenario.wind.gust_mps == 0.0
    given = load_mission("follow_ball", ["sim.wind.gust_mps=1.0", "sim.profile=ideal"])
    sim, _ = build_world(given.mission.scenario, given.config.sim, given.config)
    assert sim.wind.gust_mps == 1.0
