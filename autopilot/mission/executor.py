"""The mission executor: runs the steps' behaviours in order, hands a failed step over to
the fallback, and runs the goal API's goals in a waiting step's place; the runtime drives it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Status,
    VehicleRequest,
)
from autopilot.behaviors.flight import SafeStop
from drivers.base import Setpoint


@dataclass(frozen=True, slots=True)
class MissionEvent:
    """Something the mission did, as the flight log keeps it (``/mission/events``).

    ``kind``: ``step_started``, ``step_succeeded``, ``step_failed``, ``fallback_started``,
    ``fallback_ended``, ``mission_completed``, ``aborted``, ``request_refused``,
    ``goal_cancelled``, ``waiting_for_goals`` (back to waiting) (the mission), ``request``,
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
        events.append(self._event("waiting_for_goals", f"{self._current.name}: waiting for goals"))
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
