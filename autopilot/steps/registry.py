"""The registry of mission step kinds.

A step kind is everything the project knows about one kind of mission step, in one place:
its parameter model (what a mission file may say), how to build its behaviour, the perception
pipelines it needs (each on a named camera), the metrics it is scored by, the report panels
that show it, and what the flight log's plan record keeps about it. The runtime, the mission
loader, the summary, the report and replay ask this registry; adding a mission is adding one
module that registers its step kind (see :mod:`autopilot.steps`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any

from autopilot.behaviors.base import Behavior, BehaviorInputs, Params
from autopilot.config import AppConfig
from autopilot.pipeline import PipelineSpec
from autopilot.status import MissionStatus
from drivers.base import CameraInfo

#: (start, end) times of the intervals a step ran in
Intervals = list[tuple[float, float]]


@dataclass(frozen=True, slots=True)
class StepContext:
    """What building a behaviour may use: the configuration and the vehicle's cameras."""

    config: AppConfig
    cameras: Mapping[str, CameraInfo]
    #: runs heavy planning off the control loop (the runtime's planner thread in real time);
    #: None: the behaviour plans at once (lockstep, tests)
    offload: Callable[[Callable[[], object]], Future] | None = None


def _no_pipelines(params: Params, config: AppConfig) -> tuple[PipelineSpec, ...]:
    return ()


def _no_info(params: Params, config: AppConfig) -> dict:
    return {}


def _no_check(params: Params, config: AppConfig) -> None:
    return None


def _no_camera(params: Params, config: AppConfig) -> str | None:
    return None


def _no_warnings(params: Params, config: AppConfig) -> tuple[str, ...]:
    return ()


def _no_needs(params: Params, config: AppConfig) -> tuple[str, ...]:
    return ()


@dataclass(frozen=True, slots=True)
class Figure:
    """One number the terminal shows of a finished step: ``key`` of its metric group
    ``group``, with what it is (``label``) and its unit (``"%"``: a share shown as a
    percentage; ``""``: a count or a yes/no)."""

    group: str
    key: str
    label: str
    unit: str = ""
    after: str = ""  # what follows the number (e.g. "of the step")

    def text(self, groups: Mapping[str, Mapping]) -> str | None:
        value = (groups.get(self.group) or {}).get(self.key)
        if value is None or isinstance(value, (dict, list)):
            return None
        after = f" {self.after}" if self.after else ""
        if isinstance(value, bool):
            return f"{self.label} {'yes' if value else 'no'}{after}"
        if self.unit == "%":
            return f"{self.label} {100 * value:.1f} %{after}"
        unit = f" {self.unit}" if self.unit else ""
        if isinstance(value, float):
            digits = 1 if self.unit in ("px", "s", "°", "ms") else 3
            return f"{self.label} {value:.{digits}f}{unit}{after}"
        return f"{self.label} {value}{unit}{after}"


#: the follow metrics a replay recomputes (the others describe the flight itself)
FOLLOW_REPLAY_KEYS = ("detection_rate", "frames_in_view", "frames_processed",
                      "false_detection_rate", "max_lost_s")
#: a landing's detection figures a replay recomputes
LANDING_REPLAY_KEYS = ("frames", "detected_frames", "found_after_s")

#: what the terminal shows of the estimate a step flew on (a followed or landed-on target)
ESTIMATE_FIGURES = (
    Figure("estimation", "rms_relative_position_error_m", "estimate flown on: relative error RMS",
           "m"),
    Figure("estimation", "relative_within_2sigma", "within its 2σ", "%"),
    Figure("estimation", "rms_position_error_m", "world position error RMS", "m"),
    Figure("estimation", "rms_velocity_error_m_s", "velocity error RMS", "m/s"),
    Figure("estimation", "coasting_share", "coasting (predicted, not seen)", "%",
           "of the step"),
    Figure("estimation", "lost_share", "target lost (no estimate)", "%", "of the step"),
)


