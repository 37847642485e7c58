"""The goal desk: what the goal API asks of a flight (its status, a goal's reach checked where
the vehicle is, goals queued, cancelled, the abort), and the goals served to the mission when
a step waits for them."""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot.behaviors.base import BehaviorInputs
from autopilot.console.view import vehicle_status
from autopilot.goals import Goal, GoalError, GoalManager
from autopilot.mission import MissionEvent, MissionOutput, Step, build_behavior
from autopilot.photo_lane import PhotoLane
from autopilot.runtime.flight import Flight
from autopilot.runtime.perception import PerceptionLanes
from autopilot.runtime.recorder import MissionRecorder
from autopilot.steps import step_kind


class GoalDesk:
    """Implements :class:`autopilot.runtime.ports.GoalDeskPort` for a flight."""

    def __init__(self, flight: Flight, goals: GoalManager | None, recorder: MissionRecorder,
                 perception: PerceptionLanes, photos: PhotoLane, offload,
                 control_by: Callable[[], str]) -> None:
        self.flight = flight
        self.config = flight.config
        self.goals = goals
        self.recorder = recorder
        self.perception = perception
        self.photos = photos
        self.offload = offload  # where a goal's path is planned (None: at once)
        self.control_by = control_by  # "manual" or "autopilot" (the console's Y)
        recorder.goal_id_of = self.goal_id_of
        recorder.listeners.append(self.on_event)

    # -- what the API asks -----------------------------------------------------------------

    def api_status(self) -> dict:
        """The goal API's ``/api/status``: the mission status, the step (or goal) running,
        and the vehicle's state as telemetry says it."""
        f = self.flight
        code = self.recorder.status_code
        goal = self.goals.running() if self.goals is not None else None
        progress = f.cursor.progress
        out = {"status_code": int(code), "status": code.label, "step": f.cursor.step,
               "phase": f.cursor.phase, "goal_id": goal.id if goal is not None else None,
               "time_s": f.clock.now(),
               "progress": progress if math.isfinite(progress) else None,
               "waiting_for_goals": self.waiting_for_goals,
               "control": self.control_by(),
               "photos": self.photos.taken}
        return {**out, **vehicle_status(f.state)}

    @property
    def waiting_for_goals(self) -> bool:
        executor = self.flight.executor
        return executor is not None and executor.accepts_goals

    def goal_site(self) -> BehaviorInputs | None:
        """Where the vehicle is now, for checking a goal's reach before it is accepted (None:
        no telemetry yet)."""
        f = self.flight
        if f.state is None:
            return None
        return BehaviorInputs(now_s=f.clock.now(), state=f.state,
                              home_ned_m=f.vehicle.home_ned_m,
                              global_origin=f.vehicle.global_origin)

    def submit_goal(self, step: Step) -> Goal:
        """A validated goal from the API, queued (or GoalError saying why not now)."""
        if self.goals is None:
            raise GoalError(409, "this run takes no goals")
        f = self.flight
        return self.goals.submit(step, f.clock.now(), self.recorder.status_code,
                                 self.waiting_for_goals, f.in_air,
                                 cameras=list(f.vehicle.cameras), vehicle=f.vehicle)

    def abort(self, reason: str) -> None:
        """The goal API's abort: no more goals; the safe stop (hold, land, disarm), bounded by
        ``shutdown_timeout_s`` as after Ctrl-C."""
        if self.goals is not None:
            self.goals.abort(reason)
        self.flight.request_stop(reason)

    # -- serving the mission ---------------------------------------------------------------

    def serve(self, inputs: BehaviorInputs) -> MissionOutput | None:
        """Serve what the goal API asked since the last tick: an abort, a cancel, a queued
        goal (when the mission waits for one). None: nothing to do."""
        f = self.flight
        executor = f.executor
        if self.goals is None or f.stop_requested.is_set():
            return None
        goal = self.goals.running()
        if goal is None:
            return None
        now = f.clock.now()
        if goal.cancel_requested:
            if goal.state == "queued":
                goal.state, goal.ended_s, goal.reason = "cancelled", now, "cancelled"
                return None
            if executor.goal_running:
                return executor.cancel_goal(inputs)
        if goal.state == "queued" and executor.accepts_goals:
            try:
                return self._start(goal, inputs)
            except Exception as exc:  # a goal that cannot start fails; the flight goes on
                goal.state, goal.ended_s = "failed", now
                goal.reason = f"could not start: {type(exc).__name__}: {exc}"
                self.recorder.event(now, "goal_refused", f"goal {goal.id} {goal.step.name}: "
                                    f"{goal.reason}")
        return None

    def _start(self, goal: Goal, inputs: BehaviorInputs) -> MissionOutput:
        f = self.flight
        now = f.clock.now()
        kind = step_kind(goal.step.name)
        behavior = build_behavior(goal.step, f.config, f.vehicle.cameras, self.offload)
        specs = kind.pipelines(goal.step.params, f.config)
        self.perception.add(specs)
        goal.index = f.book.add(goal.step, tuple(spec.key for spec in specs),
                                kind.photo_camera(goal.step.params, f.config))
        self.recorder.log_goal(goal.index, goal.step, goal.id)
        goal.state, goal.started_s = "running", now
        return f.executor.start_goal(behavior, goal.index, inputs)

    def goal_at(self, index: int) -> Goal | None:
        if self.goals is None or index < self.flight.book.mission_steps:
            return None
        return next((g for g in self.goals.goals.values() if g.index == index), None)

    def goal_id_of(self, index: int) -> str | None:
        goal = self.goal_at(index)
        return goal.id if goal is not None else None

    def follow(self, out: MissionOutput) -> None:
        """A goal's photos, phase and progress, from the mission's output."""
        for index, _ in out.photos:
            goal = self.goal_at(index)
            if goal is not None:
                goal.photos += 1
        goal = self.goal_at(out.step_index)
        if goal is not None and goal.active:
            goal.phase = out.phase
            goal.progress = out.progress

    def on_event(self, event: MissionEvent) -> None:
        """A goal's end (succeeded, failed, cancelled; every active one on an abort)."""
        goal = self.goal_at(event.step_index)
        now = self.flight.clock.now()
        if goal is not None:
            if event.kind == "step_succeeded":
                goal.state, goal.ended_s = "succeeded", now
            elif event.kind == "step_failed":
                goal.state, goal.ended_s, goal.reason = "failed", now, event.text
            elif event.kind == "goal_cancelled":
                goal.state, goal.ended_s, goal.reason = "cancelled", now, "cancelled"
        if event.kind in ("aborted", "fallback_started") and self.goals is not None:
            for g in self.goals.goals.values():
                if g.active:
                    g.state, g.ended_s, g.reason = "aborted", now, event.text
