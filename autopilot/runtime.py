"""The runtime: one event loop, one task per stage, latest-value hand-over between them.

::

    vehicle.frames(camera) ─► detection (executor) ─► [slot] ─► estimation ─► [event] ─┐
       (one lane per camera the active step uses; its pipelines run on each frame)         │
    vehicle.telemetry ─► pose history (every pipeline), latest state ──────────────────────┤
                                                           control (≥ control_rate_hz,
                                                           and on every estimate)
                                                                   │ intent (expires)
                                                                   ▼
                                                      setpoint streaming ─► vehicle

* What runs is what the active mission step declares (:mod:`autopilot.steps`): its perception
  pipelines, grouped by camera into *lanes* (a detection and an estimation task per camera in
  use). A step that needs no camera runs none. A pipeline lives for the whole run, so a target
  tracked in one step is still tracked when a later step uses the same pipeline.
* Frames and telemetry carry their capture times end to end: a detection is placed in the world
  with the vehicle pose at its frame's capture time, and the latency of each setpoint computed
  from a frame (capture → sent) is logged. The target a behaviour flew on is logged at every
  control tick (``/control/target``): that, not the filter right after an update, is what the
  estimation metrics score.
* A setpoint is an *intent with an expiry*: the streaming task re-sends it at
  ``setpoint_rate_hz`` only until ``setpoint_expiry_s`` after the control step made it. If the
  control task stalls, streaming stops, and the vehicle's own offboard-loss failsafe takes over.
* :meth:`Runtime.request_stop` (Ctrl-C, SIGTERM) switches the mission to its safe stop — hold,
  land, disarm — bounded by ``shutdown_timeout_s``; every task belongs to one TaskGroup, so none
  outlives the run. Frame logging (:mod:`autopilot.framelog`) and progress lines
  (:mod:`autopilot.progress`) are separate parts the runtime starts and owns.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import multiprocessing
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from autopilot import values
from autopilot.behaviors.base import (
    BehaviorInputs,
    Percept,
    RequestKind,
    VehicleRequest,
)
from autopilot.behaviors.flight import ReturnHome, SafeStop
from autopilot.behaviors.manual import ACTIONS, HeldKeys, ManualFlight, ManualSettings
from autopilot.config import AppConfig
from autopilot.console.view import pose_record, publish_vehicle, vehicle_map, vehicle_status
from autopilot.control.battery import BatteryReserve, ReserveSettings
from autopilot.control.geofence import FenceSettings, Geofence
from autopilot.estimation.target import TargetEstimate
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.framelog import FrameLogger
from autopilot.goals import Goal, GoalError, GoalManager
from autopilot.hooks import Event, EventHub
from autopilot.mission import (
    MissionEvent,
    MissionExecutor,
    MissionOutput,
    MissionPlan,
    Step,
    build_behavior,
)
from autopilot.photo_lane import PhotoLane
from autopilot.pipeline import Pipeline, make_pipeline
from autopilot.progress import report_progress
from autopilot.status import MissionStatus, StatusTracker
from autopilot.steps import step_kind
from autopilot.watchdog import LoopWatchdog
from drivers.base import (
    FlightMode,
    Frame,
    LandedState,
    LandingTarget,
    Setpoint,
    Vehicle,
    VehicleError,
    VehicleState,
)
from drivers.slots import LatestSlot
from drivers.threads import lower_this_thread

log = logging.getLogger(__name__)

#: a step's phases that are already the way down (the battery reserve does not interrupt them)
LANDING_PHASES = frozenset({"landing", "descending", "committed", "touching down",
                            "precision landing"})
#: a landing a failsafe asked for and the vehicle refused (or did not answer within 2 s) is
#: asked for again this long after (s)
LAND_RETRY_S = 1.0


class Service(Protocol):
    """Something the runtime runs for the whole flight beside the mission (the goal API's
    web server): ``run`` until ``stop`` is awaited (``graceful``: the run ended normally;
    otherwise stop at once, the vehicle comes first)."""

    name: str

    async def run(self) -> None: ...

    async def stop(self, graceful: bool = True) -> None: ...


@dataclass(slots=True)
class Intent:
    setpoint: Setpoint
    made_s: float
    expires_s: float
    source_frame_time_s: float | None
    step: str
    phase: str
    sent: bool = False


@dataclass(frozen=True, slots=True)
class ProcessedFrame:
    """A camera frame and what each of its lane's pipelines detected in it (in lane order)."""

    time_s: float
    seq: int
    frame: Frame
    detections: tuple[object | None, ...]
    hints: tuple[object | None, ...] = ()  # where each pipeline was told to look


@dataclass(slots=True)
class Track:
    """What one pipeline has made of its frames so far."""

    pipeline: Pipeline
    detection: object | None = None  # in the newest processed frame
    last_detection: object | None = None  # in the newest frame that had one
    frame_seq: int = -1
    frames: int = 0
    detections: int = 0


@dataclass(slots=True)
class Lane:
    """One camera in use: its pipelines, and the detection and estimation tasks that run them."""

    camera: str
    keys: tuple[str, ...]
    frames: LatestSlot[ProcessedFrame] = field(default_factory=LatestSlot)
    tasks: list[asyncio.Task] = field(default_factory=list)


@dataclass
class RunStats:
    frames: int = 0  # camera frames processed by the active steps' pipelines
    detections: int = 0  # pipeline detections in them
    setpoints_sent: int = 0
    frames_log_dropped: int = 0
    loop_lag_p50_ms: float | None = None  # how late the event loop answered (wall clock)
    loop_lag_p99_ms: float | None = None
    loop_lag_max_ms: float | None = None
    loop_stalls: int = 0  # the loop silent for runtime.loop_stall_s or longer
    armed: bool = False  # the vehicle was armed at some time during the run (it flew)


@contextlib.contextmanager
def _program_hidden():
    """While a worker process is started: the program that embeds the autopilot out of its
    sight. A spawned worker otherwise runs the main script again to find its functions — a
    script without ``if __name__ == "__main__":`` would start a second flight in it, and one
    read from standard input cannot be found at all. The planner's jobs need only the
    autopilot's own modules."""
    import types

    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


def _warm_planner() -> None:
    """The planning worker's first job: the planners imported before the first plan."""
    import autopilot.behaviors.trajectory
    import autopilot.steps  # noqa: F401


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


def detection_charge(config: AppConfig, kinds: Sequence[str]
                     ) -> float | Callable[[list[tuple[object | None, float, str | None]]], float]:
    """What the lockstep clock charges for detecting ``kinds`` in one frame (``sim.compute_*``):
    a fixed time, each kind's modelled cost, or (``measured``) a function of
    :func:`_detect_all`'s results, the time they really took; all but ``fixed`` scaled by
    ``sim.compute_scale`` (a slower companion computer)."""
    sim, fixed_s = config.sim, config.runtime.lockstep_detection_s
    if sim.compute_charge == "fixed":
        return fixed_s * len(kinds)
    scale = sim.compute_scale
    if sim.compute_charge == "measured":
        return lambda results: scale * sum(ms for _, ms, _ in results) / 1e3
    return scale * sum(sim.compute_cost_ms[k] / 1e3 if k in sim.compute_cost_ms else fixed_s
                       for k in kinds)


def _detect_all(pipelines: list[Pipeline], frame: Frame, hints: list[object | None]
                ) -> list[tuple[object | None, float, str | None]]:
    """Each pipeline's detection in one frame, with its processing time (ms) and, when its
    detector raised, what it raised (no detection then: the flight goes on without it)."""
    out = []
    for pipeline, hint in zip(pipelines, hints, strict=True):
        started = time.perf_counter()
        error = None
        try:
            det = pipeline.detect(frame.image, frame.camera, frame.time_s, hint)
        except Exception as exc:
            log.exception("the %s detector raised on frame %d", pipeline.name, frame.seq)
            det, error = None, f"{type(exc).__name__}: {exc}"
        out.append((det, (time.perf_counter() - started) * 1e3, error))
    return out