@dataclass(frozen=True)
class StepKind:
    name: str
    params: type[Params]
    behavior: Callable[[Params, StepContext], Behavior]
    #: the perception pipelines the step needs while it runs (the first is its target's)
    pipelines: Callable[[Params, AppConfig], tuple[PipelineSpec, ...]] = _no_pipelines
    #: its metrics: (log records, the intervals it ran in, its plan record) → metric groups
    metrics: Callable[[Mapping[str, Sequence[Mapping]], Intervals, Mapping], dict] | None = None
    #: the report's panels that show it (names in autopilot.report)
    report: tuple[str, ...] = ()
    #: what the plan record keeps about it beyond its parameters (e.g. the standoff flown)
    plan_info: Callable[[Params, AppConfig], dict] = _no_info
    description: str = ""
    #: what the step needs of the configuration, beyond its own parameters (raises ValueError
    #: naming what is wrong; checked when the mission loads, before anything flies)
    check: Callable[[Params, AppConfig], None] = _no_check
    #: its mission status codes (registered with autopilot.status.register_status): while it
    #: runs, once it has succeeded; None: what the vehicle is doing says (3 hover in the air,
    #: 0 idle on the ground)
    status: tuple[int, int] | None = (3, 3)
    #: the camera it takes photos with (its frames are kept while it runs), or None
    photo_camera: Callable[[Params, AppConfig], str | None] = _no_camera
    #: where it would fly and how far, from where the vehicle is (``inputs``): raises
    #: ValueError (a LimitError naming its key) beyond the plan bounds or the geofence; a goal
    #: is checked so before it is accepted. None: a kind that plans no path
    reach: Callable[[Params, AppConfig, BehaviorInputs], None] | None = None
    #: what the terminal shows of it when the run ends (its main figures first); each tuple
    #: is one line
    summary: tuple[tuple[Figure, ...], ...] = ()
    #: what may not go as its author expects though it can fly (shown before the flight)
    warnings: Callable[[Params, AppConfig], tuple[str, ...]] = _no_warnings
    #: what ``autopilot replay`` recomputes of its metrics: per metrics group, the keys (what
    #: the detector saw in its frames; the flight's path and errors stay the flight's), or
    #: None for the whole group
    replay: Mapping[str, tuple[str, ...] | None] = field(default_factory=dict)
    #: a step that waits for the goal API's goals (standby): not a goal itself; the goals'
    #: default photo camera is kept ready while it runs
    waits_for_goals: bool = False
    #: whether a step with these parameters has no end of its own (it waits until told: a
    #: mission with such a step that waits for goals needs the goal API)
    endless: Callable[[Params], bool] = lambda params: False
    #: example parameters, for the goal API's documentation (the first kind with one is shown)
    example: Mapping[str, Any] | None = None
    #: what a step with these parameters needs of its vehicle beyond the vehicle interface
    #: (names in :data:`drivers.capabilities.NEEDS`): a vehicle that lacks one is refused
    #: before takeoff
    needs: Callable[[Params, AppConfig], tuple[str, ...]] = _no_needs


STEP_KINDS: dict[str, StepKind] = {}


def register(kind: StepKind) -> StepKind:
    if kind.name in STEP_KINDS:
        raise ValueError(f"step kind {kind.name!r} is registered twice")
    for code in kind.status or ():
        MissionStatus(code)  # raises unless registered (autopilot.status.register_status)
    STEP_KINDS[kind.name] = kind
    return kind


def step_kind(name: str) -> StepKind:
    try:
        return STEP_KINDS[name]
    except KeyError:
        raise KeyError(f"no step kind {name!r} (known: {', '.join(sorted(STEP_KINDS))})") \
            from None


def summary_lines(metrics: Mapping) -> list[str]:
    """The terminal's lines for a flight's scored steps: each step's figures (its kind's
    :attr:`StepKind.summary`), a line per group of them."""
    lines = []
    for step in metrics.get("steps") or ():
        kind = STEP_KINDS.get(step.get("name"))
        if kind is None:
            continue
        for i, figures in enumerate(kind.summary):
            texts = [t for t in (f.text(step) for f in figures) if t is not None]
            if texts:
                head = f"step {step['index']} {step['name']}: " if i == 0 else "  "
                lines.append(head + ", ".join(texts))
    return lines
