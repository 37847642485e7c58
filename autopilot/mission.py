"""Missions: YAML files of steps, validated before anything flies, and their executor.

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

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    Status,
    VehicleRequest,
)
from autopilot.behaviors.flight import (
    Hold,
    HoldParams,
    Land,
    LandParams,
    SafeStop,
    Takeoff,
    TakeoffParams,
)
from autopilot.behaviors.follow_ball import FollowBall, FollowBallParams, LostTargetSettings
from autopilot.config import (
    AppConfig,
    ColorName,
    ConfigError,
    Located,
    NonNegative,
    Problem,
    _dotted,
    _Model,
    apply_overrides,
    load_yaml,
    validate,
)
from autopilot.control.follow import FollowSettings
from autopilot.resources import default_config_path, missions_dir
from drivers.base import CameraInfo, Setpoint

MISSION_KEYS = ("name", "description", "steps", "fallback", "scenario", "config")


# ------------------------------------------------------------------------------------------
# The mission model
# ------------------------------------------------------------------------------------------


class BallScenario(_Model):
    path: Literal["static", "circle", "figure8", "lissajous", "random_walk"] = "circle"
    speed_mps: Annotated[float, Field(ge=0, le=15)] = 1.0
    diameter_m: Annotated[float, Field(gt=0.02, le=2)] = 0.2
    color: ColorName = "orange"
    height_m: Annotated[float, Field(gt=0.1, le=50)] = 1.5  # of the ball's centre
    start_distance_m: Annotated[float, Field(gt=0.5, le=50)] = 2.0  # ahead of the vehicle
    start_delay_s: NonNegative = 0.0  # the ball waits this long before moving
    accel_mps2: Annotated[float, Field(gt=0, le=50)] = 2.0  # then gets up to speed this fast
    size_m: Annotated[float, Field(gt=0.5, le=100)] = 8.0  # extent of the path


class WindScenario(_Model):
    gust_mps: NonNegative = 0.0
    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


class Scenario(_Model):
    seed: Annotated[int, Field(ge=0)] = 0
    ball: BallScenario = BallScenario()
    distractors: Annotated[int, Field(ge=0, le=30)] = 0
    wind: WindScenario = WindScenario()


class Mission(_Model):
    name: str
    description: str = ""
    steps: Annotated[list[dict[str, Any]], Field(min_length=1)]
    fallback: Literal["land"] = "land"
    scenario: Scenario | None = None
    config: dict[str, Any] = Field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Step:
    name: str
    params: Params


@dataclass(frozen=True, slots=True)
class MissionPlan:
    """A validated mission with the configuration it flies with."""

    mission: Mission
    steps: tuple[Step, ...]
    config: AppConfig
    source: Path


#: behaviour name → its parameter model
STEP_PARAMS: dict[str, type[Params]] = {
    "takeoff": TakeoffParams,
    "follow_ball": FollowBallParams,
    "land": LandParams,
    "hold": HoldParams,
}


# ------------------------------------------------------------------------------------------
# Loading
# ------------------------------------------------------------------------------------------


def find_mission(name_or_path: str) -> Path:
    """A mission file by path, or by name among the shipped missions."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError([Problem(str(path), None, "", "no such mission file")])
        return path
    candidate = missions_dir() / f"{name_or_path}.yaml"
    if not candidate.is_file():
        known = ", ".join(p.stem for p in shipped_missions()) or "none"
        raise ConfigError([Problem(name_or_path, None, "",
                                   f"no mission of that name (shipped missions: {known})")])
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
    base = load_yaml(config_path or default_config_path())
    config = collect(lambda: validate(AppConfig, apply_overrides(
        _merge_located(base, located, ("config",)), config_overrides)))
    if problems:
        problems.sort(key=lambda p: (p.source == "--set", p.source, p.line or 0))
        raise ConfigError(problems)
    return MissionPlan(mission, steps, config, path)


def is_mission_file(path: str | Path) -> bool:
    data = load_yaml(path).data
    return isinstance(data, dict) and "steps" in data


