"""Loading a mission: the file (or a shipped mission by name), ``--set`` overrides, the
configuration it flies with, every problem at once naming the file, line and key; and the
behaviour that flies a step."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from autopilot.behaviors.base import (
    Behavior,
)
from autopilot.config import (
    AppConfig,
    ConfigError,
    Located,
    Problem,
    apply_overrides,
    dotted_key,
    load_yaml,
    merge_located,
    unknown_key_hint,
    validate,
    with_profile,
)
from autopilot.mission.model import MISSION_KEYS, Mission, MissionPlan, Step
from autopilot.resources import default_config_path, missions_dir
from autopilot.steps import STEP_KINDS, StepContext, step_kind
from autopilot.suggest import did_you_mean
from drivers.base import CameraInfo


def find_mission(name_or_path: str) -> Path:
    """A mission file by path, or by name among the shipped missions."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError([Problem(str(path), None, "", "no such mission file")])
        return path
    candidate = missions_dir() / f"{name_or_path}.yaml"
    if not candidate.is_file():
        names = [p.stem for p in shipped_missions()]
        raise ConfigError([Problem(name_or_path, None, "",
                                   f"no mission of that name{did_you_mean(name_or_path, names)} "
                                   f"(shipped missions: {', '.join(names) or 'none'})")])
    return candidate


def shipped_missions() -> list[Path]:
    return sorted(missions_dir().glob("*.yaml"))


def split_overrides(overrides: list[str]) -> tuple[list[str], list[str]]:
    """``--set`` items for the mission and for the configuration."""
    mission, config = [], []
    for item in overrides:
        head = item.split("=", 1)[0].strip().split(".", 1)[0]
        (mission if head in MISSION_KEYS else config).append(item)
    return mission, config


def load_mission(name_or_path: str, overrides: list[str] = (),
                 config_path: str | Path | None = None) -> MissionPlan:
    path = find_mission(name_or_path)
    mission_overrides, config_overrides = split_overrides(list(overrides))
    located = apply_overrides(load_yaml(path), mission_overrides)
    # every problem at once: the mission, its steps, and the configuration it flies with
    problems: list[Problem] = []

    def collect(check: Callable[[], Any]) -> Any:
        try:
            return check()
        except ConfigError as exc:
            problems.extend(exc.problems)
            return None

    mission = collect(lambda: validate(Mission, located))
    raw_steps = located.data.get("steps") if isinstance(located.data, dict) else None
    steps = None
    if isinstance(raw_steps, list) and all(isinstance(raw, dict) for raw in raw_steps):
        steps = collect(lambda: _validate_steps(raw_steps, located))
    mission_config = located.data.get("config") if isinstance(located.data, dict) else None
    base = with_profile(load_yaml(config_path or default_config_path()), [mission_config],
                        config_overrides)
    config = collect(lambda: validate(AppConfig, apply_overrides(
        merge_located(base, located, ("config",)), config_overrides)))
    if not problems and steps is not None and config is not None:
        # what a step needs of the configuration (its pipelines: a detector that can find
        # its target, …)
        for i, step in enumerate(steps):
            try:
                step_kind(step.name).check(step.params, config)
                step_kind(step.name).pipelines(step.params, config)
            except ValueError as exc:
                source, line = located.locate(("steps", i, step.name))
                problems.append(Problem(source, line, f"steps.{i}.{step.name}", str(exc)))
        faults = mission.scenario.faults if mission.scenario is not None else []
        cameras = [name for name, cam in config.vehicle.cameras.items() if cam.enabled]
        for i, fault in enumerate(faults):
            camera = getattr(fault, "camera", None)
            if camera is not None and camera not in cameras:
                source, line = located.locate(("scenario", "faults", i))
                problems.append(Problem(source, line, f"scenario.faults.{i}.camera",
                                        f"no camera {camera!r} on the vehicle (its cameras: "
                                        f"{', '.join(cameras) or 'none'})"))
            if fault.kind == "motor_failure":
                from drivers.sim.model import rotor_count

                rotors = rotor_count(config.sim.vehicle.model)
                if fault.motor >= rotors:
                    source, line = located.locate(("scenario", "faults", i))
                    problems.append(Problem(
                        source, line, f"scenario.faults.{i}.motor",
                        f"no motor {fault.motor}: the vehicle ({config.sim.vehicle.model}) has "
                        f"{rotors}, numbered 0 to {rotors - 1} in PX4's order"))
    if problems:
        problems.sort(key=lambda p: (p.source == "--set", p.source, p.line or 0))
        raise ConfigError(problems)
    warnings = tuple(f"steps[{i}].{step.name}: {text}" for i, step in enumerate(steps)
                     for text in step_kind(step.name).warnings(step.params, config))
    return MissionPlan(command_line_wins(mission, config, overrides), steps, config, path,
                       warnings)


