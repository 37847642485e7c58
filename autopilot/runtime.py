"""The runtime: one event loop, one task per stage, latest-value hand-over between them.

::

    vehicle.frames ─► detection (executor) ─► [slot] ─► estimation ─► [event] ─┐
    vehicle.telemetry ─► pose history, latest state ────────────────────────────┤
                                                           control (≥ control_rate_hz,
                                                           and on every estimate)
                                                                   │ intent (expires)
                                                                   ▼
                                                      setpoint streaming ─► vehicle

* Frames and telemetry carry their capture times end to end: a detection is placed in the world
  with the vehicle pose at its frame's capture time, and the latency of each setpoint computed
  from a frame (capture → sent) is logged.
* A setpoint is an *intent with an expiry*: the streaming task re-sends it at
  ``setpoint_rate_hz`` only until ``setpoint_expiry_s`` after the control step made it. If the
  control task stalls, streaming stops, and the vehicle's own offboard-loss failsafe takes over.
* :meth:`Runtime.request_stop` (Ctrl-C, SIGTERM) switches the mission to its safe stop — hold,
  land, disarm — bounded by ``shutdown_timeout_s``; every task belongs to one TaskGroup, so none
  outlives the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import cv2
import numpy as np

from autopilot.behaviors.base import BehaviorInputs, RequestKind, VehicleRequest
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.mission import MissionExecutor, MissionOutput, MissionPlan, build_behavior
from autopilot.perception.ball import BallDetection
from autopilot.pipeline import TargetPipeline, detection_record
from drivers.base import Frame, Setpoint, Vehicle, VehicleError, VehicleState
from drivers.slots import LatestSlot


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
    time_s: float
    seq: int
    frame: Frame
    detection: BallDetection | None


@dataclass
class RunStats:
    frames: int = 0
    detections: int = 0
    follow_frames: int = 0
    follow_detections: int = 0
    setpoints_sent: int = 0
    frames_log_dropped: int = 0
    stages_ms: list[float] = field(default_factory=list)


FRAME_LOG_BUFFER = 32  # frames waiting for JPEG encoding; more are dropped (and counted)
FRAME_LOG_PIPELINE = 3  # frames being encoded at once (each within this many frame periods)


class FrameSampler:
    """Which frames of a camera go to the log: ``rate_hz`` per second on average, evenly
    spread; every frame when the rate is at or above the camera's."""

    def __init__(self, rate_hz: float, camera_rate_hz: float) -> None:
        self._period_s = 1.0 / rate_hz if rate_hz > 0 else math.inf
        self._slack_s = 0.5 / camera_rate_hz if camera_rate_hz > 0 else 0.0
        self._due_s = -math.inf

    def take(self, time_s: float) -> bool:
        if math.isinf(self._period_s) or time_s < self._due_s - self._slack_s:
            return False
        # the next one is due a period after this one was due (the rate holds on average);
        # after a gap (or at the start), a period after this one
        due = self._due_s + self._period_s
        self._due_s = due if due >= time_s else time_s + self._period_s
        return True