def _validate_steps(raw_steps: list[dict[str, Any]], located: Located) -> tuple[Step, ...]:
    steps, problems = [], []
    for i, raw in enumerate(raw_steps):
        where = ("steps", i)
        if len(raw) != 1:
            source, line = located.locate(where)
            problems.append(Problem(source, line, _dotted(where),
                                    "a step is one behaviour name with its parameters, e.g. "
                                    "'- takeoff: {altitude_m: 2}'"))
            continue
        (name, params), = raw.items()
        if name not in STEP_PARAMS:
            source, line = located.locate((*where, name))
            problems.append(Problem(source, line, _dotted((*where, name)),
                                    f"unknown behaviour (known: {', '.join(STEP_PARAMS)})"))
            continue
        try:
            steps.append(Step(name, STEP_PARAMS[name].model_validate(params or {})))
        except ValidationError as exc:
            for err in exc.errors(include_url=False):
                loc = (*where, name, *err["loc"])
                source, line = located.locate(loc)
                message = {"extra_forbidden": "unknown key",
                           "missing": "missing required key"}.get(
                    err["type"], f"{err['msg']} (got {err.get('input')!r})")
                problems.append(Problem(source, line, _dotted(loc), message))
    if problems:
        raise ConfigError(problems)
    return tuple(steps)


def _merge_located(base: Located, other: Located, prefix: tuple[str, ...]) -> Located:
    """``base`` with ``other``'s section at ``prefix`` deep-merged over it, keeping the source
    lines of every merged key."""
    section: Any = other.data
    for key in prefix:
        section = section.get(key) if isinstance(section, dict) else None
    if not section or not isinstance(section, Mapping):
        return base  # (a section that is not a mapping is reported by the mission's model)

    def merge(into: dict, new: Mapping) -> None:
        for key, value in new.items():
            if isinstance(value, Mapping) and isinstance(into.get(key), dict):
                merge(into[key], value)
            else:
                into[key] = copy.deepcopy(value)

    data = copy.deepcopy(base.data)
    merge(data, section)
    lines = dict(base.lines)
    n = len(prefix)
    lines.update({path[n:]: where for path, where in other.lines.items()
                  if len(path) > n and path[:n] == prefix})
    return Located(data, base.source, lines)


# ------------------------------------------------------------------------------------------
# Behaviours from steps
# ------------------------------------------------------------------------------------------


def build_behavior(step: Step, config: AppConfig, cameras: Mapping[str, CameraInfo]) -> Behavior:
    if step.name == "takeoff":
        return Takeoff(step.params)
    if step.name == "land":
        return Land(step.params)
    if step.name == "hold":
        return Hold(step.params)
    if step.name == "follow_ball":
        params: FollowBallParams = step.params
        f = config.control.follow
        camera_name = config.perception.ball.camera
        if camera_name not in cameras:
            raise ConfigError([Problem("config", None, "perception.ball.camera",
                                       f"the vehicle has no camera {camera_name!r} "
                                       f"(it has {', '.join(cameras) or 'none'})")])
        follow = FollowSettings(
            mode=params.mode or f.mode,
            standoff_m=params.standoff_m or f.standoff_m,
            position_gain=f.position_gain,
            yaw_gain=f.yaw_gain,
            max_speed_m_s=f.max_speed_m_s,
            max_vertical_speed_m_s=f.max_vertical_speed_m_s,
            max_accel_m_s2=f.max_accel_m_s2,
            max_yaw_rate_rad_s=math.radians(f.max_yaw_rate_deg_s),
            altitude_floor_m=f.altitude_floor_m,
            accel_lead_s=f.accel_lead_s,
            accel_filter_s=f.accel_filter_s,
        )
        lost = LostTargetSettings(f.lost_after_s, f.lost_hold_s,
                                  math.radians(f.search_yaw_rate_deg_s), f.lost_timeout_s)
        return FollowBall(params, follow, lost, cameras[camera_name],
                          config.perception.ball.diameter_m)
    raise AssertionError(f"no behaviour {step.name}")


