"""Goals at runtime (seed 004's action servers): steps sent while a standby step waits.

A goal is one mission step — ``{"orbit": {...}}`` exactly as in a mission file — validated the
same way (its parameter model, then what it needs of the configuration), before it is queued.
:class:`GoalManager` keeps every goal's record and the requests from outside (submit, cancel,
abort); the runtime's control loop serves them at its next tick, so nothing here touches the
vehicle or blocks. Only one goal runs at a time, and only while the mission waits for goals
(a standby step: status 0 idle on the ground, 3 hovering); anything else is refused with the
reason, as seed 004 refused a goal while another ran.
"""

from __future__ import annotations

import itertools
import math
import secrets
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from autopilot.behaviors.base import BehaviorInputs
from autopilot.behaviors.trajectory_plan import LimitError
from autopilot.config import AppConfig
from autopilot.mission import Step
from autopilot.status import MissionStatus
from autopilot.steps import STEP_KINDS


class GoalError(Exception):
    """A goal refused: ``status`` is the HTTP status (404 unknown, 409 not now, 422 invalid)."""

    def __init__(self, status: int, reason: str, problems: list[dict] | None = None) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason
        self.problems = problems or []

    def as_dict(self) -> dict:
        out: dict[str, Any] = {"error": self.reason}
        if self.problems:
            out["problems"] = self.problems
        return out


def goal_kinds() -> list[str]:
    """The step kinds the goal API takes (all but those that wait for goals)."""
    return [name for name, kind in STEP_KINDS.items() if not kind.waits_for_goals]


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def validate_goal(body: Any, config: AppConfig, site: BehaviorInputs | None = None) -> Step:
    """A goal body as a validated step; :class:`GoalError` (422) naming the bad key.

    ``site``: where the vehicle is now (its position, home, global origin): a goal that plans a
    path is then checked against the plan bounds and the geofence from there — too long, too
    many photos, too far or high from home, or below ``failsafe.geofence.min_altitude_m`` — and
    refused naming the key and the limit, before it starts."""
    if not isinstance(body, dict) or len(body) != 1 or not isinstance(next(iter(body)), str):
        raise GoalError(422, "a goal is one step: {\"KIND\": {parameters}}, e.g. "
                        "{\"goto\": {\"position_m\": [5, 0, 3]}}",
                        [{"key": "", "error": f"expected an object with one key, got "
                                              f"{type(body).__name__}"}])
    (name, params), = body.items()
    if name not in goal_kinds():
        raise GoalError(422, f"unknown goal kind {name!r}",
                        [{"key": name, "error": f"known: {', '.join(goal_kinds())}"}])
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise GoalError(422, f"{name}: parameters must be an object",
                        [{"key": name, "error": f"expected an object, got "
                                                f"{type(params).__name__}"}])
    kind = STEP_KINDS[name]
    try:
        model = kind.params.model_validate(params)
    except ValidationError as exc:
        problems = []
        for err in exc.errors(include_url=False):
            key = ".".join(str(p) for p in (name, *err["loc"]))
            message = {"extra_forbidden": "unknown key",
                       "missing": "missing required key"}.get(
                err["type"], f"{err['msg']} (got {_short(err.get('input'))})")
            problems.append({"key": key, "error": message})
        # the input is echoed once, shortened, in the problem that names its key
        raise GoalError(422, f"invalid {name} goal: " + ", ".join(
            p["key"] for p in problems), problems) from None
    try:
        kind.check(model, config)
        kind.pipelines(model, config)
        if kind.reach is not None:
            kind.reach(model, config, site)
    except LimitError as exc:
        key = f"{name}.{exc.key}"
        raise GoalError(422, f"{name}: {exc}", [{"key": key, "error": str(exc)}]) from None
    except ValueError as exc:
        raise GoalError(422, f"{name}: {exc}", [{"key": name, "error": str(exc)}]) from None
    return Step(name, model)


