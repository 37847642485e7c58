"""The watch: what the target kinds watch over every flight with (:mod:`autopilot.watch`) —
watchers run on the frames the running step's lanes already receive, after the step's own
pipelines (so they never delay what the step flies on), and setpoint guards every setpoint
streamed passes through. What they report goes to the flight log; each intervention of a guard
(on one subject — a zone —, as long as it keeps acting on it: a gap of up to
:data:`INTERVENTION_GAP_S` continues it) is a mission event, told to the hooks, and counted in
the run's stats; every setpoint a guard changed is logged (``/control/guard``) and counted."""

from __future__ import annotations

import logging
from concurrent.futures import Executor

from autopilot.flightlog import records as ch
from autopilot.hooks import Event
from autopilot.runtime.flight import Flight
from autopilot.runtime.perception import detect_all, detection_charge
from autopilot.runtime.recorder import MissionRecorder
from autopilot.watch import SetpointGuard, Watcher, make_watch
from drivers.base import Frame, Setpoint, VehicleState

log = logging.getLogger(__name__)

#: a guard acting on the same subject again within this of its last change to a setpoint goes
#: on with the same intervention (at a zone's edge, the pass-through and the push-out alternate)
INTERVENTION_GAP_S = 1.0


class Watch:
    def __init__(self, flight: Flight, recorder: MissionRecorder) -> None:
        self.flight = flight
        self.recorder = recorder
        parts = make_watch(flight.config)
        self.watchers: list[Watcher] = [p for p in parts if isinstance(p, Watcher)]
        self.guards: list[SetpointGuard] = [p for p in parts if isinstance(p, SetpointGuard)]
        #: each guard's running intervention: its subject, and when it last acted on it
        self._running: dict[str, tuple[str, float]] = {}
        self._failed: set[str] = set()  # watchers whose detector raised (said once)

    def add_state(self, state: VehicleState) -> None:
        for watcher in self.watchers:
            watcher.add_state(state)

    async def look(self, frame: Frame, executor: Executor) -> None:
        """The watchers that take ``frame``, run on it (charged on the lockstep clock as
        their kinds' cost), their reports logged."""
        f = self.flight
        watchers = [w for w in self.watchers if w.looks_at(frame.camera.name, frame.seq)]
        if not watchers:
            return
        results = await f.clock.run_blocking(
            detect_all, watchers, frame, [None] * len(watchers), executor=executor,
            budget_s=detection_charge(f.config, [w.kind for w in watchers]))
        now = f.clock.now()
        for watcher, (detection, _ms, error) in zip(watchers, results, strict=True):
            if error is not None:  # (a watcher's failure does not fail the step)
                if watcher.name not in self._failed:
                    self._failed.add(watcher.name)
                    self.recorder.event(now, "runtime", f"the {watcher.name} watcher raised "
                                        f"{error}; it goes on with the next frames")
                continue
            report = watcher.update(frame.time_s, frame.seq, frame.camera, detection)
            for topic, record in report.records:
                f.log.write(topic, frame.time_s, record)
            for note in report.notes:
                self.recorder.event(now, "watch", note)
                f.events.emit(Event("mission", "watch", now, note, data={"watcher":
                                                                         watcher.name}))

    def guard(self, setpoint: Setpoint, state: VehicleState | None, step: str,
              phase: str) -> Setpoint:
        """``setpoint`` through every guard, in order, for the vehicle in ``state``."""
        if state is None or not self.guards:
            return setpoint
        f = self.flight
        for guard in self.guards:
            result = guard.guard(setpoint, state)
            if result.action is None:
                continue
            setpoint = result.setpoint
            now = f.clock.now()
            f.stats.guarded_setpoints += 1
            running = self._running.get(guard.name)
            self._running[guard.name] = (result.subject, now)
            if running is None or running[0] != result.subject or \
                    now - running[1] > INTERVENTION_GAP_S:  # a new intervention begins
                f.stats.guard_interventions += 1
                self.recorder.event(now, "guard", result.text)
                f.events.emit(Event("mission", "guard", now, result.text,
                                    data={"guard": guard.name, "action": result.action,
                                          "subject": result.subject}))
            f.log.write(ch.GUARDED_SETPOINTS, now, {
                "time_s": now, "guard": guard.name, "action": result.action,
                "subject": result.subject, "step": step, "phase": phase, **result.record})
        return setpoint