# ------------------------------------------------------------------------------------------
# Execution
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class MissionOutput:
    setpoint: Setpoint | None
    requests: tuple[VehicleRequest, ...]
    events: tuple[str, ...]
    finished: bool
    status: str  # running | completed | failed | aborted
    step: str
    phase: str


@dataclass
class MissionExecutor:
    """Runs behaviours in order. A failed step hands over to the fallback (a safe stop:
    hold, land, disarm); :meth:`abort` does the same on request (Ctrl-C)."""

    behaviors: list[Behavior]
    fallback: Callable[[], Behavior] = SafeStop
    _index: int = field(default=-1, init=False)
    _current: Behavior | None = field(default=None, init=False)
    _status: str = field(default="running", init=False)
    _in_fallback: bool = field(default=False, init=False)
    _failure: str = field(default="", init=False)

    @property
    def status(self) -> str:
        return self._status

    @property
    def step_name(self) -> str:
        return self._current.name if self._current is not None else ""

    @property
    def failure(self) -> str:
        return self._failure

    def start(self, inputs: BehaviorInputs) -> MissionOutput:
        return self._advance(inputs, [])

    def update(self, inputs: BehaviorInputs) -> MissionOutput:
        if self._current is None:
            return self._output(None, (), [], "")
        return self._handle(self._current.update(inputs), inputs, [])

    def request_failed(self, request: VehicleRequest, reason: str,
                       inputs: BehaviorInputs) -> MissionOutput:
        if self._current is None:
            return self._output(None, (), [], "")
        return self._handle(self._current.request_failed(request, reason), inputs,
                            [f"{request.kind.value} refused: {reason}"])

    def abort(self, reason: str, inputs: BehaviorInputs) -> MissionOutput:
        if self._in_fallback or self._current is None:
            return self._output(None, (), [f"abort requested ({reason}): already stopping"], "")
        self._status = "aborted"
        self._failure = reason
        return self._enter_fallback(inputs, [f"aborted: {reason}"])

    # -- internals --------------------------------------------------------------------------

    def _handle(self, out: BehaviorOutput, inputs: BehaviorInputs,
                events: list[str]) -> MissionOutput:
        if out.status is Status.RUNNING:
            return self._output(out.setpoint, out.requests, events, out.phase)
        name = self._current.name
        if self._in_fallback:
            events.append(f"{name} {out.status.value}" + (f": {out.reason}" if out.reason else ""))
            if out.status is Status.FAILED:
                self._status = "failed"
            self._current = None
            return self._output(out.setpoint, out.requests, events, out.phase, finished=True)
        if out.status is Status.SUCCEEDED:
            events.append(f"step {name} succeeded")
            return self._advance(inputs, events, out.setpoint)
        self._status = "failed"
        self._failure = f"{name}: {out.reason}"
        return self._enter_fallback(inputs, [*events, f"step {name} failed: {out.reason}"])

    def _advance(self, inputs: BehaviorInputs, events: list[str],
                 setpoint: Setpoint | None = None) -> MissionOutput:
        self._index += 1
        if self._index >= len(self.behaviors):
            self._current = None
            if self._status == "running":
                self._status = "completed"
            events.append("mission completed")
            return self._output(setpoint, (), events, "", finished=True)
        self._current = self.behaviors[self._index]
        events.append(f"step {self._current.name} started")
        return self._handle(self._current.activate(inputs), inputs, events)

    def _enter_fallback(self, inputs: BehaviorInputs, events: list[str]) -> MissionOutput:
        self._in_fallback = True
        self._current = self.fallback()
        events.append(f"fallback {self._current.name} started")
        return self._handle(self._current.activate(inputs), inputs, events)

    def _output(self, setpoint, requests, events, phase, finished=False) -> MissionOutput:
        return MissionOutput(setpoint, tuple(requests), tuple(events), finished, self._status,
                             self.step_name, phase)