@dataclass
class Goal:
    id: str
    step: Step
    created_s: float
    #: queued, running, succeeded, failed, cancelled, aborted (shown as "cancelling" between
    #: a cancel and the control loop's next tick)
    state: str = "queued"
    index: int = -1  # its step index in the run (after the mission's steps)
    started_s: float | None = None
    ended_s: float | None = None
    reason: str = ""
    phase: str = ""
    progress: float = math.nan
    photos: int = 0
    cancel_requested: bool = False

    @property
    def active(self) -> bool:
        return self.state in ("queued", "running")

    def as_dict(self) -> dict:
        return {
            "goal_id": self.id, "kind": self.step.name,
            "params": self.step.params.model_dump(mode="json"),
            "state": "cancelling" if self.cancel_requested and self.active else self.state,
            "created_s": self.created_s, "started_s": self.started_s, "ended_s": self.ended_s,
            "feedback": {"phase": self.phase,
                         "progress": self.progress if math.isfinite(self.progress) else None,
                         "photos": self.photos},
            "result": None if self.active else {"state": self.state, "reason": self.reason,
                                                "photos": self.photos},
        }


@dataclass
class GoalManager:
    """Goals and the requests about them, shared by the API (which submits) and the runtime
    (which serves them). All methods run on the event loop's thread."""

    config: AppConfig
    goals: dict[str, Goal] = field(default_factory=dict)
    abort_requested: str | None = None
    _counter: itertools.count = field(default_factory=lambda: itertools.count(1))

    def submit(self, step: Step, now_s: float, status: MissionStatus,
               waiting_for_goals: bool, in_air: bool,
               cameras: Sequence[str] | None = None, vehicle: object | None = None) -> Goal:
        """Queue a validated goal (:func:`validate_goal`), or :class:`GoalError` (409) saying
        why not now. ``cameras``: the vehicle's (a goal needing another is refused);
        ``vehicle``: a goal needing what it lacks (:data:`drivers.capabilities.NEEDS`: a
        survey's geotagged photos without GNSS) is refused, as a mission is before it flies."""
        running = self.running()
        if running is not None:
            raise GoalError(409, f"goal {running.id} ({running.step.name}) is {running.state}: "
                            "cancel it first, or wait for it to end")
        if self.abort_requested is not None or status is MissionStatus.ABORT:
            raise GoalError(409, "the mission is aborting (hold, land, disarm): no goals")
        if not waiting_for_goals:
            raise GoalError(409, f"the mission is busy (status {int(status)} {status.label}); "
                            "goals are taken while a standby step waits (status 0 or 3)")
        if step.name == "takeoff" and in_air:
            raise GoalError(409, "already flying (hovering): a takeoff goal is for the ground")
        if step.name != "takeoff" and not in_air and step.name not in ("land", "hold"):
            raise GoalError(409, f"on the ground: take off first (a {step.name} goal flies)")
        if cameras is not None:
            kind = STEP_KINDS[step.name]
            needed = [spec.camera for spec in kind.pipelines(step.params, self.config)]
            photo = kind.photo_camera(step.params, self.config)
            missing = [c for c in dict.fromkeys([*needed, *([photo] if photo else [])])
                       if c not in cameras]
            if missing:
                raise GoalError(409, f"this vehicle has no camera {missing[0]!r} attached "
                                f"(attached: {', '.join(cameras) or 'none'})")
        if vehicle is not None:
            from drivers.capabilities import NEEDS, lacks

            missing = lacks(vehicle, STEP_KINDS[step.name].needs(step.params, self.config))
            if missing:
                raise GoalError(409, f"a {step.name} goal needs {NEEDS[missing[0]][1]} "
                                f"({missing[0]}), which this vehicle does not have")
        goal = Goal(f"g{next(self._counter)}-{secrets.token_hex(3)}", step, now_s)
        self.goals[goal.id] = goal
        return goal

    def running(self) -> Goal | None:
        return next((g for g in self.goals.values() if g.active), None)

    def get(self, goal_id: str) -> Goal:
        try:
            return self.goals[goal_id]
        except KeyError:
            raise GoalError(404, f"no goal {goal_id!r}") from None

    def cancel(self, goal_id: str) -> Goal:
        goal = self.get(goal_id)
        if not goal.active:
            raise GoalError(409, f"goal {goal_id} has already ended ({goal.state})")
        goal.cancel_requested = True
        return goal

    def abort(self, reason: str = "abort requested") -> None:
        if self.abort_requested is None:
            self.abort_requested = reason
