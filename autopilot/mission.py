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

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    Status,
    VehicleRequest,
)
from autopilot.behaviors.flight import SafeStop
from autopilot.config import (
    AppConfig,
    ColorName,
    ConfigError,
    ConfigModel,
    Located,
    NonNegative,
    Problem,
    apply_overrides,
    dotted_key,
    load_yaml,
    merge_located,
    unknown_key_hint,
    validate,
    with_profile,
)
from autopilot.perception.colors import COLORS
from autopilot.pipeline import PipelineSpec
from autopilot.resources import default_config_path, missions_dir
from autopilot.steps import STEP_KINDS, StepContext, step_kind
from autopilot.suggest import did_you_mean
from drivers.base import CameraInfo, Setpoint
from drivers.sim.faults import Fault

MISSION_KEYS = ("name", "description", "steps", "fallback", "scenario", "config")


# ------------------------------------------------------------------------------------------
# The mission model
# ------------------------------------------------------------------------------------------


class BallScenario(ConfigModel):
    path: Literal["static", "circle", "figure8", "lissajous", "random_walk"] = "circle"
    speed_mps: Annotated[float, Field(ge=0, le=15)] = 1.0
    diameter_m: Annotated[float, Field(gt=0.02, le=2)] = 0.2
    color: ColorName = "orange"
    height_m: Annotated[float, Field(gt=0.1, le=50)] = 1.5  # of the ball's centre
    start_distance_m: Annotated[float, Field(gt=0.5, le=50)] = 2.0  # ahead of the vehicle
    start_delay_s: NonNegative = 0.0  # the ball waits this long before moving
    #: it gets up to speed this fast; on a random walk, its greatest acceleration
    accel_mps2: Annotated[float, Field(gt=0, le=50)] = 2.0
    size_m: Annotated[float, Field(gt=0.5, le=100)] = 8.0  # extent of the path


class MarkerScenario(ConfigModel):
    """A fiducial marker on a board (seed 002: ArUco id 36, 16 cm), moving like the ball."""

    dictionary: str = "DICT_ARUCO_ORIGINAL"  # OpenCV dictionary or AprilTag family
    id: Annotated[int, Field(ge=0)] = 36
    size_m: Annotated[float, Field(gt=0.02, le=2)] = 0.16  # side of the black square
    board_m: Annotated[float, Field(gt=0.02, le=3)] = 0.3  # the white board around it
    path: Literal["static", "circle", "figure8", "lissajous", "random_walk"] = "static"
    speed_mps: Annotated[float, Field(ge=0, le=15)] = 0.0
    height_m: Annotated[float, Field(gt=0.1, le=50)] = 1.5  # of the marker's centre
    start_distance_m: Annotated[float, Field(gt=0.3, le=50)] = 2.0  # ahead of the vehicle
    start_delay_s: NonNegative = 0.0
    #: as the ball's: getting up to speed, and a random walk's greatest acceleration
    accel_mps2: Annotated[float, Field(gt=0, le=50)] = 2.0
    path_size_m: Annotated[float, Field(gt=0.5, le=100)] = 6.0  # extent of the path
    #: which way the board turns its face: to the drone, along its travel, against it (to a
    #: follower behind it), or a fixed heading (yaw_deg; default: back towards the start)
    facing: Literal["drone", "travel", "trail", "fixed"] = "drone"
    yaw_deg: float | None = None


class WindScenario(ConfigModel):
    gust_mps: NonNegative = 0.0
    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ImageScenario(ConfigModel):
    """A printed image lying on the ground (hover_image), on gravel and grass."""

    file: str = "default"  # "default": the generated target; else an image file
    size_m: Annotated[float, Field(gt=0.05, le=50)] = 1.0  # printed width
    north_east_m: tuple[float, float] = (0.0, 0.0)  # its centre, from the vehicle's start
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading of its top


