"""The control loop: a tick on every estimate and at least every control period, in which the
failsafes look first, then the safe stop, the console's keys, the goals, and the running step;
what they decide (a setpoint, vehicle requests, photos, a plan) is applied."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math

import numpy as np

from autopilot.behaviors.base import BehaviorInputs, RequestKind, VehicleRequest
from autopilot.flightlog import records as ch
from autopilot.mission import MissionOutput
from autopilot.photo_lane import PhotoLane
from autopilot.runtime.commands import SetpointStream, VehicleCommands
from autopilot.runtime.console_bridge import ConsoleBridge
from autopilot.runtime.failsafes import Failsafes, Verdict
from autopilot.runtime.flight import Flight
from autopilot.runtime.goal_desk import GoalDesk
from autopilot.runtime.perception import PerceptionLanes
from autopilot.runtime.readout import Readout
from autopilot.runtime.recorder import MissionRecorder
from autopilot.runtime.telemetry import TelemetryIntake
from drivers.base import FlightMode, VehicleError, VehicleState
from drivers.stages import STAGES

log = logging.getLogger(__name__)


def next_tick_due(due_s: float, now_s: float, period_s: float, *, estimate: bool,
                  lockstep: bool) -> float:
    """When the control tick after the one at ``now_s`` is due (at the latest; an estimate
    brings it forward). ``due_s``: when this one was due; ``estimate``: this tick came with
    an estimate. In real time a tick that came late when due does not delay the next one
    (the schedule is kept, as PX4's work queues keep theirs), but no two come closer than
    half a period; after an estimate, or in lockstep, the period counts from now."""
    if estimate or lockstep or now_s < due_s:
        return now_s + period_s
    return max(due_s + period_s, now_s + 0.5 * period_s)


@dataclasses.dataclass
class Rooms:
    """The rooms the control loop drives."""

    recorder: MissionRecorder
    telemetry: TelemetryIntake
    perception: PerceptionLanes
    setpoints: SetpointStream
    commands: VehicleCommands
    failsafes: Failsafes
    desk: GoalDesk
    console: ConsoleBridge
    photos: PhotoLane
    readout: Readout


class ControlLoop:
    def __init__(self, flight: Flight, rooms: Rooms) -> None:
        self.flight = flight
        self.rooms = rooms
        #: the step starts afresh from where the vehicle is at the next tick (back from
        #: manual flight, or from a silence it was told to hold through)
        self.resumed = False
        #: the newest planned path (a counter, north-east points): the console's map
        self.planned_path: tuple[int, list[list[float]]] = (0, [])

    def resume(self) -> None:
        self.resumed = True

    def inputs(self, state: VehicleState) -> BehaviorInputs:
        """What the behaviours see now: the vehicle, and the running step's percepts (its
        first pipeline's target as ``target``). At a step change, the new step is activated
        with the inputs of the moment before it (its pipelines start with it)."""
        f = self.flight
        now = f.clock.now()
        percepts = self.rooms.perception.percepts(now)
        first = percepts[0] if percepts else None
        return BehaviorInputs(now_s=now, state=state,
                              target=first.target if first is not None else None,
                              percept=first, percepts=percepts,
                              home_ned_m=f.vehicle.home_ned_m,
                              global_origin=f.vehicle.global_origin)

    async def next_tick(self, period: float) -> float | None:
        """Wait for a fresh estimate (returns its frame's capture time) or the period."""
        try:
            source = await self.flight.clock.wait_for(self.flight.wake.get(), period)
        except TimeoutError:
            return None
        return None if math.isnan(source) else source

    async def run(self) -> None:
        f, r = self.flight, self.rooms
        clock, executor, failsafes = f.clock, f.executor, r.failsafes
        state = await r.telemetry.first_state()
        out = executor.start(self.inputs(state))
        await self.apply(out)
        period = 1.0 / f.config.runtime.control_rate_hz
        deadline: float | None = None
        # Control runs on every estimate and at least every period. In real time the period
        # counts from when the last tick was due, not from when its work ended: a tick made
        # late by a busy CPU (the loop's thread waiting for a core) or by its own work does
        # not delay the next one (next_tick_due). Lockstep keeps its schedule as it was: a
        # period from the end of each tick.
        next_tick_s = clock.now() + period
        while not out.finished:
            wait_s = period if clock.lockstep else max(0.0, next_tick_s - clock.now())
            source = await self.next_tick(wait_s)
            failsafes.last_tick_s = now = clock.now()
            next_tick_s = next_tick_due(next_tick_s, now, period, estimate=source is not None,
                                        lockstep=clock.lockstep)
            with STAGES.stage("control"):
                inputs = self.inputs(f.state)
            r.recorder.control_target(inputs)
            verdict, taken = await failsafes.check_link(inputs)
            if verdict is Verdict.GO_ON:
                r.readout.publish(inputs)
                verdict, taken = await failsafes.check_flight(inputs)
            if verdict is Verdict.END:
                return
            if verdict is Verdict.NEXT:
                if taken is not None:
                    out = taken
                    await self.apply(out, None)
                continue
            if f.stop_requested.is_set() and deadline is None:
                r.console.hand_back()  # the safe stop flies, whatever the console asked
                deadline = clock.now() + f.config.runtime.shutdown_timeout_s
                out = executor.abort(f.stop_reason or "stop requested", inputs)
            elif deadline is not None and clock.now() > deadline:
                f.status, f.reason = "failed", "safe stop did not finish in time"
                await failsafes.last_resort()
                return
            elif (console := r.console.tick(inputs)) is not None:
                out = console
            elif self.resumed and executor.accepts_goals:
                self.resumed = False  # a step waiting for goals waits here, not back there
                out = executor.reactivate(inputs, "back from manual flight")
            else:
                try:
                    with STAGES.stage("control"):
                        out = r.desk.serve(inputs) or executor.update(inputs)
                except Exception as exc:  # a bug in the step: it fails, the fallback flies
                    if executor.in_fallback:
                        raise
                    log.exception("step %s raised", executor.step_name)
                    out = await failsafes.take_over(
                        f"the step raised {type(exc).__name__}: {exc}", inputs, fail=True)
                    await self.apply(out, source)
                    continue
                out = self._after_manual(out, inputs)
            await self.apply(out, source)
            await r.console.perform()
        f.status = executor.status
        f.reason = executor.failure
        s = f.state
        if s is not None and s.in_air and s.armed and not failsafes.stale:
            # a mission that ends in the air (its last step a goto, a timed standby, …) leaves
            # the vehicle in the vehicle's own position hold, not in OFFBOARD without setpoints
            r.setpoints.drop()
            r.recorder.event(clock.now(), "runtime", "mission ended in the air: holding")
            with contextlib.suppress(VehicleError, TimeoutError):
                await clock.wait_for(f.vehicle.hold(), 2.0)

    def _after_manual(self, out: MissionOutput, inputs: BehaviorInputs) -> MissionOutput:
        """The step's output, the first tick back from manual flight: its mode asked again."""
        if self.resumed and out.setpoint is None and inputs.state.in_air:
            # a step flown by the vehicle's own modes (land, hold, the safe stop): it asks
            # for its mode again (manual flight left OFFBOARD behind)
            out = self.flight.executor.reactivate(inputs, "back from manual flight")
        elif self.resumed and out.setpoint is not None and inputs.state.in_air and \
                inputs.state.mode is not FlightMode.OFFBOARD:
            # back from manual flight out of OFFBOARD (after T, or a landing stopped): the
            # step's setpoints need OFFBOARD again
            out = dataclasses.replace(out, requests=(
                VehicleRequest(RequestKind.START_OFFBOARD), *out.requests))
        self.resumed = False
        return out

    async def apply(self, out: MissionOutput, source_frame_s: float | None = None) -> None:
        """What the mission decided this tick, carried out."""
        f, r = self.flight, self.rooms
        now = f.clock.now()
        for event in out.events:
            r.recorder.mission_event(now, event)
        f.cursor.step, f.cursor.phase = out.step, out.phase
        f.cursor.progress = out.progress
        if out.plan is not None:
            self._planned(now, out.plan)
        r.photos.want(out.photo_soon)
        for index, photo in out.photos:
            r.photos.request(index, f.book.steps[index].name, photo)
        r.desk.follow(out)
        if out.step_index != f.cursor.index:
            f.cursor.index = index = out.step_index
            r.perception.use(f.book.pipeline_keys[index] if index >= 0 else ())
            await r.photos.use(f.book.photo_camera[index] if index >= 0 else None)
        if out.finished and f.state is not None:
            r.recorder.set_status(r.recorder.status_tracker.idle(f.state.in_air))
        if out.setpoint is not None and not r.failsafes.stale:
            await r.setpoints.put(out.setpoint, source_frame_s, out.step, out.phase)
        for request in out.requests:
            try:
                await r.commands.perform(request)
            except VehicleError as exc:
                failed = f.executor.request_failed(request, str(exc), self.inputs(f.state))
                await self.apply(failed)
                return

    def _planned(self, now: float, plan: dict) -> None:
        self.flight.log.write(ch.PLANNED_PATH, now, dict(plan, time_s=now))
        points = plan.get("points_ned_m")
        points = np.zeros((0, 3)) if points is None else \
            np.asarray(points, dtype=float).reshape(-1, 3)
        every = max(1, len(points) // 400)
        self.planned_path = (self.planned_path[0] + 1, np.round(points[::every, :2], 2).tolist())