class Runtime:
    def __init__(self, vehicle: Vehicle, plan: MissionPlan, log: FlightLog, *,
                 progress: Callable[[str], None] | None = None,
                 log_cameras: Mapping[str, float] | None = None,
                 photos_dir: Path | None = None, goals: GoalManager | None = None,
                 services: Sequence[Service] = ()) -> None:
        self.vehicle = vehicle
        self.plan = plan
        self.config = plan.config
        self.log = log
        self.clock = vehicle.clock
        cfg = plan.config
        specs = plan.all_pipelines()
        self.pipelines: dict[str, Pipeline] = {
            key: make_pipeline(cfg, spec) for key, spec in specs.items()}
        self.tracks = {key: Track(p) for key, p in self.pipelines.items()}
        self._step_keys = [tuple(spec.key for spec in plan.pipelines(i))
                           for i in range(len(plan.steps))]
        self.stats = RunStats()
        self.status = "running"
        self.reason = ""
        self.errors: list[BaseException] = []
        self._progress = progress
        self._state: VehicleState | None = None
        self._estimated: LatestSlot[float] = LatestSlot()  # capture time of the frame used
        self._intent: Intent | None = None
        self._last_send_s = -math.inf
        self._stop_reason: str | None = None
        self._stop_requested = asyncio.Event()
        self._stale = False  # telemetry lost (a silence past the grace): no more setpoints
        #: when (our clock) a newer position / attitude than any before was last received
        self._position_heard_s = -math.inf
        self._attitude_heard_s = -math.inf
        #: a silence under the grace: when it began (None: telemetry flowing), and whether
        #: the vehicle was told to hold (the step then asks for OFFBOARD again on resuming)
        self._silent_since: float | None = None
        self._silence_held = False
        self._tick_clock_s = -math.inf  # (the clock) the newest control tick
        self._sensors_started = False
        self._late_tasks: list[asyncio.Task] = []  # started during the run (ended with it)
        self._executor: MissionExecutor | None = None
        self._step = ""
        self._step_index = -1
        self._phase = ""
        self._active: tuple[str, ...] = ()  # the running step's pipelines (keys)
        self._lanes: dict[str, Lane] = {}
        self._group: asyncio.TaskGroup | None = None
        self._detect_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="detect",
                                               initializer=lower_this_thread)
        #: plans goto, orbit and survey paths in a worker process in real time (the vehicle
        #: holds meanwhile; a process, so that no plan holds the event loop's interpreter);
        #: in lockstep a step plans at once (the same plan at the same simulated moment)
        self._planner: ProcessPoolExecutor | None = None
        self._step_photo_camera = [step_kind(step.name).photo_camera(step.params, cfg)
                                   for step in plan.steps]
        #: the mission's steps, then the goals run so far (a goal's index is its place here)
        self._steps: list[Step] = list(plan.steps)
        self.goals = goals
        self._services = list(services)
        self.photos = PhotoLane(vehicle, log, cfg, photos_dir)
        self.status_tracker = StatusTracker()
        self._status_logged: MissionStatus | None = None
        self.step_progress = math.nan
        # camera frames for the log: by default the cameras the steps use, at the log's rate
        if log_cameras is None:
            frames = cfg.log.frames
            rate = frames.sim_rate_hz if cfg.driver == "sim" else frames.vehicle_rate_hz
            log_cameras = {spec.camera: rate for spec in specs.values() if spec.camera}
        self.frame_logger = FrameLogger(vehicle, log, log_cameras, cfg.log.frames.jpeg_quality)
        #: what happens, for hooks and the console (:mod:`autopilot.hooks`)
        self.events = EventHub()
        #: the ``name::value`` board (:mod:`autopilot.values`)
        self.values = values.board()
        # the console: keyboard flying, the frames it draws over, the plan it maps
        c = cfg.console
        self._manual_settings = ManualSettings(
            c.speed_m_s, c.vertical_speed_m_s, math.radians(c.yaw_rate_deg_s), c.key_timeout_s,
            c.min_altitude_m, takeoff_altitude_m=c.takeoff_altitude_m)
        self.held_keys = HeldKeys(c.key_timeout_s)
        #: the keys' clock: the wall clock (a person's keys, whatever the simulated clock
        #: does); tests that drive the keys on the lockstep clock swap it
        self.key_clock: Callable[[], float] = time.monotonic
        self._manual = ManualFlight(self._manual_settings)
        self.manual = False  # the console's Y: the mission waits, the keys fly
        self._manual_enter = False
        self._manual_from_air = False
        self._manual_offboard_asked_s = -math.inf
        self._console_actions: list[str] = []
        self._console_requests: tuple[VehicleRequest, ...] = ()
        gf = cfg.failsafe.geofence
        #: the autopilot's own geofence, checked on every setpoint (autopilot/control/geofence)
        self.fence = Geofence(FenceSettings(
            gf.max_distance_m or None, gf.max_altitude_m or None,
            tuple(tuple(p) for p in gf.polygon_m) if gf.polygon_m else None, gf.lookahead_s))
        self._fence_breach: str | None = None
        self._fence_handled = False
        #: when to ask again for a landing the vehicle refused (:meth:`_land_where_it_is`)
        self._land_retry_s: float | None = None
        b = cfg.failsafe.battery
        #: the battery reserve for the way home (autopilot/control/battery.py)
        self.battery_reserve = BatteryReserve(ReserveSettings(
            b.reserve_fraction, b.speed_m_s, b.descent_m_s, b.margin,
            return_altitude_m=b.return_altitude_m, climb_m_s=b.climb_m_s,
            fast_descent_m_s=b.fast_descent_m_s, slow_below_m=b.slow_below_m,
            land_here=b.action == "land"))
        self._battery_handled = False
        #: a failure the step cannot fly on (its detector or estimator raised, the event loop
        #: stalled in flight): the step fails into the fallback at the next tick
        self._step_failure: str | None = None
        self.watchdog = LoopWatchdog(cfg.runtime.loop_stall_s, self._on_loop_stall,
                                     quiet=self.clock.lockstep)
        self._control_ended = False
        self._resumed = False
        self._emergency: str | None = None
        self.latest_processed: dict[str, ProcessedFrame] = {}
        self._processed_signals: dict[str, asyncio.Event] = {}
        #: the flown track (north, east), every 10 cm or more: the console's map
        self.track_ne_m: deque[tuple[float, float]] = deque(maxlen=4000)
        self.intent_record: dict | None = None  # the newest setpoint, as the log keeps it
        self.planned_path: tuple[int, list[list[float]]] = (0, [])

    # ------------------------------------------------------------------------------------
    # Control from outside
    # ------------------------------------------------------------------------------------

    def request_stop(self, reason: str = "stop requested") -> None:
        """Ask for a safe stop (hold, land, disarm). Safe to call from a signal handler."""
        if self._stop_reason is None:
            self._stop_reason = reason
        self._stop_requested.set()
        self._estimated.put(math.nan)  # wake the control loop now

    # ------------------------------------------------------------------------------------
    # The run
    # ------------------------------------------------------------------------------------

    async def run(self) -> str:
        """Fly the mission; returns ``completed``, ``failed`` or ``aborted``."""
        self._log_plan()
        cameras = self.vehicle.cameras
        for camera in cameras.values():
            self.log.write(ch.CAMERA_INFO, self.clock.now(), ch.camera_info_record(camera))
        true_cameras = getattr(self.vehicle, "true_cameras", None)  # the simulator: scoring
        if callable(true_cameras):
            for camera in true_cameras().values():
                self.log.write(ch.CAMERA_TRUTH, self.clock.now(), ch.camera_info_record(camera))
        behaviors = [build_behavior(step, self.config, cameras, self._offload)
                     for step in self.plan.steps]
        self._start_planner()
        self._executor = MissionExecutor(behaviors)
        self.values.clear()
        try:
            async with asyncio.TaskGroup() as tasks:
                self._group = tasks
                background = [
                    tasks.create_task(self.watchdog.run(), name="loop-watchdog"),
                    *self.events.tasks(tasks),
                    tasks.create_task(self._telemetry(), name="telemetry"),
                    tasks.create_task(self._streaming(), name="setpoint-streaming"),
                    *self._sensor_tasks(tasks),
                    *self._simulator_tasks(tasks),
                    *self.frame_logger.tasks(tasks),
                ]
                self.photos.group = tasks
                for service in self._services:
                    background.append(tasks.create_task(service.run(), name=service.name))
                if self._progress is not None:
                    background.append(tasks.create_task(report_progress(
                        self.progress_line, self._progress,
                        self.config.runtime.progress_interval_s), name="progress"))
                ended = False
                try:
                    await self._control()
                    ended = True
                finally:
                    self._control_ended = True
                    self._use_pipelines(())
                    for service in self._services:  # (after a failure: at once, no waiting)
                        await service.stop(graceful=ended)
                    if ended:
                        await self.photos.use(None)
                    self.events.close()  # (hooks added during the run end with it too)
                    for task in [*background, *self._late_tasks, *self.events.runners]:
                        task.cancel()
        except* Exception as group:  # the link broke, or a bug: never leave the motors running
            self.status = "failed"
            self.reason = "; ".join(f"{type(e).__name__}: {e}" for e in group.exceptions)
            self.errors = list(group.exceptions)
            await self._last_resort()
        finally:
            self._group = None
            self.values.clear()  # the run's last values (status, battery, ...) end with it
            self.events.close()
            self._detect_pool.shutdown(wait=True, cancel_futures=True)
            if self._planner is not None:  # (a plan still being made ends within a second)
                self._planner.shutdown(wait=True, cancel_futures=True)
            self.photos.close()
            self.frame_logger.close()
            self.stats.frames_log_dropped = self.frame_logger.dropped
            dog = self.watchdog
            self.stats.loop_lag_p50_ms = dog.lag_percentile_ms(50)
            self.stats.loop_lag_p99_ms = dog.lag_percentile_ms(99)
            self.stats.loop_lag_max_ms = dog.lag_percentile_ms(100)
            self.stats.loop_stalls = len(dog.stalls_s)
        return self.status

    async def _control(self) -> None:
        executor = self._executor
        state = await self._first_state()
        out = executor.start(self._inputs(state))
        await self._apply(out)
        period = 1.0 / self.config.runtime.control_rate_hz
        deadline: float | None = None
        # Control runs on every estimate and at least every period. In real time the period
        # counts from when the last tick was due, not from when its work ended: a tick made
        # late by a busy CPU (the loop's thread waiting for a core) or by its own work does
        # not delay the next one (next_tick_due). Lockstep keeps its schedule as it was: a
        # period from the end of each tick.
        next_tick_s = self.clock.now() + period
        while not out.finished:
            wait_s = period if self.clock.lockstep else max(0.0, next_tick_s - self.clock.now())
            source = await self._next_tick(wait_s)
            self._tick_clock_s = now = self.clock.now()
            next_tick_s = next_tick_due(next_tick_s, now, period, estimate=source is not None,
                                        lockstep=self.clock.lockstep)
            inputs = self._inputs(self._state)
            self._log_control_target(inputs)
            if self._stale:
                pass  # lost for good: the fallback flies on the vehicle's own modes
            elif (silence := self._telemetry_silence()) is not None:
                if self._silent_since is None:
                    await self._hold_silent(silence, inputs)
                if self._emergency is not None:  # the motors stop, whatever we know
                    await self._emergency_stop(inputs)
                    return
                lost = silence > self.config.runtime.telemetry_grace_s
                if not lost and not self._stop_requested.is_set():
                    continue  # holding: the step waits for telemetry (or the grace's end)
                # flying blind for longer than the grace (or asked to stop meanwhile): the
                # mission's fallback brings the vehicle down, as for a lost link
                self._stale = True
                why = f"telemetry lost: nothing new received for {silence:.2f} s " \
                      f"(grace {self.config.runtime.telemetry_grace_s:g} s)"
                self._event(self.clock.now(), "failsafe", why)
                self.events.emit(Event("mission", "failsafe", self.clock.now(), why))
                if executor.in_fallback:
                    # already coming down or home: a vehicle flying its own return or landing
                    # goes on with it (a hold would stop it); otherwise it lands where it is
                    if inputs.state.mode not in ReturnHome.RETURN_MODES:
                        await self._land_where_it_is()
                    continue
                out = executor.abort(why, inputs)
                await self._apply(out, None)
                continue
            elif self._silent_since is not None:
                gap = min(self._position_heard_s, self._attitude_heard_s) - \
                    self._silent_since
                self._silent_since = None
                # back within the grace: the step resumes from where the vehicle is (OFFBOARD
                # asked again if it was told to hold)
                self._resumed = self._resumed or self._silence_held
                self._event(self.clock.now(), "runtime",
                            f"telemetry back after {gap:.2f} s: {self._step or 'mission'} "
                            "resumes")
            if self._land_retry_s is not None and self.clock.now() >= self._land_retry_s:
                await self._land_where_it_is()
            self._publish_values(inputs)
            if self._fence_breach is None and self.fence.settings.active and \
                    inputs.state.in_air:
                where = self.fence.check_state(inputs.state, self.vehicle.home_ned_m)
                if where is not None:
                    self._fence_breach = f"the vehicle is {where}"
            if self._fence_breach is not None and not self._fence_handled:
                # geofence: no setpoint went out; the mission's fallback (hold, land) takes over
                self._fence_handled = True
                self.manual = False
                self._console_actions.clear()
                self._intent = None
                self._event(self.clock.now(), "failsafe", f"geofence: {self._fence_breach}")
                self.events.emit(Event("mission", "geofence", self.clock.now(),
                                       f"geofence: {self._fence_breach}"))
                if executor.in_fallback:
                    # the fallback is already taking the vehicle down or home (the vehicle's
                    # return climbing above the ceiling, a landing blown outside): it lands
                    # where it is now; a hold would stop the fallback, not end the flight
                    self._event(self.clock.now(), "failsafe",
                                "geofence during the fallback: landing where it is")
                    await self._land_where_it_is()
                    continue
                with contextlib.suppress(VehicleError, TimeoutError):
                    await self.clock.wait_for(self.vehicle.hold(), 2.0)
                out = executor.abort(f"geofence: {self._fence_breach}", inputs)
                await self._apply(out, None)
                continue
            if (call := self._battery_call(inputs)) is not None:
                out = call
                await self._apply(out, None)
                continue
            if self._step_failure is not None:
                why, self._step_failure = self._step_failure, None
                self.manual = False
                self._event(self.clock.now(), "failsafe", why)
                self.events.emit(Event("mission", "failsafe", self.clock.now(), why))
                out = executor.fail(why, inputs)
                await self._apply(out, None)
                continue
            if self._emergency is not None:
                await self._emergency_stop(inputs)
                return
            if self._stop_requested.is_set() and deadline is None:
                self.manual = False  # the safe stop flies, whatever the console asked
                self._console_actions.clear()
                deadline = self.clock.now() + self.config.runtime.shutdown_timeout_s
                out = executor.abort(self._stop_reason or "stop requested", inputs)
            elif deadline is not None and self.clock.now() > deadline:
                self.status, self.reason = "failed", "safe stop did not finish in time"
                await self._last_resort()
                return
            elif (console := self._console_tick(inputs)) is not None:
                out = console
            elif self._resumed and executor.accepts_goals:
                self._resumed = False  # a step waiting for goals waits here, not back there
                out = executor.reactivate(inputs, "back from manual flight")
            else:
                try:
                    out = self._serve_goals(inputs) or executor.update(inputs)
                except Exception as exc:  # a bug in the step: it fails, the fallback flies
                    if executor.in_fallback:
                        raise
                    log.exception("step %s raised", executor.step_name)
                    why = f"the step raised {type(exc).__name__}: {exc}"
                    self._event(self.clock.now(), "failsafe", why)
                    self.events.emit(Event("mission", "failsafe", self.clock.now(), why))
                    self._intent = None
                    out = executor.fail(why, inputs)
                    await self._apply(out, source)
                    continue
                if self._resumed and out.setpoint is None and inputs.state.in_air:
                    # a step flown by the vehicle's own modes (land, hold, the safe stop):
                    # it asks for its mode again (manual flight left OFFBOARD behind)
                    out = executor.reactivate(inputs, "back from manual flight")
                elif self._resumed and out.setpoint is not None and inputs.state.in_air and \
                        inputs.state.mode is not FlightMode.OFFBOARD:
                    # back from manual flight out of OFFBOARD (after T, or a landing
                    # stopped): the step's setpoints need OFFBOARD again
                    out = dataclasses.replace(out, requests=(
                        VehicleRequest(RequestKind.START_OFFBOARD), *out.requests))
                self._resumed = False
            await self._apply(out, source)
            await self._console_perform()
        self.status = executor.status
        self.reason = executor.failure
        s = self._state
        if s is not None and s.in_air and s.armed and not self._stale:
            # a mission that ends in the air (its last step a goto, a timed standby, …) leaves
            # the vehicle in the vehicle's own position hold, not in OFFBOARD without setpoints
            self._intent = None
            self._event(self.clock.now(), "runtime", "mission ended in the air: holding")
            with contextlib.suppress(VehicleError, TimeoutError):
                await self.clock.wait_for(self.vehicle.hold(), 2.0)

    async def _apply(self, out: MissionOutput, source_frame_s: float | None = None) -> None:
        now = self.clock.now()
        for event in out.events:
            self._mission_event(now, event)
        self._step, self._phase = out.step, out.phase
        self.step_progress = out.progress
        if out.plan is not None:
            self.log.write(ch.PLANNED_PATH, now, dict(out.plan, time_s=now))
            points = out.plan.get("points_ned_m")
            points = np.zeros((0, 3)) if points is None else \
                np.asarray(points, dtype=float).reshape(-1, 3)
            every = max(1, len(points) // 400)
            self.planned_path = (self.planned_path[0] + 1,
                                 np.round(points[::every, :2], 2).tolist())
        self.photos.want(out.photo_soon)
        for index, photo in out.photos:
            self.photos.request(index, self._steps[index].name, photo)
            goal = self._goal_at(index)
            if goal is not None:
                goal.photos += 1
        goal = self._goal_at(out.step_index)
        if goal is not None and goal.active:
            goal.phase = out.phase
            goal.progress = out.progress
        if out.step_index != self._step_index:
            self._step_index = out.step_index
            self._use_pipelines(self._step_keys[out.step_index] if out.step_index >= 0 else ())
            await self.photos.use(self._step_photo_camera[out.step_index]
                                  if out.step_index >= 0 else None)
        if out.finished and self._state is not None:
            self._set_status(self.status_tracker.idle(self._state.in_air))
        if out.setpoint is not None and not self._stale:
            self._intent = Intent(out.setpoint, now, now + self.config.runtime.setpoint_expiry_s,
                                  source_frame_s, out.step, out.phase)
            await self._send(self._intent)
        for request in out.requests:
            try:
                await self._perform(request)
            except VehicleError as exc:
                failed = self._executor.request_failed(request, str(exc),
                                                       self._inputs(self._state))
                await self._apply(failed)
                return

    # ------------------------------------------------------------------------------------
    # Goals (the goal API)
    # ------------------------------------------------------------------------------------

    def add_service(self, service: Service) -> None:
        """Run ``service`` beside the mission (before :meth:`run`)."""
        self._services.append(service)

    def _serve_goals(self, inputs: BehaviorInputs) -> MissionOutput | None:
        """Serve what the goal API asked since the last tick: an abort, a cancel, a queued
        goal (when the mission waits for one). None: nothing to do."""
        goals, executor = self.goals, self._executor
        if goals is None or self._stop_requested.is_set():
            return None
        goal = goals.running()
        if goal is None:
            return None
        now = self.clock.now()
        if goal.cancel_requested:
            if goal.state == "queued":
                goal.state, goal.ended_s, goal.reason = "cancelled", now, "cancelled"
                return None
            if executor.goal_running:
                return executor.cancel_goal(inputs)
        if goal.state == "queued" and executor.accepts_goals:
            try:
                return self._start_goal(goal, inputs)
            except Exception as exc:  # a goal that cannot start fails; the flight goes on
                goal.state, goal.ended_s = "failed", now
                goal.reason = f"could not start: {type(exc).__name__}: {exc}"
                self._event(now, "goal_refused", f"goal {goal.id} {goal.step.name}: "
                            f"{goal.reason}")
        return None

    def _start_goal(self, goal: Goal, inputs: BehaviorInputs) -> MissionOutput:
        now = self.clock.now()
        kind = step_kind(goal.step.name)
        behavior = build_behavior(goal.step, self.config, self.vehicle.cameras, self._offload)
        specs = kind.pipelines(goal.step.params, self.config)
        for spec in specs:
            if spec.key not in self.pipelines:
                self.pipelines[spec.key] = make_pipeline(self.config, spec)
                self.tracks[spec.key] = Track(self.pipelines[spec.key])
        if self._group is not None:  # a goal's pipeline may take sensors
            self._late_tasks += self._sensor_tasks(self._group)
        goal.index = len(self._steps)
        self._steps.append(goal.step)
        self._step_keys.append(tuple(spec.key for spec in specs))
        self._step_photo_camera.append(kind.photo_camera(goal.step.params, self.config))
        self.log.write(ch.MISSION_GOALS, now, ch.clean({
            **self._step_record(goal.index, goal.step), "goal_id": goal.id,
            "time_s": now}))
        goal.state, goal.started_s = "running", now
        return self._executor.start_goal(behavior, goal.index, inputs)

    def _goal_at(self, index: int):
        if self.goals is None or index < len(self.plan.steps):
            return None
        return next((g for g in self.goals.goals.values() if g.index == index), None)

    def _goal_event(self, event: MissionEvent) -> None:
        goal = self._goal_at(event.step_index)
        now = self.clock.now()
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

    def api_status(self) -> dict:
        """The goal API's ``/api/status``: the mission status, the step (or goal) running,
        and the vehicle's state as telemetry says it."""
        s = self._state
        code = self.status_tracker.code
        goal = self.goals.running() if self.goals is not None else None
        out = {"status_code": int(code), "status": code.label, "step": self._step,
               "phase": self._phase, "goal_id": goal.id if goal is not None else None,
               "time_s": self.clock.now(),
               "progress": self.step_progress if math.isfinite(self.step_progress) else None,
               "waiting_for_goals": self.waiting_for_goals,
               "control": "manual" if self.manual else "autopilot",
               "photos": self.photos.taken}
        return {**out, **vehicle_status(s)}

    @property
    def waiting_for_goals(self) -> bool:
        return self._executor is not None and self._executor.accepts_goals

    def submit_goal(self, step: Step) -> Goal:
        """A validated goal from the API, queued (or GoalError saying why not now)."""
        if self.goals is None:
            raise GoalError(409, "this run takes no goals")
        s = self._state
        return self.goals.submit(step, self.clock.now(), self.status_tracker.code,
                                 self.waiting_for_goals, bool(s is not None and s.in_air),
                                 cameras=list(self.vehicle.cameras))

    def abort(self, reason: str) -> None:
        """The goal API's abort: no more goals; the safe stop (hold, land, disarm), bounded by
        ``shutdown_timeout_s`` as after Ctrl-C."""
        if self.goals is not None:
            self.goals.abort(reason)
        self.request_stop(reason)

    async def _perform(self, request: VehicleRequest) -> None:
        if request.kind is RequestKind.LANDING_TARGET:
            await self._command(request)
            return
        name = request.kind.value
        data = {"altitude_m": request.altitude_m} if request.altitude_m is not None else {}
        if request.kind is RequestKind.DISARM:
            data["force"] = request.force
        self.events.emit(Event("command", name, self.clock.now(), f"command {name}", "before",
                               data))
        try:
            await self._command(request)
        except Exception as exc:
            self.events.emit(Event("command", name, self.clock.now(),
                                   f"command {name} failed: {exc}", "after",
                                   {**data, "result": f"{type(exc).__name__}: {exc}"}))
            raise
        self.events.emit(Event("command", name, self.clock.now(), f"command {name} done",
                               "after", {**data, "result": "ok"}))

    async def _command(self, request: VehicleRequest) -> None:
        v = self.vehicle
        if request.kind is RequestKind.LANDING_TARGET:  # a stream, as setpoints: not an event
            await v.send_landing_target(LandingTarget(request.time_s, request.position_ned_m))
            return
        if request.kind is RequestKind.START_OFFBOARD and self._state is not None and \
                self._state.mode is FlightMode.OFFBOARD:
            return  # already there (one offboard step after another): nothing to ask
        self._event(self.clock.now(), "request", f"request {request.kind.value}")
        if request.kind is RequestKind.ARM:
            await v.arm()
        elif request.kind is RequestKind.TAKEOFF:
            await v.takeoff(request.altitude_m)
        elif request.kind is RequestKind.START_OFFBOARD:
            warmup = self.config.runtime.offboard_warmup_s
            if self._intent is not None:  # keep the entry setpoint alive while warming up
                self._intent.expires_s = self.clock.now() + warmup + \
                    self.config.runtime.setpoint_expiry_s
            await self.clock.sleep(warmup)
            await v.start_offboard()
        elif request.kind is RequestKind.HOLD:
            await v.hold()
        elif request.kind is RequestKind.LAND:
            await v.land()
        elif request.kind is RequestKind.RETURN:
            await v.return_to_launch()
        elif request.kind is RequestKind.PRECISION_LAND:
            await v.precision_land()
        elif request.kind is RequestKind.DISARM:
            await v.disarm(force=request.force)

    def _fail_step(self, why: str) -> None:
        """The running step cannot go on (its perception raised, …): it fails into the
        fallback at the next control tick (the first reason wins)."""
        if self._step_failure is None and self._executor is not None and \
                not self._executor.in_fallback:
            self._step_failure = why

    def _on_loop_stall(self, seconds: float) -> None:
        """The event loop was stalled for ``runtime.loop_stall_s`` or more (the one threshold:
        autopilot/watchdog.py). In real time, flying, the step does not resume blindly on what
        it saw before the stall (its setpoints lapsed meanwhile, and PX4's offboard-loss
        failsafe may have acted): it fails into the fallback."""
        if self.clock.lockstep:  # simulated time waited for the loop: the flight lost nothing
            return
        now = self.clock.now()
        text = f"event loop stalled for {seconds:.2f} s"
        # the vehicle's own time since the last control tick: a real-time simulator slowed
        # with a starved CPU (drivers/clock.py, PacedClock) may have waited for the loop, and
        # then no setpoint lapsed on its clock; a real vehicle never waits
        waited = now - self._tick_clock_s
        if waited < self.config.runtime.setpoint_expiry_s:
            self._event(now, "runtime", f"{text} (the vehicle's clock {waited:.2f} s: "
                        "its world waited)")
            return
        self._event(now, "runtime", text)
        s = self._state
        if s is not None and s.in_air:
            self._fail_step(text)

    def _battery_call(self, inputs: BehaviorInputs) -> MissionOutput | None:
        """The battery reserve (autopilot/control/battery.py): time to go home?"""
        if self._battery_handled or not self.battery_reserve.active or \
                self._executor is None or self._executor.in_fallback:
            return None
        s = inputs.state
        if s.mode in (FlightMode.LAND, FlightMode.PRECLAND) or \
                s.landed_state is LandedState.LANDING or self._phase in LANDING_PHASES:
            return None  # already on the cheapest way down: a landing is not interrupted
        battery = getattr(s, "battery", None)
        call = self.battery_reserve.check(
            inputs.now_s, getattr(battery, "remaining_fraction", None), s.position_ned_m,
            self.vehicle.home_ned_m, s.in_air)
        if call is None:
            return None
        self._battery_handled = True
        self.manual = False
        self._console_actions.clear()
        self._intent = None
        go_home = call.go_home and self.config.failsafe.battery.action == "return"
        why = f"battery reserve: {call.reason}; " + ("returning home" if go_home else "landing")
        self._event(self.clock.now(), "failsafe", why)
        self.events.emit(Event("mission", "battery_reserve", self.clock.now(), why))
        return self._executor.abort(why, inputs, ReturnHome if go_home else SafeStop)

    async def _last_resort(self) -> None:
        """The orderly stop failed or the link broke: one bounded attempt to land."""
        with contextlib.suppress(Exception):
            await self.clock.wait_for(self.vehicle.land(), 2.0)

    # ------------------------------------------------------------------------------------
    # The console (autopilot/console): values, events, keyboard flying
    # ------------------------------------------------------------------------------------

    def spawn(self, coro, name: str) -> asyncio.Task:
        """Run ``coro`` as a task of the run (cancelled when it ends; an exception in it
        fails the run, so a service catches its own)."""
        if self._group is None:
            raise RuntimeError("the run has not started (or has ended)")
        task = self._group.create_task(coro, name=name)
        self._late_tasks = [t for t in self._late_tasks if not t.done()]
        self._late_tasks.append(task)
        return task

    async def processed_frame(self, camera: str, seq: int, timeout_s: float
                              ) -> ProcessedFrame | None:
        """The running step's pipelines' result for frame ``seq`` of ``camera``, waiting up to
        ``timeout_s`` for it (None: no pipeline reads that camera now, or it did not come)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while camera in self._lanes:
            found = self.latest_processed.get(camera)
            if found is not None and found.seq >= seq:
                return found if found.seq == seq else None
            signal = self._processed_signals.setdefault(camera, asyncio.Event())
            try:
                await asyncio.wait_for(signal.wait(), deadline - loop.time())
            except TimeoutError:
                return None
        return None

    def overlay_records(self, camera: str, frame: Frame) -> dict:
        """What the console draws over ``frame``, as the flight log's records (for
        :func:`autopilot.report.video.overlay_from`): the detections in it when a step's
        pipelines processed it, the pose now, the target estimate, the newest setpoint."""
        now = self.clock.now()
        det = est = None
        processed = self.latest_processed.get(camera)
        for key in self._active:
            track = self.tracks[key]
            if track.pipeline.camera != camera:
                continue
            if processed is not None and processed.seq == frame.seq:
                i = self._lanes[camera].keys.index(key) if camera in self._lanes and \
                    key in self._lanes[camera].keys else -1
                if i >= 0:
                    det = track.pipeline.detection_record(
                        frame.seq, frame.time_s, camera, processed.detections[i],
                        processed.hints[i] if i < len(processed.hints) else None)
            target = track.pipeline.target(now)
            if target is not None:
                cov = np.asarray(target.covariance)
                est = {"time_s": now, "position_ned_m": target.position_ned_m.tolist(),
                       "velocity_ned_m_s": target.velocity_ned_m_s.tolist(),
                       "position_cov_m2": cov[:3, :3].reshape(-1).tolist(),
                       "velocity_std_m_s": np.sqrt(np.clip(np.diag(cov)[3:6], 0, None)
                                                   ).tolist()}
            break
        return {"det": det, "pose": pose_record(self._state), "est": est,
                "setpoint": self.intent_record,
                "step": self._step, "phase": self._phase}

    def map_snapshot(self) -> dict:
        """The console's mini-map: where the vehicle is and faces, home, the target."""
        s = self._state
        out = vehicle_map(s, self.vehicle.home_ned_m, self.planned_path[0])
        if s is None:
            return out
        if self._active:
            target = self.tracks[self._active[0]].pipeline.target(self.clock.now())
            if target is not None and not target.stale:
                out["target_ne_m"] = [round(float(target.position_ned_m[0]), 3),
                                      round(float(target.position_ned_m[1]), 3)]
                out["target_sigma_m"] = round(float(np.sqrt(np.mean(
                    np.diag(target.covariance)[:2]))), 3)
        return out

    def console_about(self) -> dict:
        """What the console's page is told first: the mission, the camera to show, whether
        it may fly and send goals, and the clock."""
        camera = next((p.camera for p in self.pipelines.values() if p.camera),
                      next(iter(self.vehicle.cameras), ""))
        return {"mission": self.plan.mission.name, "camera": camera, "can_fly": True,
                "track_ne_m": list(self.track_ne_m),
                "takes_goals": self.goals is not None,
                "clock": "lockstep" if self.clock.lockstep else "realtime"}

    def console_keys(self, held: Sequence[str], source: object = None) -> None:
        """The movement keys a console page (``source``) holds now (renewed while held)."""
        self.held_keys.report(held, self.key_clock(), source)

    def console_release(self, source: object = None) -> None:
        """A console page went away: what it held is let go at once."""
        self.held_keys.release(source)

    def console_action(self, action: str, confirm: bool = False) -> str:
        """One of the console's keys (:data:`~autopilot.behaviors.manual.ACTIONS`); acted on
        at the next control tick. Returns what will happen (ValueError: refused now)."""
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; actions: {list(ACTIONS)}")
        if self._executor is None or self._control_ended:
            raise ValueError("the mission is not flying: the console's keys are off")
        if action == "emergency":  # (the kill switch works during a safe stop too)
            if not confirm:
                raise ValueError("the emergency stop needs confirming (it stops the motors, in "
                                 "the air too)")
            self._emergency = self._emergency or "emergency stop from the console"
            self._estimated.put(math.nan)  # act now, not at the next tick
            return "emergency stop: the motors stop"
        if self._stop_requested.is_set() or self._stale or self._emergency:
            raise ValueError("the mission is stopping (a safe stop flies): only the emergency "
                             "stop (R) acts now")
        if action == "takeoff" and not self.manual:
            raise ValueError("T acts in manual flight only (Y hands the vehicle to the keys)")
        self._console_actions.append(action)
        self._estimated.put(math.nan)
        return {"autopilot": "manual flight" if not self.manual else "autopilot on",
                "follow_mode": "switching follow mode", "takeoff": "taking off",
                "land": "landing"}[action]

    def _console_tick(self, inputs: BehaviorInputs) -> MissionOutput | None:
        """The console's actions since the last tick, and the keys' setpoint while manual;
        None: the mission runs this tick as usual."""
        actions, self._console_actions = self._console_actions, []
        s, now = inputs.state, inputs.now_s
        requests: list[VehicleRequest] = []
        for action in actions:
            if action == "autopilot":
                self._toggle_manual(s, now)
            elif action == "follow_mode":
                behavior = self._executor.current
                toggle = getattr(behavior, "toggle_follow_mode", None)
                if toggle is None:
                    self._console_event(now, "follow_mode", "F: the running step does not follow "
                                        "a target")
                else:
                    mode = toggle()
                    self._console_event(now, "follow_mode", f"following by {mode}",
                                        {"mode": mode})
            elif action == "land":
                if not self.manual:
                    self.abort("land requested from the console")
                    return None
                self._console_event(now, "land", "landing (manual)")
                requests.append(VehicleRequest(RequestKind.LAND))
            elif action == "takeoff":
                if s.in_air or s.armed:
                    self._console_event(now, "takeoff", "T: already armed or flying")
                else:
                    self._console_event(now, "takeoff", "taking off (manual)")
                    self._manual.reset()
                    requests += [VehicleRequest(RequestKind.ARM), VehicleRequest(
                        RequestKind.TAKEOFF, altitude_m=self._manual_settings.takeoff_altitude_m)]
        self._console_requests = tuple(requests)
        if not self.manual or self._stop_requested.is_set():
            return None
        held = self.held_keys.held(self.key_clock())
        setpoint = self._manual.setpoint(held, s, now) if s.in_air else None
        if s.in_air and s.armed and s.mode is not FlightMode.OFFBOARD and not requests and \
                (held or self._manual_enter) and now - self._manual_offboard_asked_s > 2.0:
            self._manual_offboard_asked_s = now
            self._console_requests += (VehicleRequest(RequestKind.START_OFFBOARD),)
        self._manual_enter = False
        return MissionOutput(setpoint, (), (), False, "running", self._step, "manual",
                             self._step_index)

    async def _console_perform(self) -> None:
        """The console's vehicle commands (T, L, entering OFFBOARD): one refused is reported,
        it fails no step (the step never asked for it)."""
        requests, self._console_requests = self._console_requests, ()
        for request in requests:
            try:
                await self._perform(request)
            except VehicleError as exc:
                self._console_event(self.clock.now(), "refused",
                                    f"{request.kind.value} refused: {exc}")
                return

    def _toggle_manual(self, s: VehicleState, now: float) -> None:
        if not self.manual:
            self.manual = True
            self._manual.reset()
            self.held_keys.release_all()
            self._manual_enter = s.in_air
            self._manual_from_air = s.in_air
            self._console_event(now, "autopilot", "autopilot off: manual flight (keys)",
                                {"autopilot": False})
            return
        self.held_keys.release_all()
        if not s.in_air and self._manual_from_air:
            self.manual = False
            self._console_event(now, "autopilot", "autopilot on: landed under manual "
                                "control, so the mission ends", {"autopilot": True})
            self.request_stop("landed under manual control")
            return
        self.manual = False
        self._resumed = True
        self._console_event(now, "autopilot", f"autopilot on: {self._step or 'mission'} "
                            "resumes", {"autopilot": True})

    def _console_event(self, now: float, name: str, text: str, data=None) -> None:
        self._event(now, "console", text)
        self.events.emit(Event("console", name, now, text, data=data or {}))

    async def _emergency_stop(self, inputs: BehaviorInputs) -> None:
        """R, confirmed: the motors stop now — flight termination in the air (a forced
        disarm, PX4's kill), a disarm on the ground — and the run ends."""
        in_air = inputs.state.in_air
        reason = self._emergency or "emergency stop"
        self._intent = None
        self.manual = False
        self._console_event(inputs.now_s, "emergency", f"{reason}: "
                            + ("flight termination (motors off in the air)" if in_air
                               else "disarm on the ground"))
        try:
            await self.clock.wait_for(self._perform(VehicleRequest(RequestKind.DISARM,
                                                                   force=in_air)), 2.0)
        except (VehicleError, TimeoutError) as exc:
            self._event(self.clock.now(), "runtime", f"emergency disarm failed: {exc}")
            await self._last_resort()
        self.status, self.reason = "aborted", reason

    def _state_events(self, previous: VehicleState | None, state: VehicleState) -> None:
        self.stats.armed = self.stats.armed or state.armed
        if previous is None:
            return
        t = state.time_s
        if state.mode is not previous.mode:
            self.events.emit(Event("mode", state.mode.value, t, f"mode {state.mode.value}",
                                   data={"previous": previous.mode.value}))
        if state.armed != previous.armed:
            name = "armed" if state.armed else "disarmed"
            self.events.emit(Event("armed", name, t, name))
        if state.failsafe and not previous.failsafe:
            self.events.emit(Event("mission", "failsafe", t, "vehicle failsafe",
                                   data={"failsafe": state.failsafe}))

    def _publish_values(self, inputs: BehaviorInputs) -> None:
        """The runtime's own values on the board (status, mode, battery, height, target)."""
        pub = self.values.publish
        s, code = inputs.state, self.status_tracker.code
        pub("status", f"{int(code)} {code.label}")
        pub("control", "manual" if self.manual else "autopilot")
        pub("step", f"{self._step or '-'} / {self._phase or '-'}")
        publish_vehicle(self.values, s)
        if math.isfinite(self.step_progress):
            pub("progress", f"{100 * self.step_progress:.0f} %")
        if self._active:
            track = self.tracks[self._active[0]]
            det = track.detection
            score = getattr(det, "score", None)
            pub("det.score", round(float(score), 3) if score is not None else
                ("found" if det is not None else "none"))
            if track.frames:
                pub("det.rate", f"{100.0 * track.detections / track.frames:.0f} %")
            est = inputs.target
            if est is not None:
                pub("target.range_m", round(float(np.linalg.norm(
                    est.position_ned_m - s.position_ned_m)), 2), "m")
                pub("target.sigma_m", round(float(np.sqrt(np.mean(
                    np.diag(est.covariance)[:3]))), 3), "m")
                pub("target.age_s", round(float(est.age_s), 2), "s")

    # ------------------------------------------------------------------------------------
    # Perception lanes: what the active step uses
    # ------------------------------------------------------------------------------------

    def _use_pipelines(self, keys: tuple[str, ...]) -> None:
        """Run exactly ``keys``' pipelines: one lane per camera; lanes whose pipelines do not
        change keep running (their subscriptions and slots are not disturbed)."""
        self._active = keys
        wanted: dict[str, tuple[str, ...]] = {}
        for key in keys:
            camera = self.pipelines[key].camera
            if not camera:
                continue  # it reads no camera (a deck tracked without its tag)
            wanted[camera] = (*wanted.get(camera, ()), key)
        for camera, lane in list(self._lanes.items()):
            if wanted.get(camera) != lane.keys:
                for task in lane.tasks:
                    task.cancel()
                del self._lanes[camera]
        if self._group is None:
            return
        for camera, lane_keys in wanted.items():
            if camera in self._lanes:
                continue
            lane = Lane(camera, lane_keys)
            lane.tasks = [
                self._group.create_task(self._detection(lane), name=f"detection-{camera}"),
                self._group.create_task(self._estimation(lane), name=f"estimation-{camera}")]
            self._lanes[camera] = lane

    async def _detection(self, lane: Lane) -> None:
        pipelines = [self.pipelines[key] for key in lane.keys]
        budget = detection_charge(self.config, [p.kind for p in pipelines])
        async with contextlib.aclosing(self.vehicle.frames(lane.camera)) as frames:
            async for frame in frames:
                received = self.clock.now()
                hints = [p.hint(frame.time_s, frame.camera) for p in pipelines]
                results = await self.clock.run_blocking(
                    _detect_all, pipelines, frame, hints, executor=self._detect_pool,
                    budget_s=budget)
                processed = ProcessedFrame(frame.time_s, frame.seq, frame,
                                           tuple(det for det, _, _ in results), tuple(hints))
                lane.frames.put(processed)
                self.latest_processed[lane.camera] = processed
                signal = self._processed_signals.pop(lane.camera, None)
                if signal is not None:  # (whoever waits for this camera's next one)
                    signal.set()
                detected = self.clock.now()
                for pipeline, hint, (det, elapsed_ms, error) in zip(pipelines, hints, results,
                                                                    strict=True):
                    if error is not None:
                        self._fail_step(f"the {pipeline.name} detector raised {error}")
                    self.stats.frames += 1
                    self.stats.detections += det is not None
                    record = pipeline.detection_record(frame.seq, frame.time_s,
                                                       frame.camera.name, det, hint)
                    record.update(processing_ms=elapsed_ms, received_s=received,
                                  detected_s=detected)
                    self.log.write(ch.detection_topic(pipeline.name), frame.time_s, record)

    async def _estimation(self, lane: Lane) -> None:
        while True:
            item = await lane.frames.get()
            for key, det in zip(lane.keys, item.detections, strict=True):
                track = self.tracks[key]
                track.detection = det
                track.frame_seq = item.seq
                track.frames += 1
                if det is not None:
                    track.detections += 1
                    track.last_detection = det
                    try:
                        record = track.pipeline.estimate(item.time_s, item.frame.camera, det)
                    except Exception as exc:  # the step cannot fly on it: it fails
                        log.exception("the %s estimator raised", track.pipeline.name)
                        self._fail_step(f"the {track.pipeline.name} estimator raised "
                                        f"{type(exc).__name__}: {exc}")
                        continue
                    if record is not None:
                        self.log.write(ch.TARGET_ESTIMATES, item.time_s, record)
                    self._log_relative(track.pipeline)
            self._estimated.put(item.time_s)

    # ------------------------------------------------------------------------------------
    # Telemetry, setpoints, the simulator's extras
    # ------------------------------------------------------------------------------------

    async def _telemetry(self) -> None:
        async with contextlib.aclosing(self.vehicle.telemetry(buffer=64)) as samples:
            async for state in samples:
                previous, self._state = self._state, state
                now = self.clock.now()
                if previous is None or state.time_s > previous.time_s:
                    self._position_heard_s = now
                if previous is None or state.attitude_time_s > previous.attitude_time_s:
                    self._attitude_heard_s = now
                self._state_events(previous, state)
                ne = (round(float(state.position_ned_m[0]), 2),
                      round(float(state.position_ned_m[1]), 2))
                last = self.track_ne_m[-1] if self.track_ne_m else None
                if last is None or math.hypot(ne[0] - last[0], ne[1] - last[1]) >= 0.1:
                    self.track_ne_m.append(ne)
                self.photos.add_state(state)
                for pipeline in self.pipelines.values():
                    pipeline.add_state(state)
                    self._log_relative(pipeline)
                record = ch.vehicle_state_record(state)
                record["received_s"] = self.clock.now()
                self.log.write(ch.VEHICLE_STATE, state.time_s, record)

    def _sensor_tasks(self, tasks: asyncio.TaskGroup) -> list[asyncio.Task]:
        """The vehicle's extra sensor streams (UWB, the rover's reports) while any pipeline
        takes them: logged, and handed to those pipelines as they arrive."""
        if self._sensors_started or not any(callable(getattr(p, "add_sensor", None))
                                            for p in self.pipelines.values()):
            return []
        self._sensors_started = True
        streams = {"uwb": (self.vehicle.uwb_ranges, ch.UWB_RANGES),
                   "rover": (self.vehicle.rover_states, ch.ROVER_STATES)}
        return [tasks.create_task(self._sensor(*streams[name]), name=f"sensor-{name}")
                for name in sorted(self.vehicle.sensors) if name in streams]

    async def _sensor(self, subscribe, topic: str) -> None:
        async with contextlib.aclosing(subscribe(buffer=64)) as samples:
            async for sample in samples:
                record = ch.clean(dataclasses.asdict(sample))
                record["received_s"] = self.clock.now()
                self.log.write(topic, sample.time_s, record)
                for pipeline in self.pipelines.values():
                    add = getattr(pipeline, "add_sensor", None)
                    if add is not None:
                        add(sample)
                        self._log_relative(pipeline)

    def _log_relative(self, pipeline: Pipeline) -> None:
        take = getattr(pipeline, "take_records", None)
        if take is None:
            return
        for record in take():
            self.log.write(ch.RELATIVE_ESTIMATES, record["time_s"], record)

    async def _streaming(self) -> None:
        period = 1.0 / self.config.runtime.setpoint_rate_hz
        while True:
            await self.clock.sleep(period)
            intent = self._intent
            now = self.clock.now()
            if intent is not None and now < intent.expires_s and not self._stale and \
                    now - self._last_send_s >= 0.9 * period and self._silent_since is None:
                await self._send(intent)

    async def _send(self, intent: Intent) -> None:
        state = self._state
        if state is not None and self.fence.settings.active:
            why = self.fence.check(intent.setpoint, state, self.vehicle.home_ned_m)
            if why is not None:  # nothing goes out; the control loop hands over to the fallback
                if self._fence_breach is None:
                    self._fence_breach = why
                    self._estimated.put(math.nan)
                self._intent = None
                return
        await self.vehicle.send_setpoint(intent.setpoint)
        now = self.clock.now()
        self._last_send_s = now
        self.stats.setpoints_sent += 1
        if not intent.sent:
            intent.sent = True
            sp = intent.setpoint
            latency = None if intent.source_frame_time_s is None \
                else (now - intent.source_frame_time_s) * 1e3
            record = {
                "time_s": now, "source_frame_time_s": intent.source_frame_time_s,
                "latency_ms": latency, "frame": sp.frame.value,
                "position_ned_m": sp.position_ned_m, "velocity_m_s": sp.velocity_m_s,
                "acceleration_m_s2": sp.acceleration_m_s2, "yaw_rad": sp.yaw_rad,
                "yaw_rate_rad_s": sp.yaw_rate_rad_s,
                "expires_s": intent.expires_s, "step": intent.step, "phase": intent.phase}
            self.intent_record = record
            self.log.write(ch.SETPOINTS, now, record)

    def _simulator_tasks(self, tasks: asyncio.TaskGroup) -> list[asyncio.Task]:
        """Ground truth, when the vehicle is the simulator (for the log and scoring only;
        nothing here reaches the autopilot's decisions), and the vehicle's status messages
        (the simulator's, or STATUSTEXT over MAVLink: the log and the console's events)."""
        found = []
        truth = getattr(self.vehicle, "ground_truth", None)
        if callable(truth):
            found.append(tasks.create_task(self._record_truth(truth), name="ground-truth"))
        events = getattr(self.vehicle, "events", None)
        if callable(events):
            found.append(tasks.create_task(self._record_status(events), name="status-text"))
        return found

    async def _record_truth(self, stream) -> None:
        async with contextlib.aclosing(stream(buffer=1024)) as samples:
            async for gt in samples:
                self.log.write(ch.GROUND_TRUTH, gt.time_s, ch.ground_truth_record(gt))

    async def _record_status(self, stream) -> None:
        async with contextlib.aclosing(stream(buffer=64)) as messages:
            async for time_s, text in messages:
                self.log.write(ch.VEHICLE_STATUS, time_s, {"time_s": time_s, "text": text})
                self.events.emit(Event("status_text", "status_text", time_s, text))

    # ------------------------------------------------------------------------------------
    # Helpers
    # ------------------------------------------------------------------------------------

    async def _first_state(self) -> VehicleState:
        while self._state is None:
            await self.clock.sleep(0.01)
        return self._state

    async def _next_tick(self, period: float) -> float | None:
        """Wait for a fresh estimate (returns its frame's capture time) or the period."""
        try:
            source = await self.clock.wait_for(self._estimated.get(), period)
        except TimeoutError:
            return None
        return None if math.isnan(source) else source

    async def _land_where_it_is(self) -> None:
        """Land now (a failsafe during the fallback); a land the vehicle refuses or does not
        answer is asked for again every ``LAND_RETRY_S`` until it takes it."""
        try:
            await self.clock.wait_for(self.vehicle.land(), 2.0)
        except (VehicleError, TimeoutError) as exc:
            self._event(self.clock.now(), "runtime", f"land refused ({exc}): asking again")
            self._land_retry_s = self.clock.now() + LAND_RETRY_S
        else:
            self._land_retry_s = None

    def _telemetry_silence(self) -> float | None:
        """How long the vehicle has said nothing new (no newer position or attitude received),
        on our clock; None while that is under ``runtime.telemetry_silence_s``. Judged on
        arrival, not on the capture stamps' age: a vehicle whose clock lags ours (a starved
        simulator) or a link with latency is not silent while its samples keep coming."""
        if self._state is None:
            return None
        silence = self.clock.now() - min(self._position_heard_s, self._attitude_heard_s)
        return silence if silence > self.config.runtime.telemetry_silence_s else None

    async def _hold_silent(self, silence: float, inputs: BehaviorInputs) -> None:
        """A silence began: no motion setpoint goes out on an old pose. A vehicle flown by our
        setpoints is told to HOLD (as PX4 holds on offboard loss); one flying its own mode
        (takeoff, land, return) goes on with it."""
        now = self.clock.now()
        self._silent_since = now - silence  # (the last news)
        self._intent = None
        self.manual = False  # the step (or the fallback) flies again after, whatever the keys
        self._console_actions.clear()
        self._silence_held = inputs.state.mode is FlightMode.OFFBOARD
        grace = self.config.runtime.telemetry_grace_s
        what = "holding" if self._silence_held else f"the vehicle's {inputs.state.mode.value} " \
            "goes on"
        self._event(now, "runtime", f"telemetry silent: nothing new for {silence:.2f} s; "
                    f"setpoints stopped, {what} (up to {grace:g} s)")
        if self._silence_held:
            with contextlib.suppress(VehicleError, TimeoutError):
                await self.clock.wait_for(self._perform(VehicleRequest(RequestKind.HOLD)), 2.0)

    @property
    def _offload(self):
        if self.clock.lockstep:
            return None
        return self._plan_off_loop

    def _plan_off_loop(self, job) -> Future:
        if self._planner is None:  # (started with the first plan, or when the run starts)
            self._planner = ProcessPoolExecutor(
                max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                initializer=lower_this_thread)
            with _program_hidden():  # (its worker starts with this first job)
                return self._planner.submit(job)
        return self._planner.submit(job)

    def _start_planner(self) -> None:
        """In real time, a mission that may plan paths (its steps, or goals) starts its
        planning worker with the run (a process takes a second or two to start)."""
        if self.clock.lockstep:
            return
        if self.goals is not None or any(step_kind(s.name).reach is not None
                                          for s in self.plan.steps):
            self._plan_off_loop(_warm_planner)

    def goal_site(self) -> BehaviorInputs | None:
        """Where the vehicle is now, for checking a goal's reach before it is accepted (None:
        no telemetry yet)."""
        if self._state is None:
            return None
        return BehaviorInputs(now_s=self.clock.now(), state=self._state,
                              home_ned_m=self.vehicle.home_ned_m,
                              global_origin=self.vehicle.global_origin)

    def _inputs(self, state: VehicleState) -> BehaviorInputs:
        """What the behaviours see now: the vehicle, and the running step's percepts (its
        first pipeline's target as ``target``). At a step change, the new step is activated
        with the inputs of the moment before it (its pipelines start with it)."""
        now = self.clock.now()
        percepts = tuple(self._percept(key, now) for key in self._active)
        first = percepts[0] if percepts else None
        return BehaviorInputs(now_s=now, state=state,
                              target=first.target if first is not None else None,
                              percept=first, percepts=percepts,
                              home_ned_m=self.vehicle.home_ned_m,
                              global_origin=self.vehicle.global_origin)

    def _percept(self, key: str, now: float) -> Percept:
        track = self.tracks[key]
        p = track.pipeline
        return Percept(p.name, p.kind, track.detection, track.last_detection, track.frame_seq,
                       p.target(now))

    def _log_control_target(self, inputs: BehaviorInputs) -> None:
        """The target the behaviour is about to act on, as it saw it (scored by the metrics,
        coasting and lost stretches included)."""
        percept = inputs.percept
        if percept is None:
            return
        est: TargetEstimate | None = inputs.target
        record = {"time_s": inputs.now_s, "pipeline": percept.pipeline, "step": self._step,
                  "step_index": self._step_index, "present": est is not None}
        if est is not None:
            record.update(position_ned_m=est.position_ned_m,
                          velocity_ned_m_s=est.velocity_ned_m_s,
                          position_std_m=est.position_std_m, age_s=est.age_s,
                          stale=est.stale, confirmed=est.confirmed)
        self.log.write(ch.CONTROL_TARGET, inputs.now_s, record)

    def _mission_event(self, time_s: float, event: MissionEvent) -> None:
        self._write_event(time_s, event.kind, event.step_index, event.step, event.text)
        data = {"step_index": event.step_index, "step": event.step, "event": event.kind}
        if event.kind == "step_started":
            self.events.emit(Event("step_started", event.step, time_s, event.text, data=data))
        elif event.kind in ("step_succeeded", "step_failed", "goal_cancelled"):
            outcome = {"step_succeeded": "succeeded", "step_failed": "failed"}.get(
                event.kind, "cancelled")
            self.events.emit(Event("step_ended", event.step, time_s, event.text,
                                   data={**data, "outcome": outcome}))
        else:
            self.events.emit(Event("mission", event.kind, time_s, event.text, data=data))
        tracker = self.status_tracker
        self._goal_event(event)
        codes = step_kind(self._steps[event.step_index].name).status \
            if event.step_index >= 0 else None
        in_air = self._state is not None and self._state.in_air
        if event.kind == "step_started" and event.step_index >= 0:
            self._set_status(tracker.step_started(codes) if codes is not None
                             else tracker.idle(in_air), event.step_index)
        elif event.kind == "step_succeeded" and codes is not None:
            self._set_status(tracker.step_succeeded(codes), event.step_index)
        elif event.kind in ("fallback_started", "aborted"):
            self._set_status(tracker.abort())
        elif event.kind in ("standby", "goal_cancelled"):
            self._set_status(tracker.idle(in_air), event.step_index)

    @property
    def status_code(self) -> MissionStatus:
        return self.status_tracker.code

    def _set_status(self, code: MissionStatus, step_index: int | None = None) -> None:
        if code == self._status_logged:
            return
        self._status_logged = code
        now = self.clock.now()
        index = self._step_index if step_index is None else step_index
        step = self._steps[index].name if 0 <= index < len(self._steps) else ""
        goal = self._goal_at(index)
        self.log.write(ch.MISSION_STATUS, now, {
            "time_s": now, "code": int(code), "status": code.label, "step": step,
            "step_index": index, "goal_id": goal.id if goal is not None else None})
        self.events.emit(Event("status", code.label, now, f"status {int(code)} {code.label}",
                               data={"code": int(code), "step": step}))

    def _event(self, time_s: float, kind: str, text: str) -> None:
        """The runtime's own events (``request``, ``runtime``), in the running step."""
        self._write_event(time_s, kind, self._step_index, self._step, text)

    def _write_event(self, time_s: float, kind: str, index: int, step: str, text: str) -> None:
        self.log.write(ch.MISSION_EVENTS, time_s, {"time_s": time_s, "kind": kind,
                                                    "step_index": index, "step": step,
                                                    "text": text})
        if self._progress is not None and kind != "request":
            self._progress(f"[{time_s:7.2f} s] {text}")

    def _step_record(self, index: int, step: Step) -> dict:
        """What the flight log keeps about a step (or a goal), for scoring and replay."""
        kind = step_kind(step.name)
        specs = kind.pipelines(step.params, self.config)
        return ch.clean({
            "name": step.name, "index": index, "params": step.params.model_dump(),
            "pipelines": [{"name": spec.key, "kind": spec.kind, "camera": spec.camera,
                           "truth_body": spec.truth_body, "size_m": spec.target_size_m,
                           "target": spec.target}
                          for spec in specs],
            **kind.plan_info(step.params, self.config)})

    def _log_plan(self) -> None:
        plan = self.plan
        steps = [self._step_record(index, step) for index, step in enumerate(plan.steps)]
        self.log.write(ch.MISSION_PLAN, self.clock.now(), ch.clean({
            "mission": plan.mission.name, "source": str(plan.source), "steps": steps,
            # (sim.cameras is a copy of vehicle.cameras, not a setting of its own)
            "config": self.config.model_dump(mode="json", exclude={"sim": {"cameras"}}),
            "driver": self.config.driver,
            "scenario": plan.mission.scenario.model_dump() if plan.mission.scenario else None}))

    def progress_line(self) -> str:
        s = self._state
        now = self.clock.now()
        code = self.status_tracker.code
        parts = [f"t={now:6.1f}s", f"status={int(code)} {code.label}",
                 f"step={self._step or '-'}", f"phase={self._phase or '-'}"]
        if math.isfinite(self.step_progress):
            parts.append(f"progress={100 * self.step_progress:3.0f}%")
        if self.photos.taken:
            parts.append(f"photos={self.photos.taken}")
        if s is not None:
            parts += [f"mode={s.mode.value}", f"alt={s.altitude_m:4.1f}m"]
        if self._active:
            track = self.tracks[self._active[0]]
            est = track.pipeline.target(now)
            if s is not None and est is not None and not est.stale:
                distance = float(np.linalg.norm(est.position_ned_m - s.position_ned_m))
                parts.append(f"target={distance:4.2f}m")
            if track.frames:
                parts.append(f"det={100.0 * track.detections / track.frames:3.0f}%")
        return " ".join(parts)