class PadScenario(ConfigModel):
    """A landing pad on the ground (land_pad): a coloured circle (``size_m`` across, on a white
    square a quarter wider) or the nested marker pad (``size_m`` square; its markers' ``ids``:
    the small centre one first)."""

    kind: Literal["circle", "markers"] = "circle"
    color: ColorName = "red"  # circle: red = land here (seed 001)
    size_m: Annotated[float, Field(gt=0.1, le=10)] = 0.8
    north_east_m: tuple[float, float] = (0.0, 0.0)  # its centre, from the vehicle's start
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading of its top
    dictionary: str = "DICT_4X4_50"  # markers
    ids: tuple[int, int, int, int, int] = (0, 1, 2, 3, 4)  # markers: centre, then the four

    @model_validator(mode="after")
    def _layout(self) -> PadScenario:
        if self.kind == "markers":
            from autopilot.perception.pad import marker_pad_layout

            marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self


class DeckTagScenario(ConfigModel):
    """The tag on the rover's deck (the nested marker pad)."""

    kind: Literal["markers"] = "markers"
    size_m: Annotated[float, Field(gt=0.1, le=5)] = 0.7
    ids: tuple[int, int, int, int, int] = (0, 1, 2, 3, 4)
    dictionary: str = "DICT_APRILTAG_36h11"

    @model_validator(mode="after")
    def _layout(self) -> DeckTagScenario:
        from autopilot.perception.pad import marker_pad_layout

        marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self


class RoverScenario(ConfigModel):
    """A rover driving a path (land_on_rover), its deck carrying the tag. Deck, tag and UWB
    anchors default to the configuration's ``rover`` section (what the autopilot knows)."""

    path: Literal["straight", "circle", "random_turns", "stop_and_go", "static"] = "straight"
    speed_mps: Annotated[float, Field(ge=0, le=5)] = 1.5
    start_north_east_m: tuple[float, float] = (6.0, 3.0)  # from the vehicle's start
    heading_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # where it drives first
    size_m: Annotated[float, Field(gt=2, le=500)] = 24.0  # circle diameter; widest random turn
    accel_mps2: Annotated[float, Field(gt=0, le=5)] = 1.0  # pulling away and braking
    deck_size_m: tuple[Annotated[float, Field(gt=0.2, le=10)],
                       Annotated[float, Field(gt=0.2, le=10)]] | None = None
    deck_height_m: Annotated[float, Field(ge=0, le=5)] | None = None
    tag: DeckTagScenario | None = None


class UwbScenario(ConfigModel):
    """The rover's UWB anchors (default: the configuration's ``rover.uwb.anchors_frd_m``) and
    the ranging's quality (default: ``sim.uwb``)."""

    anchors: list[tuple[float, float, float]] | None = None
    range_noise_m: Annotated[float, Field(ge=0, le=5)] | None = None
    dropout: Annotated[float, Field(ge=0, le=1)] | None = None
    nlos_fraction: Annotated[float, Field(ge=0, le=1)] | None = None


