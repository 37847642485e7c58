"""The mission recorder: what the flight log keeps of the mission (its plan, its events, its
status codes, the target the behaviours flew on, the simulator's ground truth) and what the
hooks hear of it."""

from __future__ import annotations

import contextlib
from collections.abc import Callable

from autopilot.behaviors.base import BehaviorInputs
from autopilot.estimation.target import TargetEstimate
from autopilot.flightlog import records as ch
from autopilot.hooks import Event
from autopilot.mission import MissionEvent, Step
from autopilot.runtime.flight import Flight
from autopilot.status import MissionStatus, StatusTracker
from autopilot.steps import step_kind
from drivers.base import VehicleState

#: a mission event's outcome, for the hooks' ``step_ended``
_OUTCOMES = {"step_succeeded": "succeeded", "step_failed": "failed",
             "goal_cancelled": "cancelled"}


class MissionRecorder:
    def __init__(self, flight: Flight) -> None:
        self.flight = flight
        self.status_tracker = StatusTracker()
        self._status_logged: MissionStatus | None = None
        #: the goal (its id) a step index ran, if any (the goal desk answers)
        self.goal_id_of: Callable[[int], str | None] = lambda index: None
        #: told of every mission event before the status follows it (the goal desk)
        self.listeners: list[Callable[[MissionEvent], None]] = []

    # -- the plan --------------------------------------------------------------------------

    def step_record(self, index: int, step: Step) -> dict:
        """What the flight log keeps about a step (or a goal), for scoring and replay."""
        config = self.flight.config
        kind = step_kind(step.name)
        specs = kind.pipelines(step.params, config)
        return ch.clean({
            "name": step.name, "index": index, "params": step.params.model_dump(),
            "pipelines": [{"name": spec.key, "kind": spec.kind, "camera": spec.camera,
                           "truth_body": spec.truth_body, "size_m": spec.target_size_m,
                           "target": spec.target}
                          for spec in specs],
            **kind.plan_info(step.params, config)})

    def log_plan(self) -> None:
        f = self.flight
        plan, now = f.plan, f.clock.now()
        steps = [self.step_record(index, step) for index, step in enumerate(plan.steps)]
        f.log.write(ch.MISSION_PLAN, now, ch.clean({
            "mission": plan.mission.name, "source": str(plan.source), "steps": steps,
            # (sim.cameras is a copy of vehicle.cameras, not a setting of its own)
            "config": f.config.model_dump(mode="json", exclude={"sim": {"cameras"}}),
            "driver": f.config.driver,
            "scenario": plan.mission.scenario.model_dump() if plan.mission.scenario else None}))
        for camera in f.vehicle.cameras.values():
            f.log.write(ch.CAMERA_INFO, f.clock.now(), ch.camera_info_record(camera))

    def log_truth_cameras(self, cameras) -> None:
        """The cameras as they really are (the simulator: for scoring only)."""
        for camera in cameras.values():
            self.flight.log.write(ch.CAMERA_TRUTH, self.flight.clock.now(),
                                  ch.camera_info_record(camera))

    def log_goal(self, index: int, step: Step, goal_id: str) -> None:
        now = self.flight.clock.now()
        self.flight.log.write(ch.MISSION_GOALS, now, ch.clean({
            **self.step_record(index, step), "goal_id": goal_id, "time_s": now}))

    # -- events ----------------------------------------------------------------------------

    def event(self, time_s: float, kind: str, text: str) -> None:
        """The runtime's own events (``request``, ``runtime``, ``failsafe``, ``console``), in
        the running step."""
        cursor = self.flight.cursor
        self.write_event(time_s, kind, cursor.index, cursor.step, text)

    def failsafe(self, name: str, text: str) -> None:
        """A failsafe acting: the log's event and the hooks' (``mission``/``name``)."""
        now = self.flight.clock.now()
        self.event(now, "failsafe", text)
        self.flight.events.emit(Event("mission", name, now, text))

    def console(self, time_s: float, name: str, text: str, data: dict | None = None) -> None:
        """What the console did (or refused): the log's event and the hooks' (``console``)."""
        self.event(time_s, "console", text)
        self.flight.events.emit(Event("console", name, time_s, text, data=data or {}))

    def write_event(self, time_s: float, kind: str, index: int, step: str, text: str) -> None:
        f = self.flight
        f.log.write(ch.MISSION_EVENTS, time_s, {"time_s": time_s, "kind": kind,
                                                 "step_index": index, "step": step,
                                                 "text": text})
        if f.progress is not None and kind != "request":
            f.progress(f"[{time_s:7.2f} s] {text}")

    def mission_event(self, time_s: float, event: MissionEvent) -> None:
        """A mission event: logged, told to the hooks and the listeners, and the status code
        it brings."""
        f = self.flight
        self.write_event(time_s, event.kind, event.step_index, event.step, event.text)
        data = {"step_index": event.step_index, "step": event.step, "event": event.kind}
        if event.kind == "step_started":
            f.events.emit(Event("step_started", event.step, time_s, event.text, data=data))
        elif event.kind in _OUTCOMES:
            f.events.emit(Event("step_ended", event.step, time_s, event.text,
                                data={**data, "outcome": _OUTCOMES[event.kind]}))
        else:
            f.events.emit(Event("mission", event.kind, time_s, event.text, data=data))
        for listener in self.listeners:
            listener(event)
        tracker = self.status_tracker
        codes = step_kind(f.book.steps[event.step_index].name).status \
            if event.step_index >= 0 else None
        if event.kind == "step_started" and event.step_index >= 0:
            self.set_status(tracker.step_started(codes) if codes is not None
                            else tracker.idle(f.in_air), event.step_index)
        elif event.kind == "step_succeeded" and codes is not None:
            self.set_status(tracker.step_succeeded(codes), event.step_index)
        elif event.kind in ("fallback_started", "aborted"):
            self.set_status(tracker.abort())
        elif event.kind in ("waiting_for_goals", "goal_cancelled"):
            self.set_status(tracker.idle(f.in_air), event.step_index)

    @property
    def status_code(self) -> MissionStatus:
        return self.status_tracker.code

    def set_status(self, code: MissionStatus, step_index: int | None = None) -> None:
        if code == self._status_logged:
            return
        self._status_logged = code
        f = self.flight
        now = f.clock.now()
        index = f.cursor.index if step_index is None else step_index
        step = f.book.name(index)
        f.log.write(ch.MISSION_STATUS, now, {
            "time_s": now, "code": int(code), "status": code.label, "step": step,
            "step_index": index, "goal_id": self.goal_id_of(index)})
        f.events.emit(Event("status", code.label, now, f"status {int(code)} {code.label}",
                            data={"code": int(code), "step": step}))

    def state_events(self, previous: VehicleState | None, state: VehicleState) -> None:
        """The vehicle's mode, arming and failsafe changes, for the hooks."""
        f = self.flight
        f.stats.armed = f.stats.armed or state.armed
        if previous is None:
            return
        t = state.time_s
        if state.mode is not previous.mode:
            f.events.emit(Event("mode", state.mode.value, t, f"mode {state.mode.value}",
                                data={"previous": previous.mode.value}))
        if state.armed != previous.armed:
            name = "armed" if state.armed else "disarmed"
            f.events.emit(Event("armed", name, t, name))
        if state.failsafe and not previous.failsafe:
            f.events.emit(Event("mission", "failsafe", t, "vehicle failsafe",
                                data={"failsafe": state.failsafe}))

    # -- what the behaviours flew on -------------------------------------------------------

    def control_target(self, inputs: BehaviorInputs) -> None:
        """The target the behaviour is about to act on, as it saw it (scored by the metrics,
        coasting and lost stretches included)."""
        percept = inputs.percept
        if percept is None:
            return
        cursor = self.flight.cursor
        est: TargetEstimate | None = inputs.target
        record = {"time_s": inputs.now_s, "pipeline": percept.pipeline, "step": cursor.step,
                  "step_index": cursor.index, "present": est is not None}
        if est is not None:
            record.update(position_ned_m=est.position_ned_m,
                          velocity_ned_m_s=est.velocity_ned_m_s,
                          position_std_m=est.position_std_m, age_s=est.age_s,
                          stale=est.stale, confirmed=est.confirmed)
        self.flight.log.write(ch.CONTROL_TARGET, inputs.now_s, record)

    # -- the vehicle's extras: ground truth (scoring only), its status messages ------------

    async def record_truth(self, stream) -> None:
        async with contextlib.aclosing(stream(buffer=1024)) as samples:
            async for gt in samples:
                self.flight.log.write(ch.GROUND_TRUTH, gt.time_s, ch.ground_truth_record(gt))

    async def record_status_texts(self, stream) -> None:
        async with contextlib.aclosing(stream(buffer=64)) as messages:
            async for time_s, text in messages:
                self.flight.log.write(ch.VEHICLE_STATUS, time_s,
                                      {"time_s": time_s, "text": text})
                self.flight.events.emit(Event("status_text", "status_text", time_s, text))