def encode_jpeg(image_bgr: np.ndarray, quality: int) -> bytes:
    """JPEG without chroma subsampling (4:4:4): colour detection lives on the chroma, and
    halving its resolution moves a ball's edge by a few tenths of a pixel."""
    ok, buffer = cv2.imencode(".jpg", image_bgr, [
        cv2.IMWRITE_JPEG_QUALITY, quality,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buffer.tobytes()


class Runtime:
    def __init__(self, vehicle: Vehicle, plan: MissionPlan, log: FlightLog, *,
                 progress: Callable[[str], None] | None = None,
                 log_cameras: Mapping[str, float] | None = None) -> None:
        self.vehicle = vehicle
        self.plan = plan
        self.config = plan.config
        self.log = log
        self.clock = vehicle.clock
        cfg = plan.config
        self.pipeline = TargetPipeline(cfg)
        self.filter = self.pipeline.filter
        self.history = self.pipeline.history
        self.camera_name = cfg.perception.ball.camera
        self.stats = RunStats()
        self.status = "running"
        self.reason = ""
        self.errors: list[BaseException] = []
        self._progress = progress
        self._state: VehicleState | None = None
        self._frames: LatestSlot[ProcessedFrame] = LatestSlot()
        self._estimated: LatestSlot[float] = LatestSlot()  # capture time of the frame used
        self._last_frame: ProcessedFrame | None = None
        self._last_detection: BallDetection | None = None
        self._intent: Intent | None = None
        self._last_send_s = -math.inf
        self._stop_reason: str | None = None
        self._stop_requested = asyncio.Event()
        self._stale = False  # the pose went stale: no more motion setpoints this run
        self._executor: MissionExecutor | None = None
        self._step = ""
        self._phase = ""
        self._detect_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="detect")
        # camera frames for the log: which cameras, how often; encoded off the loop
        if log_cameras is None:
            frames = cfg.log.frames
            rate = frames.sim_rate_hz if cfg.driver == "sim" else frames.vehicle_rate_hz
            log_cameras = {self.camera_name: rate}
        cams = vehicle.cameras
        self._samplers = {} if log.path is None else {
            name: FrameSampler(rate, cams[name].rate_hz)
            for name, rate in log_cameras.items() if rate > 0 and name in cams}
        self._to_log: asyncio.Queue[Frame] = asyncio.Queue(maxsize=FRAME_LOG_BUFFER)
        self._log_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="frame-log")
        self._encoding: deque[tuple[Frame, asyncio.Future[bytes]]] = deque()

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
        behaviors = [build_behavior(step, self.config, cameras) for step in self.plan.steps]
        self._executor = MissionExecutor(behaviors)
        try:
            async with asyncio.TaskGroup() as tasks:
                background = [
                    tasks.create_task(self._telemetry(), name="telemetry"),
                    tasks.create_task(self._detection(), name="detection"),
                    tasks.create_task(self._estimation(), name="estimation"),
                    tasks.create_task(self._streaming(), name="setpoint-streaming"),
                    *self._simulator_tasks(tasks),
                ]
                if self._samplers:
                    background.append(tasks.create_task(self._log_frames(), name="frame-log"))
                    background += [
                        tasks.create_task(self._other_camera(name), name=f"camera-{name}")
                        for name in self._samplers if name != self.camera_name]
                if self._progress is not None:
                    background.append(tasks.create_task(self._report_progress(), name="progress"))
                try:
                    await self._control()
                finally:
                    for task in background:
                        task.cancel()
        except* Exception as group:  # the link broke, or a bug: never leave the motors running
            self.status = "failed"
            self.reason = "; ".join(f"{type(e).__name__}: {e}" for e in group.exceptions)
            self.errors = list(group.exceptions)
            await self._last_resort()
        finally:
            self._detect_pool.shutdown(wait=True, cancel_futures=True)
            self._drain_frame_log()
            self._log_pool.shutdown(wait=True, cancel_futures=True)
        return self.status

    async def _control(self) -> None:
        executor = self._executor
        state = await self._first_state()
        out = executor.start(self._inputs(state))
        await self._apply(out)
        period = 1.0 / self.config.runtime.control_rate_hz
        deadline: float | None = None
        while not out.finished:
            source = await self._next_tick(period)
            inputs = self._inputs(self._state)
            stale = self._telemetry_stale()
            if stale is not None and not self._stale:
                # flying blind: no motion setpoint may go out on an old pose; hold, and let
                # the mission's fallback bring the vehicle down (as for a lost link)
                self._stale = True
                self._intent = None
                self._event(self.clock.now(), f"telemetry stale: {stale}; setpoints stopped")
                with contextlib.suppress(VehicleError, TimeoutError):
                    await self.clock.wait_for(self.vehicle.hold(), 2.0)
                out = executor.abort(f"telemetry stale: {stale}", inputs)
                await self._apply(out, None)
                continue
            if self._stop_requested.is_set() and deadline is None:
                deadline = self.clock.now() + self.config.runtime.shutdown_timeout_s
                out = executor.abort(self._stop_reason or "stop requested", inputs)
            elif deadline is not None and self.clock.now() > deadline:
                self.status, self.reason = "failed", "safe stop did not finish in time"
                await self._last_resort()
                return
            else:
                out = executor.update(inputs)
            await self._apply(out, source)
        self.status = executor.status
        self.reason = executor.failure

    async def _apply(self, out: MissionOutput, source_frame_s: float | None = None) -> None:
        now = self.clock.now()
        for text in out.events:
            self._event(now, text)
        self._step, self._phase = out.step, out.phase
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

    async def _perform(self, request: VehicleRequest) -> None:
        v = self.vehicle
        self._event(self.clock.now(), f"request {request.kind.value}")
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

    async def _last_resort(self) -> None:
        """The orderly stop failed or the link broke: one bounded attempt to land."""
        with contextlib.suppress(Exception):
            await self.clock.wait_for(self.vehicle.land(), 2.0)

    # ------------------------------------------------------------------------------------
    # Stages
    # ------------------------------------------------------------------------------------

    async def _telemetry(self) -> None:
        async with contextlib.aclosing(self.vehicle.telemetry(buffer=64)) as samples:
            async for state in samples:
                self._state = state
                self.pipeline.add_state(state)
                record = ch.vehicle_state_record(state)
                record["received_s"] = self.clock.now()
                self.log.write(ch.VEHICLE_STATE, state.time_s, record)

    async def _detection(self) -> None:
        camera = self.vehicle.cameras[self.camera_name]
        self.log.write(ch.CAMERA_INFO, self.clock.now(), ch.camera_info_record(camera))
        async with contextlib.aclosing(self.vehicle.frames(self.camera_name)) as frames:
            async for frame in frames:
                received = self.clock.now()
                self._offer_frame(frame)
                hint = self.pipeline.hint(frame.time_s, frame.camera)
                started = time.perf_counter()
                detection = await self.clock.run_blocking(
                    self.pipeline.detect, frame.image, frame.camera, frame.time_s, hint,
                    executor=self._detect_pool, budget_s=self.config.runtime.lockstep_detection_s)
                elapsed_ms = (time.perf_counter() - started) * 1e3
                processed = ProcessedFrame(frame.time_s, frame.seq, frame, detection)
                self._frames.put(processed)
                self._count_frame(detection)
                record = detection_record(frame.seq, frame.time_s, frame.camera.name, detection,
                                          hint)
                record.update(processing_ms=elapsed_ms, received_s=received,
                              detected_s=self.clock.now())
                self.log.write(ch.BALL_DETECTIONS, frame.time_s, record)

    def _offer_frame(self, frame: Frame) -> None:
        """Hand a frame to the frame log if its camera's rate wants it (never waits: a full
        buffer drops the frame and counts it)."""
        sampler = self._samplers.get(frame.camera.name)
        if sampler is None or not sampler.take(frame.time_s):
            return
        try:
            self._to_log.put_nowait(frame)
        except asyncio.QueueFull:
            self.stats.frames_log_dropped += 1

    async def _log_frames(self) -> None:
        """Encode frames for the log (JPEG, off the loop) and write them in order.

        Up to ``FRAME_LOG_PIPELINE`` frames are in hand at once, each modelled (on the lockstep
        clock) as encoded within that many frame periods: the encoder uses the CPU the rest
        of the pipeline leaves idle instead of the simulator stopping for it every frame."""
        quality = self.config.log.frames.jpeg_quality
        pending = self._encoding
        try:
            while True:
                frame = await self._to_log.get()
                pending.append((frame, asyncio.ensure_future(self.clock.run_blocking(
                    encode_jpeg, frame.image, quality, executor=self._log_pool,
                    budget_s=FRAME_LOG_PIPELINE / frame.camera.rate_hz))))
                while pending and (pending[0][1].done() or len(pending) >= FRAME_LOG_PIPELINE):
                    done, job = pending[0]
                    jpeg = await job
                    pending.popleft()
                    self.log.write_image(done.camera.name, done.time_s, jpeg)
        finally:
            for _, job in pending:
                job.cancel()

    def _drain_frame_log(self) -> None:
        """Frames still waiting when the run ends are written now (the last second of a
        flight belongs in its video)."""
        quality = self.config.log.frames.jpeg_quality
        waiting = [frame for frame, _ in self._encoding]
        self._encoding.clear()
        while not self._to_log.empty():
            waiting.append(self._to_log.get_nowait())
        for frame in waiting:
            with contextlib.suppress(Exception):  # the run's outcome matters more than a frame
                self.log.write_image(frame.camera.name, frame.time_s,
                                     encode_jpeg(frame.image, quality))

    async def _other_camera(self, name: str) -> None:
        """Frames of a camera that nothing but the log uses (the video's chosen camera)."""
        async with contextlib.aclosing(self.vehicle.frames(name)) as frames:
            async for frame in frames:
                self._offer_frame(frame)

    async def _estimation(self) -> None:
        while True:
            item = await self._frames.get()
            self._last_frame = item
            det = item.detection
            if det is not None:
                self._last_detection = det
                record = self.pipeline.estimate(item.time_s, item.frame.camera, det)
                if record is not None:
                    self.log.write(ch.TARGET_ESTIMATES, item.time_s, record)
            self._estimated.put(item.time_s)

    async def _streaming(self) -> None:
        period = 1.0 / self.config.runtime.setpoint_rate_hz
        while True:
            await self.clock.sleep(period)
            intent = self._intent
            now = self.clock.now()
            if intent is not None and now < intent.expires_s and not self._stale and \
                    now - self._last_send_s >= 0.9 * period and self._telemetry_stale() is None:
                await self._send(intent)

    async def _send(self, intent: Intent) -> None:
        await self.vehicle.send_setpoint(intent.setpoint)
        now = self.clock.now()
        self._last_send_s = now
        self.stats.setpoints_sent += 1
        if not intent.sent:
            intent.sent = True
            sp = intent.setpoint
            latency = None if intent.source_frame_time_s is None \
                else (now - intent.source_frame_time_s) * 1e3
            self.log.write(ch.SETPOINTS, now, {
                "time_s": now, "source_frame_time_s": intent.source_frame_time_s,
                "latency_ms": latency, "frame": sp.frame.value,
                "position_ned_m": sp.position_ned_m, "velocity_m_s": sp.velocity_m_s,
                "yaw_rad": sp.yaw_rad, "yaw_rate_rad_s": sp.yaw_rate_rad_s,
                "expires_s": intent.expires_s, "step": intent.step, "phase": intent.phase})

    def _simulator_tasks(self, tasks: asyncio.TaskGroup) -> list[asyncio.Task]:
        """Ground truth and status messages, when the vehicle is the simulator (for the log
        and scoring only; nothing here reaches the autopilot's decisions)."""
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

    def _telemetry_stale(self) -> str | None:
        """Why the newest pose is too old to fly on (None: it is fresh): position or attitude
        captured longer ago than ``runtime.telemetry_max_age_s``."""
        state = self._state
        if state is None:
            return None
        now = self.clock.now()
        limit = self.config.runtime.telemetry_max_age_s
        ages = {"position": now - state.time_s, "attitude": now - state.attitude_time_s}
        old = {name: age for name, age in ages.items() if age > limit}
        if not old:
            return None
        return ", ".join(f"{name} {age:.2f} s old" for name, age in old.items()) + \
            f" (limit {limit:g} s)"

    def _inputs(self, state: VehicleState) -> BehaviorInputs:
        now = self.clock.now()
        frame = self._last_frame
        return BehaviorInputs(
            now_s=now, state=state, target=self.filter.estimate(now),
            detection=frame.detection if frame is not None else None,
            last_detection=self._last_detection,
            frame_seq=frame.seq if frame is not None else -1)

    def _count_frame(self, detection: BallDetection | None) -> None:
        self.stats.frames += 1
        self.stats.detections += detection is not None
        if self._step == "follow_ball":
            self.stats.follow_frames += 1
            self.stats.follow_detections += detection is not None

    def _event(self, time_s: float, text: str) -> None:
        self.log.write(ch.MISSION_EVENTS, time_s, {"time_s": time_s, "step": self._step,
                                                    "text": text})
        if self._progress is not None and not text.startswith("request "):
            self._progress(f"[{time_s:7.2f} s] {text}")

    def _log_plan(self) -> None:
        plan = self.plan
        follow = next((s.params for s in plan.steps if s.name == "follow_ball"), None)
        standoff = (follow.standoff_m if follow is not None and follow.standoff_m else
                    self.config.control.follow.standoff_m)
        self.log.write(ch.MISSION_PLAN, self.clock.now(), ch.clean({
            "mission": plan.mission.name, "source": str(plan.source),
            "steps": [{s.name: s.params.model_dump()} for s in plan.steps],
            "standoff_m": standoff, "camera": self.camera_name,
            "ball_diameter_m": self.config.perception.ball.diameter_m,
            "config": self.config.model_dump(mode="json"),
            "driver": self.config.driver,
            "scenario": plan.mission.scenario.model_dump() if plan.mission.scenario else None}))

    def progress_line(self) -> str:
        s = self._state
        now = self.clock.now()
        parts = [f"t={now:6.1f}s", f"step={self._step or '-'}", f"phase={self._phase or '-'}"]
        if s is not None:
            parts += [f"mode={s.mode.value}", f"alt={s.altitude_m:4.1f}m"]
            est = self.filter.estimate(now)
            if est is not None and not est.stale:
                distance = float(np.linalg.norm(est.position_ned_m - s.position_ned_m))
                parts.append(f"target={distance:4.2f}m")
        st = self.stats
        if st.follow_frames:
            parts.append(f"det={100.0 * st.follow_detections / st.follow_frames:3.0f}%")
        return " ".join(parts)

    async def _report_progress(self) -> None:
        interactive = sys.stderr.isatty()
        interval = 0.25 if interactive else self.config.runtime.progress_interval_s
        while True:
            await asyncio.sleep(interval)  # wall time: progress is for the person watching
            line = self.progress_line()
            if interactive:
                sys.stderr.write("\r" + line.ljust(100))
                sys.stderr.flush()
            else:
                self._progress(line)
