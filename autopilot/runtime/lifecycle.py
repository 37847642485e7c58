"""The runtime's lifecycle: the rooms wired together, one TaskGroup that owns every task of the
run, and the ending — whatever ends it (the mission, Ctrl-C, a failsafe, a broken link, a
bug) — in a safe state."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from autopilot.flightlog.log import FlightLog
from autopilot.framelog import FrameLogger
from autopilot.goals import GoalManager
from autopilot.mission import MissionExecutor, MissionPlan, build_behavior
from autopilot.photo_lane import PhotoLane
from autopilot.progress import report_progress
from autopilot.runtime.commands import SetpointStream, VehicleCommands
from autopilot.runtime.console_bridge import ConsoleBridge
from autopilot.runtime.control import ControlLoop, Rooms
from autopilot.runtime.failsafes import Failsafes, make_fence
from autopilot.runtime.flight import Flight, Service
from autopilot.runtime.goal_desk import GoalDesk
from autopilot.runtime.governor import LoadGovernor
from autopilot.runtime.perception import PerceptionLanes
from autopilot.runtime.planner import PlanningWorker
from autopilot.runtime.readout import Readout
from autopilot.runtime.recorder import MissionRecorder
from autopilot.runtime.telemetry import TelemetryIntake
from autopilot.runtime.watch import Watch
from autopilot.status import MissionStatus
from autopilot.steps import step_kind
from autopilot.watchdog import LoopWatchdog
from drivers.base import Vehicle
from drivers.capabilities import SimulatorTruth, StatusTexts


class Runtime:
    """One flight: :meth:`run` flies the mission and returns how it ended. The goal API talks
    to :attr:`desk`, the console to :attr:`console`; hooks listen on :attr:`events`."""

    def __init__(self, vehicle: Vehicle, plan: MissionPlan, log: FlightLog, *,
                 progress: Callable[[str], None] | None = None,
                 log_cameras: Mapping[str, float] | None = None,
                 photos_dir: Path | None = None, goals: GoalManager | None = None,
                 services: Sequence[Service] = ()) -> None:
        self.flight = f = Flight(vehicle, plan, log, progress)
        self.vehicle, self.plan, self.config, self.log = vehicle, plan, plan.config, log
        self.clock, self.events, self.values, self.stats = f.clock, f.events, f.values, f.stats
        self.errors: list[BaseException] = []
        self._services = list(services)
        self._background: list[asyncio.Task] = []
        self._late_tasks: list[asyncio.Task] = []  # started during the run (ended with it)
        self._group: asyncio.TaskGroup | None = None
        self.planner = PlanningWorker()
        cfg = plan.config
        specs = plan.all_pipelines()
        self.photos = PhotoLane(vehicle, log, cfg, photos_dir)
        # camera frames for the log: by default the cameras the steps use, at the log's rate
        if log_cameras is None:
            frames = cfg.log.frames
            rate = frames.sim_rate_hz if cfg.driver == "sim" else frames.vehicle_rate_hz
            log_cameras = {spec.camera: rate for spec in specs.values() if spec.camera}
        self.frame_logger = FrameLogger(vehicle, log, log_cameras, cfg.log.frames.jpeg_quality)
        # the rooms
        self.recorder = recorder = MissionRecorder(f)
        fence = make_fence(f)
        self.telemetry = TelemetryIntake(f, recorder, [])
        self.failsafes = failsafes = Failsafes(f, recorder, self.telemetry, fence)
        self.watch = Watch(f, recorder)
        self.perception = PerceptionLanes(f, specs.values(), failsafes.fail_step, self.watch)
        self.telemetry.consumers += [self.photos.add_state, self.perception.add_state,
                                     self.watch.add_state]
        self.setpoints = SetpointStream(f, fence, failsafes.fence_breached, failsafes.quiet,
                                        self.watch.guard)
        self.commands = VehicleCommands(f, recorder, self.setpoints)
        self.desk = GoalDesk(f, goals, recorder, self.perception, self.photos, self._offload,
                             self._control_by)
        self.console = ConsoleBridge(f, recorder, self.desk, self.perception, self.telemetry,
                                     self.setpoints, self.commands, failsafes, self.spawn,
                                     lambda: self.control.planned_path)
        self.readout = Readout(f, recorder, self.perception, self.photos, self._control_by)
        self.control = ControlLoop(f, Rooms(
            recorder, self.telemetry, self.perception, self.setpoints, self.commands, failsafes,
            self.desk, self.console, self.photos, self.readout))
        failsafes.hand_back = self.console.hand_back
        failsafes.drop_setpoints = self.setpoints.drop
        failsafes.perform = self.commands.perform
        failsafes.resume = self.console.resume = self.control.resume
        governor = None if self.clock.lockstep else \
            LoadGovernor.from_config(cfg.runtime.yield_to_control)
        self.perception.governor = governor
        self.watchdog = LoopWatchdog(cfg.runtime.loop_stall_s, failsafes.on_loop_stall,
                                     quiet=self.clock.lockstep,
                                     on_beat=governor.observe_lag if governor else None)

    # -- what the outside reads and asks ---------------------------------------------------

    @property
    def status(self) -> str:
        """``running``, then how the run ended: ``completed``, ``failed`` or ``aborted``."""
        return self.flight.status

    @property
    def reason(self) -> str:
        return self.flight.reason

    @property
    def goals(self) -> GoalManager | None:
        return self.desk.goals

    @property
    def status_code(self) -> MissionStatus:
        return self.recorder.status_code

    def request_stop(self, reason: str = "stop requested") -> None:
        """Ask for a safe stop (hold, land, disarm). Safe to call from a signal handler."""
        self.flight.request_stop(reason)

    def add_service(self, service: Service) -> None:
        """Run ``service`` beside the mission (before :meth:`run`)."""
        self._services.append(service)

    def spawn(self, coro, name: str) -> asyncio.Task:
        """Run ``coro`` as a task of the run (cancelled when it ends; an exception in it
        fails the run, so a service catches its own)."""
        if self._group is None:
            raise RuntimeError("the run has not started (or has ended)")
        task = self._group.create_task(coro, name=name)
        self._late_tasks = [t for t in self._late_tasks if not t.done()]
        self._late_tasks.append(task)
        return task

    def progress_line(self) -> str:
        return self.readout.progress_line()

    def _control_by(self) -> str:
        """Who flies: the console's keys (``manual``) or the mission (``autopilot``)."""
        return "manual" if self.console.manual else "autopilot"

    @property
    def _offload(self):
        return None if self.clock.lockstep else self.planner.submit

    # -- the run ---------------------------------------------------------------------------

    async def run(self) -> str:
        """Fly the mission; returns ``completed``, ``failed`` or ``aborted``."""
        f = self.flight
        self.recorder.log_plan()
        if isinstance(self.vehicle, SimulatorTruth):  # the simulator: for scoring
            self.recorder.log_truth_cameras(self.vehicle.true_cameras())
        cameras = self.vehicle.cameras
        f.executor = MissionExecutor([build_behavior(step, self.config, cameras, self._offload)
                                      for step in self.plan.steps])
        if not self.clock.lockstep and (self.desk.goals is not None or any(
                step_kind(s.name).reach is not None for s in self.plan.steps)):
            self.planner.warm()  # (a mission that may plan paths: its worker starts now)
        self.values.clear()
        try:
            async with asyncio.TaskGroup() as tasks:
                self._start(tasks)
                ended = False
                try:
                    await self.control.run()
                    ended = True
                finally:
                    await self._end_tasks(ended)
        except* Exception as group:  # the link broke, or a bug: never leave the motors running
            f.status = "failed"
            f.reason = "; ".join(f"{type(e).__name__}: {e}" for e in group.exceptions)
            self.errors = list(group.exceptions)
            await self.failsafes.last_resort()
        finally:
            self._close()
        return f.status

    def _start(self, tasks: asyncio.TaskGroup) -> None:
        self._group = self.perception.group = self.photos.group = tasks
        self._background = [
            tasks.create_task(self.watchdog.run(), name="loop-watchdog"),
            *self.events.tasks(tasks),
            tasks.create_task(self.telemetry.run(), name="telemetry"),
            tasks.create_task(self.setpoints.run(), name="setpoint-streaming"),
            *self.perception.sensor_tasks(tasks),
            *self._vehicle_extras(tasks),
            *self.frame_logger.tasks(tasks),
        ]
        for service in self._services:
            self._background.append(tasks.create_task(service.run(), name=service.name))
        if self.flight.progress is not None:
            self._background.append(tasks.create_task(report_progress(
                self.progress_line, self.flight.progress,
                self.config.runtime.progress_interval_s), name="progress"))

    def _vehicle_extras(self, tasks: asyncio.TaskGroup) -> list[asyncio.Task]:
        """Ground truth, when the vehicle is the simulator (for the log and scoring only;
        nothing here reaches the autopilot's decisions), and the vehicle's status messages
        (the simulator's, or STATUSTEXT over MAVLink: the log and the console's events)."""
        found = []
        v = self.vehicle
        if isinstance(v, SimulatorTruth):
            found.append(tasks.create_task(self.recorder.record_truth(v.ground_truth),
                                           name="ground-truth"))
        if isinstance(v, StatusTexts):
            found.append(tasks.create_task(self.recorder.record_status_texts(v.events),
                                           name="status-text"))
        return found

    async def _end_tasks(self, ended: bool) -> None:
        """The control loop ended (``ended``: normally): perception stops, the services stop
        (after a failure at once, no waiting), the photo lane finishes, every task ends."""
        self.flight.control_ended = True
        self.perception.use(())
        for service in self._services:
            await service.stop(graceful=ended)
        if ended:
            await self.photos.use(None)
        self.events.close()  # (hooks added during the run end with it too)
        for task in [*self._background, *self._late_tasks, *self.perception.late_tasks,
                     *self.events.runners]:
            task.cancel()

    def _close(self) -> None:
        self._group = self.perception.group = None
        self.values.clear()  # the run's last values (status, battery, ...) end with it
        self.events.close()
        self.perception.close()
        self.planner.close()
        self.photos.close()
        self.frame_logger.close()
        self.stats.frames_log_dropped = self.frame_logger.dropped
        dog = self.watchdog
        self.stats.loop_lag_p50_ms = dog.lag_percentile_ms(50)
        self.stats.loop_lag_p99_ms = dog.lag_percentile_ms(99)
        self.stats.loop_lag_max_ms = dog.lag_percentile_ms(100)
        self.stats.loop_stalls = len(dog.stalls_s)
        governor = self.perception.governor
        if governor is not None:
            self.stats.frames_yielded = dict(governor.skipped)
            self.stats.lowest_frame_share = round(governor.lowest_share, 3)
