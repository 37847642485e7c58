"""The simulator as a :class:`~drivers.base.Vehicle`.

The synchronous :class:`~drivers.sim.simulator.Simulator` is run from the event loop in batches,
never hopping the loop per physics step.

* Lockstep (default): simulated time on a :class:`~drivers.clock.LockstepClock`. The stepping
  task waits until every other coroutine is blocked, then steps to the next moment anything
  happens (a telemetry sample or frame becomes due, or a coroutine's sleep ends). It steps on
  the loop thread itself: by construction nothing else may run while simulated time moves, so a
  worker thread would only add two thread hand-offs per batch (batches last at most one frame
  interval, so signals are still handled promptly). Runs as fast as the CPU allows and is
  deterministic for a given seed.
* Real time: a :class:`~drivers.clock.PacedClock`; the simulator lives on one dedicated
  thread, the physics runs at most ``realtime_batch_s`` ahead of the wall clock, and outputs are
  published when they are due. In process that thread (and the rendering) runs at a lower CPU
  priority, standing in for the vehicle's own hardware: when the machine is busy the
  autopilot's work comes first. A stand-alone vehicle (``background=False``: ``autopilot sim``)
  runs at normal priority, its clock running against other processes' wall clocks. The clock
  (a :class:`~drivers.clock.PacedClock`) does not run past the end of the batch being
  computed, and time lost handing a batch over is taken back: on a CPU too slow or too busy for real
  time the simulated world slows down as a whole (its clock, telemetry and frames together),
  instead of its samples arriving ever older. Time lost elsewhere (the event loop stalled) is
  caught up, as a vehicle flies on while its autopilot stalls. Running below
  :data:`SLOW_FACTOR` of real time is said with a warning: once in process, and every
  ``warn_every_s`` for a stand-alone vehicle (``autopilot sim``, whose clock then lags the wall
  clock as no real flight controller's does), which may also shed rendering
  (``shed_rendering``: every other frame is skipped while behind; physics and telemetry come
  first).

Setpoints go into a thread-safe inbox and take effect at the start of the next batch; commands
first flush that inbox, so "stream setpoints, then start OFFBOARD" works as on PX4.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import AsyncIterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from drivers.base import (
    CameraInfo,
    CameraUnavailable,
    CommandDenied,
    ConnectionLost,
    FlightMode,
    Frame,
    LandingTarget,
    RoverState,
    SensorUnavailable,
    Setpoint,
    UwbRanges,
    Vehicle,
    VehicleError,
    VehicleState,
)
from drivers.clock import Clock, LockstepClock, PacedClock
from drivers.mission import MissionItem, MissionType
from drivers.sim.camera import lower_thread_priority
from drivers.sim.camera_effects import RenderingUnavailable
from drivers.sim.config import SimConfig
from drivers.sim.flight.flight_stack import CommandRejected
from drivers.sim.flight.navigator import MissionStatus, NavEvent
from drivers.sim.flight.params import SPECS, ParamSpec, config_defaults
from drivers.sim.model import reported_camera_info, true_camera_info
from drivers.sim.scenario import ScenarioObject
from drivers.sim.simulator import GroundTruth, Photo, SimOutput, Simulator
from drivers.slots import Broadcast

log = logging.getLogger(__name__)

#: below this share of real time (over :data:`PACE_WINDOW_S` of wall time) the simulator says so
SLOW_FACTOR = 0.9
#: the wall-clock window over which the real-time factor is measured
PACE_WINDOW_S = 2.0
#: a batch's outputs waiting longer than this for the event loop: the loop stalled (the CPU is
#: not slow); half the runtime's loop_stall_s (its default 0.5 s)
STALL_S = 0.25
#: once behind, rendering stays shed for at least this long (simulated seconds): shedding makes
#: the next batches fast, and frames flickering on and off every batch would help nobody
SHED_HOLD_S = 0.5
#: a world this far behind the wall clock catches up by itself; beyond it the clock is held back
CATCH_UP_S = 0.1


class SimDriver(Vehicle):
    #: cameras are rendered only while something subscribes to their frames
    renders_on_demand = True

    def __init__(self, config: SimConfig, *, scenario: Sequence[ScenarioObject] = (),
                 seed: int | None = None, lockstep: bool = True,
                 warn_every_s: float | None = None, shed_rendering: bool = False,
                 background: bool = True) -> None:
        self.config = config
        self._scenario = list(scenario)
        self._seed = config.seed if seed is None else seed
        self.lockstep = lockstep
        self._clock: LockstepClock | PacedClock = LockstepClock() if lockstep \
            else PacedClock(slack_s=CATCH_UP_S)
        #: real time: say "simulator at 0.6× real time" once (None) or every this many seconds
        self.warn_every_s = warn_every_s
        #: real time: skip rendering frames while the simulator cannot keep up
        self.shed_rendering = shed_rendering
        #: real time: the simulator's threads (physics, telemetry, rendering) at a lower CPU
        #: priority, standing in for hardware of their own: in process, where the world
        #: slows as a whole when the autopilot needs the CPU. A stand-alone vehicle
        #: (``autopilot sim``) runs at normal priority: its clock runs against its clients'
        #: (lowered, two busy processes on its core starved it to 0.04× real time)
        self.background = background
        #: real time: the newest real-time factor (simulated / wall seconds over
        #: PACE_WINDOW_S), and the lowest seen
        self.pace_factor = math.nan
        self.slowest_pace_factor = math.nan
        self._pace_window: tuple[float, float] | None = None  # (wall, simulated) at its start
        self._slow_warned_s = -math.inf
        self._shed_until_s = -math.inf
        self._cameras = {name: reported_camera_info(name, cam)
                         for name, cam in config.cameras.items() if cam.enabled}
        self._executor: ThreadPoolExecutor | None = None
        self._sim: Simulator | None = None
        self._task: asyncio.Task[None] | None = None
        self._failure: VehicleError | None = None
        self._setpoints: deque[Setpoint] = deque()
        self._camera_toggles: deque[tuple[str, bool]] = deque()
        self._telemetry: Broadcast[VehicleState] = Broadcast()
        self._truth: Broadcast[GroundTruth] = Broadcast()
        self._events: Broadcast[tuple[float, str]] = Broadcast()
        self._mission_events: Broadcast[NavEvent] = Broadcast()
        self._photos: Broadcast[Photo] = Broadcast()
        self._uwb: Broadcast[UwbRanges] = Broadcast()
        self._rover: Broadcast[RoverState] = Broadcast()
        #: PX4 parameters as the vehicle will boot with them (the live ones once connected)
        self._param_defaults = config_defaults(config)
        self._frames: dict[str, Broadcast[Frame]] = {
            name: Broadcast(on_first=lambda n=name: self._camera_toggles.append((n, True)),
                            on_last=lambda n=name: self._camera_toggles.append((n, False)))
            for name in self._cameras
        }
        #: The newest telemetry sample (None before the first).
        self.latest_state: VehicleState | None = None
        self._wall_start = 0.0
        self._wall_busy_s = 0.0
        self._batch_end = 0.0  # (perf_counter) when the newest batch ended

    # ------------------------------------------------------------------------------------
    # Vehicle interface
    # ------------------------------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        return self._clock

    @property
    def cameras(self) -> Mapping[str, CameraInfo]:
        return self._cameras

    async def connect(self, timeout_s: float = 10.0) -> None:
        if self._task is not None:
            return
        loop = asyncio.get_running_loop()
        try:
            if self.lockstep:
                self._sim = self._build()
            else:
                self._executor = ThreadPoolExecutor(
                    max_workers=1, thread_name_prefix="simulator",
                    initializer=lower_thread_priority if self.background else None)
                self._sim = await loop.run_in_executor(self._executor, self._build)
                self._clock.restart(self._sim.time_s)
        except RenderingUnavailable as exc:
            await self.close()
            raise CameraUnavailable(f"simulator cameras: {exc}", "rendering") from exc
        self._wall_start = time.perf_counter()
        run = self._run_lockstep if self.lockstep else self._run_realtime
        self._task = loop.create_task(run(), name="sim-driver")
        # as a real link: connected once the vehicle has been heard from
        async with contextlib.aclosing(self.telemetry()) as samples:
            try:  # (on the wall clock: a simulator that never steps must not hang us)
                await asyncio.wait_for(anext(samples), timeout_s) if not self.lockstep \
                    else await self._clock.wait_for(anext(samples), timeout_s)
            except (TimeoutError, StopAsyncIteration):
                await self.close()
                raise ConnectionLost(
                    f"no telemetry from the simulator within {timeout_s:g} s") from None

    async def arm(self) -> None:
        await self._command("arm")

    async def disarm(self, *, force: bool = False) -> None:
        await self._command("disarm", force)

    async def takeoff(self, altitude_m: float | None = None) -> None:
        """TAKEOFF to ``altitude_m`` for this takeoff (as NAV_TAKEOFF's altitude on PX4: the
        MIS_TAKEOFF_ALT parameter is not changed), or to MIS_TAKEOFF_ALT."""
        await self._command("takeoff", altitude_m)

    async def land(self) -> None:
        await self._command("land")

    async def hold(self) -> None:
        await self._command("hold")

    async def precision_land(self) -> None:
        await self._command("precision_land")

    async def send_landing_target(self, target: LandingTarget) -> None:
        await self._command("landing_target", target.position_ned_m, target.time_s)

    async def start_offboard(self) -> None:
        await self._command("start_offboard")

    async def stop_offboard(self) -> None:
        await self._command("stop_offboard")

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        self._check_alive()
        self._setpoints.append(setpoint)

    def telemetry(self, buffer: int = 1) -> AsyncIterator[VehicleState]:
        return self._telemetry.subscribe(buffer)

    @property
    def sensors(self) -> frozenset[str]:
        """``uwb`` and ``rover`` when the scenario has a rover (with UWB anchors)."""
        from drivers.sim.rover import Rover

        rover = next((o for o in self._scenario if isinstance(o, Rover)), None)
        if rover is None:
            return frozenset()
        return frozenset({"rover", "uwb"} if len(rover.anchors_frd_m) else {"rover"})

    def uwb_ranges(self, buffer: int = 8) -> AsyncIterator[UwbRanges]:
        if "uwb" not in self.sensors:
            raise SensorUnavailable("this vehicle has no UWB ranging")
        return self._uwb.subscribe(buffer)

    def rover_states(self, buffer: int = 8) -> AsyncIterator[RoverState]:
        if "rover" not in self.sensors:
            raise SensorUnavailable("no rover is in the simulated world")
        return self._rover.subscribe(buffer)

    def frames(self, camera: str) -> AsyncIterator[Frame]:
        if camera not in self._frames:
            raise ValueError(f"no camera {camera!r}; this vehicle has {sorted(self._frames)}")
        return self._frames[camera].subscribe()

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        for broadcast in self._broadcasts():
            broadcast.close(self._failure)
        if self._executor is not None:
            if self._sim is not None:
                await asyncio.get_running_loop().run_in_executor(self._executor, self._sim.close)
            self._executor.shutdown(wait=True)
            self._executor = None
        elif self._sim is not None:
            self._sim.close()

    # ------------------------------------------------------------------------------------
    # PX4 capabilities: parameters, missions, return, camera (what the MAVLink face serves)
    # ------------------------------------------------------------------------------------

    def param_specs(self) -> list[ParamSpec]:
        """The vehicle's parameters, in index order."""
        return [SPECS[name] for name in sorted(SPECS)]

    def param(self, name: str) -> float:
        """A parameter's current value (KeyError if there is none)."""
        if self._sim is not None:
            return self._sim.params[name]
        if name not in SPECS:
            raise KeyError(name)
        return self._param_defaults.get(name, SPECS[name].default)

    async def set_param(self, name: str, value: float) -> float:
        """Set a PX4 parameter; returns the stored value. Refused (:class:`ParamError`) for
        unknown names and values of the wrong type or out of range."""
        return await self._call(f"set {name}", self._require_sim().set_param, name, value)

    async def start_mission(self) -> None:
        await self._command("start_mission")

    async def return_to_launch(self) -> None:
        await self._command("return_to_launch")

    async def set_mode(self, mode: FlightMode) -> None:
        await self._command("set_mode", mode)

    async def reposition(self, target_ned_m, yaw_rad: float = float("nan"),
                         speed_m_s: float = float("nan")) -> None:
        await self._command("reposition", target_ned_m, yaw_rad, speed_m_s)

    async def set_speed(self, speed_m_s: float) -> None:
        await self._command("set_speed", speed_m_s)

    async def take_photo(self) -> None:
        await self._command("take_photo")

    async def start_photos(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE: one photo, or ``count`` every ``interval_s`` (0: until
        :meth:`stop_photos`)."""
        await self._command("start_photos", interval_s, count)

    async def stop_photos(self) -> None:
        await self._command("stop_photos")

    async def set_trigger_distance(self, distance_m: float, trigger_now: bool = False) -> None:
        sim = self._require_sim()
        await self._call("set trigger distance", sim.flight.navigator.set_trigger_distance,
                         distance_m, trigger_now)

    async def upload_mission(self, items: list[MissionItem],
                             mission_type: int = MissionType.MISSION) -> None:
        await self._command("set_mission", list(items), mission_type)

    def mission_items(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        return self._require_sim().flight.navigator.items(mission_type)

    async def set_mission_current(self, seq: int) -> None:
        await self._command("set_mission_current", seq)

    @property
    def mission_status(self) -> MissionStatus:
        return self._require_sim().flight.navigator.status

    def mission_events(self, buffer: int = 64) -> AsyncIterator[NavEvent]:
        """Mission progress (current item, item reached, finished) and video events."""
        return self._mission_events.subscribe(buffer)

    def photos(self, buffer: int = 16) -> AsyncIterator[Photo]:
        """Photos taken by the vehicle's camera (missions, trigger distance, commands)."""
        return self._photos.subscribe(buffer)

    def home(self) -> tuple[float, float, float, np.ndarray] | None:
        """Home as (lat °, lon °, alt AMSL m, local NED), None before the first arming."""
        sim = self._require_sim()
        home = sim.flight.navigator.home
        if home is None:
            return None
        lat, lon, alt = sim.origin.to_global(*(float(v) for v in home))
        return lat, lon, alt, home

    @property
    def global_origin(self):
        return self._require_sim().origin

    @property
    def home_ned_m(self) -> np.ndarray | None:
        home = self._require_sim().flight.navigator.home
        return None if home is None else np.array(home, dtype=float)

    @property
    def geofence_breach(self) -> str | None:
        """Why the vehicle is outside its geofence (None: inside, or no fence)."""
        return self._require_sim().flight.geofence_breach

    async def gcs_heartbeat(self) -> None:
        """A ground station was heard (feeds the data-link loss failsafe, NAV_DLL_ACT)."""
        sim = self._sim
        if sim is None or self._failure is not None:
            return
        await self._call("gcs heartbeat", sim.command, "gcs_heartbeat")

    # ------------------------------------------------------------------------------------
    # Simulator-only extras (ground truth is for scoring and tests, never for the autopilot)
    # ------------------------------------------------------------------------------------

    def true_cameras(self) -> Mapping[str, CameraInfo]:
        """The cameras as they really are — true intrinsics, the mount with its error — where
        :attr:`cameras` is what their frames report (a fitted calibration, the nominal mount).
        For the log's scoring only (what a detection should have found)."""
        return {name: true_camera_info(name, self.config.cameras[name], self.config.seed)
                for name in self._cameras}

    def ground_truth(self, buffer: int = 256) -> AsyncIterator[GroundTruth]:
        """Ground-truth samples at ``sim.ground_truth_rate_hz`` (buffered: for loggers)."""
        return self._truth.subscribe(buffer)

    def events(self, buffer: int = 64) -> AsyncIterator[tuple[float, str]]:
        """The flight stack's status messages (mode changes, failsafes), like STATUSTEXT."""
        return self._events.subscribe(buffer)

    @property
    def simulator(self) -> Simulator:
        """The simulator core, for tests (touch it only while time stands still)."""
        return self._require_sim()

    @property
    def sim_time_s(self) -> float:
        return self._sim.time_s if self._sim is not None else 0.0

    @property
    def wall_time_s(self) -> float:
        return time.perf_counter() - self._wall_start if self._wall_start else 0.0

    @property
    def real_time_factor(self) -> float:
        wall = self.wall_time_s
        return self.sim_time_s / wall if wall > 0 else 0.0

    async def inject_failure(self, name: str, failed: bool = True) -> None:
        """Make a sensor unhealthy (``gyro``, ``accel``, ``mag``, ``local_position``)."""
        sim = self._require_sim()
        await self._call("inject_failure", sim.inject_failure, name, failed)

    # ------------------------------------------------------------------------------------
    # Internals
    # ------------------------------------------------------------------------------------

    def _build(self) -> Simulator:
        """The simulator, with its cameras ready to render (as a vehicle boots its cameras)."""
        sim = Simulator(self.config, self._scenario, self._seed)
        try:
            if not self.lockstep:
                sim.set_realtime_rendering(self._wait_for_clock, background=self.background)
            sim.prepare_cameras()
        except BaseException:
            sim.close()
            raise
        return sim

    def _require_sim(self) -> Simulator:
        if self._sim is None:
            raise ConnectionLost("not connected: call connect() first")
        return self._sim

    def _check_alive(self) -> None:
        if self._failure is not None:
            raise self._failure
        self._require_sim()

    async def _command(self, name: str, *args) -> None:
        sim = self._require_sim()
        await self._call(name, sim.command, name, *args)

    async def _call(self, name: str, fn, *args):
        """``fn(*args)`` on the simulator's thread, between physics batches; its result."""
        self._check_alive()

        def on_sim_thread():
            self._drain_inbox()
            return fn(*args)

        try:
            if self._executor is None:  # lockstep: time stands still while we are running
                return on_sim_thread()
            return await self._clock.run_blocking(on_sim_thread, executor=self._executor)
        except CommandRejected as exc:
            raise CommandDenied(name, exc.reason) from None

    def _wait_for_clock(self, time_s: float) -> None:
        """Block this (non-loop) thread until the real-time clock reads ``time_s``."""
        delay = time_s - self._clock.now()
        if delay > 0.0:
            time.sleep(delay)

    def _drain_inbox(self) -> None:
        """On the simulator thread: apply what the loop thread queued since the last batch."""
        sim = self._sim
        while self._camera_toggles:
            sim.set_camera_active(*self._camera_toggles.popleft())
        while self._setpoints:
            sim.push_setpoint(self._setpoints.popleft())

    def _batch(self, until_s: float) -> list[SimOutput]:
        started = time.perf_counter()
        paced = isinstance(self._clock, PacedClock)
        if paced:  # the world is not past this batch's end before the batch has computed it
            self._clock.cap_at(until_s)
        try:
            self._drain_inbox()
            outputs = self._sim.advance_to(until_s)
        finally:
            if paced:
                self._clock.cap_at(None)
        self._batch_end = time.perf_counter()
        self._wall_busy_s += self._batch_end - started
        return outputs

    def _pace(self, simulated_s: float, cycle_s: float) -> None:
        """Real time, after a cycle (a batch, and handing its outputs over) that simulated
        ``simulated_s`` in ``cycle_s`` of wall time: hold the clock back by what the CPU lost,
        measure the real-time factor, say when it is low, and shed rendering while behind (if
        asked). Not counted (``cycle_s`` leaves it out): a hand-over from the simulator's thread
        to the event loop longer than :data:`STALL_S`, which is the event loop stalling, not
        the CPU being slow; that time is caught up, as a vehicle flies on while its autopilot
        stalls."""
        clock, sim = self._clock, self._sim
        lost = cycle_s - simulated_s
        behind = clock.now() - sim.time_s
        # a world a little behind catches up on the next batches, as it always did (a batch
        # that renders a frame may take longer than the 10 ms it simulates on any machine);
        # only what is beyond CATCH_UP_S is held back, and never behind the world's own time
        excess = behind - CATCH_UP_S
        if lost > 0.0 and excess > 0.0:
            clock.hold_back(min(lost, excess))
        # shed while the last measured real-time factor is low, not on one slow batch (a batch
        # that renders a frame may take longer than the 10 ms it simulates on any machine, and
        # the next ones make it up)
        if self.shed_rendering and self.pace_factor < SLOW_FACTOR:
            self._shed_until_s = sim.time_s + SHED_HOLD_S
        if self.shed_rendering:
            sim.shed_rendering = sim.time_s < self._shed_until_s
        wall = time.perf_counter()
        if self._pace_window is None:
            self._pace_window = (wall, sim.time_s)
            return
        wall0, sim0 = self._pace_window
        if wall - wall0 < PACE_WINDOW_S:
            return
        self._pace_window = (wall, sim.time_s)
        self.pace_factor = factor = (sim.time_s - sim0) / (wall - wall0)
        if not factor >= self.slowest_pace_factor:
            self.slowest_pace_factor = factor
        if factor >= SLOW_FACTOR:
            return
        if self.warn_every_s is None:
            if self._slow_warned_s > -math.inf:
                return
            log.warning("simulator at %.1f× real time: this machine cannot run it in real time "
                        "now; the simulated world (its clock, telemetry and frames) slows down "
                        "with it", factor)
        elif wall - self._slow_warned_s >= self.warn_every_s:
            shed = sum(cam.shed for cam in sim.cameras.values())
            log.warning("simulator at %.1f× real time: the vehicle's clock lags the wall clock "
                        "by %.1f s in all (no real flight controller's does)%s", factor,
                        clock.held_back_s,
                        f"; {shed} frames not rendered to keep up" if self.shed_rendering
                        else "")
        else:
            return
        self._slow_warned_s = wall

    def _broadcasts(self) -> list[Broadcast]:
        return [self._telemetry, self._truth, self._events, self._mission_events, self._photos,
                self._uwb, self._rover, *self._frames.values()]

    def _publish(self, outputs: list[SimOutput]) -> None:
        for out in outputs:
            if out.kind == "telemetry":
                self.latest_state = out.payload
                self._telemetry.publish(out.payload)
            elif out.kind == "frame":
                self._frames[out.payload.camera.name].publish(out.payload)
            elif out.kind == "truth":
                self._truth.publish(out.payload)
            elif out.kind == "mission":
                self._mission_events.publish(out.payload)
            elif out.kind == "photo":
                self._photos.publish(out.payload)
            elif out.kind == "uwb":
                self._uwb.publish(out.payload)
            elif out.kind == "rover":
                self._rover.publish(out.payload)
            else:
                self._events.publish((out.delivery_s, out.payload))

    async def _run_lockstep(self) -> None:
        clock = self._clock
        assert isinstance(clock, LockstepClock)
        sim = self._sim
        try:
            while True:
                await clock.settle()
                target = sim.next_event_s()
                deadline = clock.next_deadline()
                if deadline is not None:
                    target = min(target, max(deadline, sim.time_s + sim.dt))
                outputs = self._batch(target)
                await clock.jobs_done(sim.time_s)
                clock.advance(sim.time_s)
                self._publish(outputs)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self._fail(exc)

    async def _run_realtime(self) -> None:
        clock = self._clock
        loop = asyncio.get_running_loop()
        sim = self._sim
        batch_s = self.config.realtime_batch_s
        cycle_start = time.perf_counter()
        try:
            while True:
                target = min(sim.next_event_s(), sim.time_s + batch_s)
                started_s = sim.time_s
                outputs = await loop.run_in_executor(self._executor, self._batch, target)
                resumed = time.perf_counter()
                handover = resumed - self._batch_end
                stalled = handover if handover > STALL_S else 0.0
                self._pace(sim.time_s - started_s, resumed - cycle_start - stalled)
                await clock.sleep_until(sim.time_s)
                cycle_start = time.perf_counter()  # (waiting for the clock is no loss)
                self._publish(outputs)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self._fail(exc)

    def _fail(self, exc: Exception) -> None:
        error = exc if isinstance(exc, VehicleError) else \
            ConnectionLost(f"simulator failed: {type(exc).__name__}: {exc}")
        if error is not exc:
            error.__cause__ = exc
        self._failure = error
        for broadcast in self._broadcasts():
            broadcast.close(error)