class Scenario(ConfigModel):
    """The simulated world. Beside the shipped targets' sections (ball, marker, image, pad,
    rover), a section for each target kind a plugin registered (:mod:`autopilot.targets`),
    validated by that kind's scenario model."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)

    seed: Annotated[int, Field(ge=0)] = 0
    ball: BallScenario | None = BallScenario()  # null: no ball
    distractors: Annotated[int, Field(ge=0, le=30)] = 0  # orange-ish objects near the ball
    marker: MarkerScenario | None = None
    image: ImageScenario | None = None
    pad: PadScenario | None = None
    rover: RoverScenario | None = None
    uwb: UwbScenario = UwbScenario()
    #: decoy markers beside the marker's path: how many (ids drawn from its dictionary), or
    #: their ids; with a pad, decoy pads around it (other colours, blue first: keep away;
    #: marker pads with other ids): how many
    decoys: Annotated[int, Field(ge=0, le=30)] | list[Annotated[int, Field(ge=0)]] = 0
    wind: WindScenario = WindScenario()
    #: injected faults, each a window after the first arming (drivers/sim/faults.py)
    faults: list[Fault] = Field(default_factory=list)

    @model_validator(mode="after")
    def _target_sections(self) -> Scenario:
        from autopilot.plugins import load_plugins
        from autopilot.suggest import did_you_mean
        from autopilot.targets import TARGET_KINDS, validate_section

        load_plugins()
        extra = self.__pydantic_extra__ or {}
        for key, value in list(extra.items()):
            kind = TARGET_KINDS.get(key)
            if kind is None:
                known = [*type(self).model_fields, *(k for k, t in TARGET_KINDS.items()
                                                      if t.scenario is not None)]
                raise PydanticCustomError("unknown_key", "unknown key" + did_you_mean(
                    key, known).replace("{", "(").replace("}", ")"),
                    {"key_path": ("scenario", key)})
            extra[key] = validate_section(kind, kind.scenario, value, ("scenario", key))
        return self

    def targets(self) -> dict[str, BaseModel]:
        """The plugins' target sections this scenario has (validated), by kind."""
        return dict(self.__pydantic_extra__ or {})

    @model_validator(mode="after")
    def _faults_apply(self) -> Scenario:
        for i, f in enumerate(self.faults):
            if f.kind == "decoy_crossing" and self.ball is None:
                raise ValueError(f"faults[{i}] decoy_crossing: the scenario has no ball to cross")
            if f.kind == "rover_stop" and self.rover is None:
                raise ValueError(f"faults[{i}] rover_stop: the scenario has no rover")
            color = getattr(f, "color", None)
            if color is not None and color not in COLORS:
                raise ValueError(f"faults[{i}] decoy_crossing: unknown color {color!r} "
                                 f"(known: {', '.join(COLORS)})")
        return self

    @model_validator(mode="after")
    def _marker_dictionary(self) -> Scenario:
        if self.marker is not None:
            from drivers.markers import aruco_dictionary_name

            try:
                aruco_dictionary_name(self.marker.dictionary)
            except ValueError as exc:
                raise ValueError(f"marker.dictionary: {exc}") from None
        if self.pad is not None and isinstance(self.decoys, list):
            raise ValueError("decoys: with a pad, the number of decoy pads (not a list of ids)")
        if self.pad is not None and self.pad.kind == "markers" and self.decoys:
            from autopilot.perception.pad import marker_pad_layout

            ids = self.pad.ids
            top = max(ids) + (max(ids) - min(ids) + 1) * int(self.decoys)
            try:
                marker_pad_layout(self.pad.size_m, [top - 4, top - 3, top - 2, top - 1, top],
                                  self.pad.dictionary)
            except ValueError:
                raise ValueError(f"decoys: {self.decoys} decoy marker pads need marker ids up "
                                 f"to {top}, more than {self.pad.dictionary} has") from None
        return self


class Mission(ConfigModel):
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
    #: what may not go as the mission's author expects, though it can fly (e.g. an orbit's
    #: centre outside its photos), each naming its step; shown before the flight
    warnings: tuple[str, ...] = ()

    def pipelines(self, index: int) -> tuple[PipelineSpec, ...]:
        """The perception pipelines step ``index`` needs while it runs."""
        step = self.steps[index]
        return step_kind(step.name).pipelines(step.params, self.config)

    def cameras_used(self) -> list[str]:
        """The cameras any step's pipelines read, in the order the steps first use them, then
        those steps take photos with (and, when the mission waits for goals, the photo camera
        goals use by default)."""
        cameras = [spec.camera for spec in self.all_pipelines().values() if spec.camera]
        for step in self.steps:
            kind = step_kind(step.name)
            photo = kind.photo_camera(step.params, self.config)
            if photo is not None:
                cameras.append(photo)
            if step.name == "standby":
                cameras.append(self.config.photos.camera)
        return list(dict.fromkeys(cameras))

    def all_pipelines(self) -> dict[str, PipelineSpec]:
        """Every pipeline any step needs, by key (steps that share one share its state)."""
        found: dict[str, PipelineSpec] = {}
        for i in range(len(self.steps)):
            for spec in self.pipelines(i):
                found.setdefault(spec.key, spec)
        return found


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
    return MissionPlan(mission, steps, config, path, warnings)


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


