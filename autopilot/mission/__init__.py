"""Missions: YAML files of steps, validated before anything flies, and their executor — the
model (:mod:`.model`, the world in :mod:`.scenario`), the loader (:mod:`.loader`) and the
executor (:mod:`.executor`).

A mission file::

    name: follow_ball
    description: ...
    steps:                       # run in order; each is {behaviour: parameters}
      - takeoff: {altitude_m: 1.7}
      - follow_ball: {duration_s: 60}
      - land: {}
    fallback: land               # when a step fails
    scenario: {...}              # the simulated world (ignored on real hardware)
    config: {...}                # overrides of config.yaml for this mission

Loading validates the mission (each step's parameters against its behaviour's own model), merges
``config:`` and the command line's ``--set`` overrides into ``config.yaml`` and validates that
too. Every error names the file, the line and the key path. ``--set`` keys whose first part is
a mission key (``name``, ``steps``, ``scenario``, …) change the mission; all others change the
configuration.

:class:`MissionExecutor` runs the behaviours synchronously; the runtime drives it.
"""

from autopilot.mission.executor import MissionEvent, MissionExecutor, MissionOutput
from autopilot.mission.loader import (
    build_behavior,
    find_mission,
    is_mission_file,
    load_mission,
    shipped_missions,
    split_overrides,
)
from autopilot.mission.model import MISSION_KEYS, Mission, MissionPlan, Step
from autopilot.mission.scenario import Scenario, WindScenario

__all__ = ["MISSION_KEYS", "Mission", "MissionEvent", "MissionExecutor", "MissionOutput",
           "MissionPlan", "Scenario", "Step", "WindScenario",
           "build_behavior", "find_mission", "is_mission_file", "load_mission",
           "shipped_missions", "split_overrides"]
