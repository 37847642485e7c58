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
from collections.abc import AsyncIterator, Mapping, Sequence

from drivers.base import (
    CameraInfo,
    CameraUnavailable,
    CommandDenied,
    ConnectionLost,
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
from drivers.clock import Clock
from drivers.sim.camera_effects import RenderingUnavailable
from drivers.sim.config import SimConfig
from drivers.sim.flight.flight_stack import CommandRejected
from drivers.sim.flight.params import config_defaults
from drivers.sim.model import reported_camera_info, true_camera_info
from drivers.sim.outlets import Outlets
from drivers.sim.px4_services import Px4Services
from drivers.sim.runner import SimRunner
from drivers.sim.scenario import ScenarioObject
from drivers.sim.simulator import GroundTruth, Simulator


class SimDriver(Px4Services, Vehicle):
    #: cameras are rendered only while something subscribes to their frames
    renders_on_demand = True

    def __init__(self, config: SimConfig, *, scenario: Sequence[ScenarioObject] = (),
                 seed: int | None = None, lockstep: bool = True,
                 warn_every_s: float | None = None, shed_rendering: bool = False,
                 background: bool = True) -> None:
        self.config = config
        self._scenario = list(scenario)
        self.lockstep = lockstep
        self._cameras = {name: reported_camera_info(name, cam)
                         for name, cam in config.cameras.items() if cam.enabled}
        self._failure: VehicleError | None = None
        #: the outputs as streams (a camera's first subscriber turns it on, its last off)
        self.outlets = Outlets(self._cameras, lambda name, on: self.runner.camera_toggles.append(
            (name, on)))
        #: steps the simulator against the clock, in lockstep or in real time (the module's
        #: notes say what ``background``, ``warn_every_s`` and ``shed_rendering`` do there)
        self.runner = SimRunner(config, self._scenario, config.seed if seed is None else seed,
                                lockstep=lockstep, background=background,
                                warn_every_s=warn_every_s, shed_rendering=shed_rendering,
                                publish=self.outlets.publish, fail=self._fail)
        #: PX4 parameters as the vehicle will boot with them (the live ones once connected)
        self._param_defaults = config_defaults(config)

    @property
    def latest_state(self) -> VehicleState | None:
        """The newest telemetry sample (None before the first)."""
        return self.outlets.latest_state

    # ------------------------------------------------------------------------------------
    # Vehicle interface
    # ------------------------------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        return self.runner.clock

    @property
    def cameras(self) -> Mapping[str, CameraInfo]:
        return self._cameras

    async def connect(self, timeout_s: float = 10.0) -> None:
        if self.runner.started:
            return
        try:
            await self.runner.start()
        except RenderingUnavailable as exc:
            await self.close()
            raise CameraUnavailable(f"simulator cameras: {exc}", "rendering") from exc
        except BaseException:
            await self.close()  # (its thread too)
            raise
        # as a real link: connected once the vehicle has been heard from
        async with contextlib.aclosing(self.telemetry()) as samples:
            try:  # (on the wall clock: a simulator that never steps must not hang us)
                await asyncio.wait_for(anext(samples), timeout_s) if not self.lockstep \
                    else await self.clock.wait_for(anext(samples), timeout_s)
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

    async def precision_landing_problem(self) -> str | None:
        return None  # PX4's AUTO.PRECLAND lands on the target whatever its PLD_* say

    async def send_landing_target(self, target: LandingTarget) -> None:
        await self._command("landing_target", target.position_ned_m, target.time_s)

    async def start_offboard(self) -> None:
        await self._command("start_offboard")

    async def stop_offboard(self) -> None:
        await self._command("stop_offboard")

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        self._check_alive()
        self.runner.setpoints.append(setpoint)

    def telemetry(self, buffer: int = 1) -> AsyncIterator[VehicleState]:
        return self.outlets.telemetry.subscribe(buffer)

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
        return self.outlets.uwb.subscribe(buffer)

    def rover_states(self, buffer: int = 8) -> AsyncIterator[RoverState]:
        if "rover" not in self.sensors:
            raise SensorUnavailable("no rover is in the simulated world")
        return self.outlets.rover.subscribe(buffer)

    def frames(self, camera: str) -> AsyncIterator[Frame]:
        frames = self.outlets.frames
        if camera not in frames:
            raise ValueError(f"no camera {camera!r}; this vehicle has {sorted(frames)}")
        return frames[camera].subscribe()

    async def close(self) -> None:
        await self.runner.stop()
        self.outlets.close(self._failure)
        await self.runner.close()

    # ------------------------------------------------------------------------------------
    # Simulator-only extras (ground truth is for scoring and tests, never for the autopilot)
    # ------------------------------------------------------------------------------------

    def true_cameras(self) -> Mapping[str, CameraInfo]:
        """The cameras as they really are — true intrinsics, the mount with its error — where
        :attr:`cameras` is what their frames report (a fitted calibration, the nominal mount).
        For the log's scoring only (what a detection should have found)."""
        return {name: true_camera_info(name, self.config.cameras[name], self.runner.seed)
                for name in self._cameras}

    def ground_truth(self, buffer: int = 256) -> AsyncIterator[GroundTruth]:
        """Ground-truth samples at ``sim.ground_truth_rate_hz`` (buffered: for loggers)."""
        return self.outlets.truth.subscribe(buffer)

    def events(self, buffer: int = 64) -> AsyncIterator[tuple[float, str]]:
        """The flight stack's status messages (mode changes, failsafes), like STATUSTEXT."""
        return self.outlets.events.subscribe(buffer)

    @property
    def simulator(self) -> Simulator:
        """The simulator core, for tests (touch it only while time stands still)."""
        return self._require_sim()

    @property
    def sim_time_s(self) -> float:
        return self.runner.sim.time_s if self.runner.sim is not None else 0.0

    @property
    def wall_time_s(self) -> float:
        return self.runner.wall_time_s

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

    def _require_sim(self) -> Simulator:
        if self.runner.sim is None:
            raise ConnectionLost("not connected: call connect() first")
        return self.runner.sim

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
        try:
            return await self.runner.call(fn, *args)
        except CommandRejected as exc:
            raise CommandDenied(name, exc.reason) from None

    def _fail(self, exc: Exception) -> None:
        error = exc if isinstance(exc, VehicleError) else \
            ConnectionLost(f"simulator failed: {type(exc).__name__}: {exc}")
        if error is not exc:
            error.__cause__ = exc
        self._failure = error
        self.outlets.close(error)