# ------------------------------------------------------------------------------------------
# Execution
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class MissionEvent:
    """Something the mission did, as the flight log keeps it (``/mission/events``).

    ``kind``: ``step_started``, ``step_succeeded``, ``step_failed``, ``fallback_started``,
    ``fallback_ended``, ``mission_completed``, ``aborted``, ``request_refused``,
    ``goal_cancelled``, ``standby`` (back to waiting for goals) (the mission), ``request``,
    ``runtime`` and ``goal_refused`` (the runtime's own); ``step_index`` is the step's place
    in the plan, or a goal's index after the plan's steps (−1 for the fallback and the
    mission as a whole); ``text`` is for people."""

    kind: str
    step_index: int
    step: str
    text: str

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True, slots=True)
class MissionOutput:
    setpoint: Setpoint | None
    requests: tuple[VehicleRequest, ...]
    events: tuple[MissionEvent, ...]
    finished: bool
    status: str  # running | completed | failed | aborted
    step: str
    phase: str
    step_index: int = -1  # the running step's place in the plan (−1: the fallback, or none)
    photos: tuple = ()  # (step index, PhotoRequest) of what ran this tick
    progress: float = float("nan")  # of the running step (0..1; NaN: not said)
    plan: dict | None = None  # the running step's plan, the tick it made it
    photo_soon: bool = False  # the running step will ask for a photo within a moment