#: the simulator's keys a mission's scenario sets (autopilot.scenario.build_world lays the
#: scenario's over the configuration's), by their place in the scenario
SCENARIO_OWNED = {"sim.seed": ("seed",), "sim.wind.gust_mps": ("wind", "gust_mps"),
                  "sim.wind.steady_ned_m_s": ("wind", "steady_ned_m_s")}


def command_line_wins(mission: Mission, config: AppConfig, overrides: Sequence[str]
                      ) -> Mission:
    """A ``--set`` of one of :data:`SCENARIO_OWNED`'s keys flies as given, although the
    mission's scenario sets it too (every shipped mission has a seed and a wind): it is laid
    over the scenario, unless the scenario's own key is set on the command line as well."""
    if mission.scenario is None:
        return mission
    keys = {item.split("=", 1)[0].strip() for item in overrides}
    scenario = mission.scenario
    for key, place in SCENARIO_OWNED.items():
        given = key in keys or (key.startswith("sim.wind.") and "sim.wind" in keys)
        if not given or ".".join(("scenario", *place)) in keys:
            continue
        value = getattr(config.sim.wind, place[1]) if place[0] == "wind" else config.sim.seed
        if place[0] == "wind":
            scenario = scenario.model_copy(update={"wind": scenario.wind.model_copy(
                update={place[1]: value})})
        else:
            scenario = scenario.model_copy(update={place[0]: value})
    return mission if scenario is mission.scenario else \
        mission.model_copy(update={"scenario": scenario})


def is_mission_file(path: str | Path) -> bool:
    data = load_yaml(path).data
    return isinstance(data, dict) and "steps" in data


def _validate_steps(raw_steps: list[dict[str, Any]], located: Located) -> tuple[Step, ...]:
    steps, problems = [], []
    for i, raw in enumerate(raw_steps):
        where = ("steps", i)
        if len(raw) != 1:
            source, line = located.locate(where)
            problems.append(Problem(source, line, dotted_key(where),
                                    "a step is one behaviour name with its parameters, e.g. "
                                    "'- takeoff: {altitude_m: 2}'"))
            continue
        (name, params), = raw.items()
        if name not in STEP_KINDS:
            source, line = located.locate((*where, name))
            problems.append(Problem(source, line, dotted_key((*where, name)),
                                    f"unknown step kind{did_you_mean(name, STEP_KINDS)} "
                                    f"(known: {', '.join(STEP_KINDS)})"))
            continue
        try:
            steps.append(Step(name, STEP_KINDS[name].params.model_validate(params or {})))
        except ValidationError as exc:
            for err in exc.errors(include_url=False):
                loc = (*where, name, *err["loc"])
                source, line = located.locate(loc)
                message = {"extra_forbidden": "unknown key" + unknown_key_hint(
                               STEP_KINDS[name].params, err["loc"]),
                           "missing": "missing required key"}.get(
                    err["type"], f"{err['msg']} (got {err.get('input')!r})")
                problems.append(Problem(source, line, dotted_key(loc), message))
    if problems:
        raise ConfigError(problems)
    return tuple(steps)


# ------------------------------------------------------------------------------------------
# Behaviours from steps
# ------------------------------------------------------------------------------------------


def build_behavior(step: Step, config: AppConfig, cameras: Mapping[str, CameraInfo],
                   offload=None) -> Behavior:
    """The behaviour that flies a step, as its registered kind builds it (``offload``: where
    heavy planning runs, see :class:`StepContext`)."""
    return step_kind(step.name).behavior(step.params, StepContext(config, cameras, offload))