@dataclass
class MissionExecutor:
    """Runs behaviours in order. A failed step hands over to the fallback (a safe stop:
    hold, land, disarm); :meth:`abort` does the same on request (Ctrl-C).

    Goals (the goal API): while a step that takes goals runs (``accepts_goals``: standby),
    :meth:`start_goal` runs a goal's behaviour in its place, under the goal's own index; when
    the goal ends — succeeded, failed or cancelled (:meth:`cancel_goal`) — the waiting step is
    activated again (it hovers where the vehicle is). A goal that fails does not end the
    mission; only an abort does (the fallback)."""

    behaviors: list[Behavior]
    fallback: Callable[[], Behavior] = SafeStop
    _index: int = field(default=-1, init=False)
    _current: Behavior | None = field(default=None, init=False)
    _status: str = field(default="running", init=False)
    _in_fallback: bool = field(default=False, init=False)
    _failure: str = field(default="", init=False)
    _extras: tuple = field(default=((), float("nan"), None, False), init=False)
    _waiting: tuple[int, Behavior] | None = field(default=None, init=False)  # under a goal

    @property
    def status(self) -> str:
        return self._status

    @property
    def accepts_goals(self) -> bool:
        """A goal may start now: a step that takes goals is running, and no goal is."""
        return (not self._in_fallback and self._waiting is None and self._current is not None
                and self._current.accepts_goals)

    @property
    def goal_running(self) -> bool:
        return self._waiting is not None

    def start_goal(self, behavior: Behavior, index: int, inputs: BehaviorInputs
                   ) -> MissionOutput:
        if not self.accepts_goals:
            raise RuntimeError("no step is waiting for goals")
        saved = (self._index, self._current)
        self._waiting = saved
        self._index, self._current = index, behavior
        started = self._event("step_started", f"goal {behavior.name} started")
        try:
            out = behavior.activate(inputs)
        except Exception:  # it never started: the waiting step goes on as it was
            self._index, self._current = saved
            self._waiting = None
            raise
        return self._handle(out, inputs, [started])

    def cancel_goal(self, inputs: BehaviorInputs, reason: str = "cancelled") -> MissionOutput:
        if self._waiting is None:
            return self._output(None, (), [], "")
        return self._resume(inputs, [self._event("goal_cancelled",
                                                 f"goal {self.step_name} {reason}")])

    def reactivate(self, inputs: BehaviorInputs, why: str) -> MissionOutput:
        """Start the running step afresh from where the vehicle is (a step waiting for goals,
        after manual flight: it hovers here, not back where it began)."""
        if self._current is None:
            return self._output(None, (), [], "")
        return self._handle(self._current.activate(inputs), inputs,
                            [self._event("resumed", f"{self._current.name} resumed: {why}")])

    @property
    def current(self) -> Behavior | None:
        """The behaviour running now (a step's, a goal's or the fallback's)."""
        return self._current

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
                            [self._event("request_refused",
                                         f"{request.kind.value} refused: {reason}")])

    def abort(self, reason: str, inputs: BehaviorInputs,
              fallback: Callable[[], Behavior] | None = None) -> MissionOutput:
        """Stop the mission: its fallback (or ``fallback``, e.g. a return home) takes over."""
        if self._in_fallback or self._current is None:
            return self._output(None, (), [self._event(
                "aborted", f"abort requested ({reason}): already stopping")], "")
        self._status = "aborted"
        self._failure = reason
        return self._enter_fallback(inputs, [self._event("aborted", f"aborted: {reason}")],
                                    fallback)

    def fail(self, reason: str, inputs: BehaviorInputs) -> MissionOutput:
        """The running step fails (an exception in it, or in the perception it flies on):
        the fallback takes over, as for a step that reports its own failure."""
        if self._in_fallback or self._current is None:
            return self._output(None, (), [self._event(
                "step_failed", f"failure ({reason}) while already stopping")], "")
        name = self._current.name
        self._status = "failed"
        self._failure = f"{name}: {reason}"
        return self._enter_fallback(inputs, [self._event("step_failed",
                                                         f"step {name} failed: {reason}")])

    @property
    def in_fallback(self) -> bool:
        return self._in_fallback

    @property
    def step_index(self) -> int:
        return -1 if self._in_fallback or self._current is None else self._index

    def _event(self, kind: str, text: str) -> MissionEvent:
        return MissionEvent(kind, self.step_index, self.step_name, text)

    # -- internals --------------------------------------------------------------------------

    def _handle(self, out: BehaviorOutput, inputs: BehaviorInputs,
                events: list[str]) -> MissionOutput:
        photos, _, plan, _ = self._extras  # (a step's last tick and the next one's add up)
        self._extras = (photos + tuple((self._index, ph) for ph in out.photos), out.progress,
                        plan if out.plan is None else
                        dict(out.plan, step_index=self._index, step=self._current.name),
                        out.photo_soon)
        if out.status is Status.RUNNING:
            return self._output(out.setpoint, out.requests, events, out.phase)
        name = self._current.name
        if self._in_fallback:
            events.append(self._event("fallback_ended", f"{name} {out.status.value}"
                                      + (f": {out.reason}" if out.reason else "")))
            if out.status is Status.FAILED:
                self._status = "failed"
            self._current = None
            return self._output(out.setpoint, out.requests, events, out.phase, finished=True)
        if self._waiting is not None:  # a goal ended: back to the step that waits for goals
            if out.status is Status.SUCCEEDED:
                events.append(self._event("step_succeeded", f"goal {name} succeeded"))
            else:
                events.append(self._event("step_failed", f"goal {name} failed: {out.reason}"))
            return self._resume(inputs, events)
        if out.status is Status.SUCCEEDED:
            events.append(self._event("step_succeeded", f"step {name} succeeded"))
            return self._advance(inputs, events, out.setpoint)
        self._status = "failed"
        self._failure = f"{name}: {out.reason}"
        return self._enter_fallback(inputs, [*events, self._event(
            "step_failed", f"step {name} failed: {out.reason}")])

    def _advance(self, inputs: BehaviorInputs, events: list[str],
                 setpoint: Setpoint | None = None) -> MissionOutput:
        self._index += 1
        if self._index >= len(self.behaviors):
            self._current = None
            if self._status == "running":
                self._status = "completed"
            events.append(MissionEvent("mission_completed", -1, "", "mission completed"))
            return self._output(setpoint, (), events, "", finished=True)
        self._current = self.behaviors[self._index]
        events.append(self._event("step_started", f"step {self._current.name} started"))
        return self._handle(self._current.activate(inputs), inputs, events)

    def _resume(self, inputs: BehaviorInputs, events: list) -> MissionOutput:
        self._index, self._current = self._waiting
        self._waiting = None
        events.append(self._event("standby", f"{self._current.name}: waiting for goals"))
        return self._handle(self._current.activate(inputs), inputs, events)

    def _enter_fallback(self, inputs: BehaviorInputs, events: list,
                        fallback: Callable[[], Behavior] | None = None) -> MissionOutput:
        self._in_fallback = True
        self._waiting = None
        self._current = (fallback or self.fallback)()
        events.append(self._event("fallback_started", f"fallback {self._current.name} started"))
        return self._handle(self._current.activate(inputs), inputs, events)

    def _output(self, setpoint, requests, events, phase, finished=False) -> MissionOutput:
        photos, progress, plan, soon = self._extras
        self._extras = ((), float("nan"), None, False)
        return MissionOutput(setpoint, tuple(requests), tuple(events), finished, self._status,
                             self.step_name, phase, self.step_index, photos, progress, plan,
                             soon)
