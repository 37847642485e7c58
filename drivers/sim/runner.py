"""Runs the synchronous :class:`~drivers.sim.simulator.Simulator` against a clock from the
event loop, in batches (never hopping the loop per physics step): in lockstep on the loop's
thread, in real time on a thread of its own, paced by a :class:`~drivers.sim.pacing.Pacer`.
What the driver queued (setpoints, cameras turned on or off) is applied at the start of each
batch and before each call on the simulator. The modes are described in
:mod:`drivers.sim.driver`."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from drivers.base import Setpoint
from drivers.clock import LockstepClock, PacedClock
from drivers.sim.camera import lower_thread_priority
from drivers.sim.config import SimConfig
from drivers.sim.pacing import CATCH_UP_S, Pacer
from drivers.sim.scenario import ScenarioObject
from drivers.sim.simulator import SimOutput, Simulator

#: a batch's outputs waiting longer than this for the event loop: the loop stalled (the CPU is
#: not slow); half the runtime's loop_stall_s (its default 0.5 s)
STALL_S = 0.25


class SimRunner:
    def __init__(self, config: SimConfig, scenario: Sequence[ScenarioObject], seed: int, *,
                 lockstep: bool, background: bool, warn_every_s: float | None,
                 shed_rendering: bool, publish: Callable[[list[SimOutput]], None],
                 fail: Callable[[Exception], None]) -> None:
        self.config = config
        self._scenario = scenario
        #: the simulator's seed (its noise, its cameras' mount errors)
        self.seed = seed
        self.lockstep = lockstep
        self.clock: LockstepClock | PacedClock = LockstepClock() if lockstep \
            else PacedClock(slack_s=CATCH_UP_S)
        #: real time: the simulator's threads (physics, telemetry, rendering) at a lower CPU
        #: priority (see SimDriver)
        self.background = background
        #: real time: the real-time factor kept, measured and said
        self.pacer = Pacer(self.clock, warn_every_s, shed_rendering) if not lockstep else None
        self._publish, self._fail = publish, fail
        #: the simulator (None before :meth:`start`)
        self.sim: Simulator | None = None
        #: real time: the simulator's thread
        self.executor: ThreadPoolExecutor | None = None
        self._task: asyncio.Task[None] | None = None
        #: what the event loop queued for the next batch
        self.setpoints: deque[Setpoint] = deque()
        self.camera_toggles: deque[tuple[str, bool]] = deque()
        self._closed = False
        self._wall_start = 0.0
        self._batch_end = 0.0  # (perf_counter) when the newest batch ended

    @property
    def started(self) -> bool:
        return self._task is not None

    @property
    def wall_time_s(self) -> float:
        return time.perf_counter() - self._wall_start if self._wall_start else 0.0

    async def start(self) -> None:
        """Build the simulator (its cameras ready to render) and start stepping it."""
        loop = asyncio.get_running_loop()
        self._closed = False
        if self.lockstep:
            self.sim = self._build()
        else:
            self.executor = ThreadPoolExecutor(
                max_workers=1, thread_name_prefix="simulator",
                initializer=lower_thread_priority if self.background else None)
            self.sim = await loop.run_in_executor(self.executor, self._build)
            self.clock.restart(self.sim.time_s)
        self._wall_start = time.perf_counter()
        run = self._run_lockstep if self.lockstep else self._run_realtime
        self._task = loop.create_task(run(), name="sim-driver")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def close(self) -> None:
        """Stop stepping and release the simulator (its renderer, its thread); once."""
        await self.stop()
        if self._closed:
            return
        self._closed = True
        if self.executor is not None:
            if self.sim is not None:
                await asyncio.get_running_loop().run_in_executor(self.executor, self.sim.close)
            self.executor.shutdown(wait=True)
            self.executor = None
        elif self.sim is not None:
            self.sim.close()

    async def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` on the simulator's thread, between physics batches; its result."""

        def on_sim_thread():
            self._drain_inbox()
            return fn(*args)

        if self.executor is None:  # lockstep: time stands still while we are running
            return on_sim_thread()
        return await self.clock.run_blocking(on_sim_thread, executor=self.executor)

    def _build(self) -> Simulator:
        sim = Simulator(self.config, self._scenario, self.seed)
        try:
            if not self.lockstep:
                # rendering as the real-time driver needs (see camera.py): each scheduled frame
                # held until realtime_render_lead_s before it is due, at a lower priority
                sim.rig.render_gate = self._wait_for_clock
                sim.rig.background = self.background
            sim.prepare_cameras()
        except BaseException:
            sim.close()
            raise
        return sim

    def _wait_for_clock(self, time_s: float) -> None:
        """Block this (non-loop) thread until the real-time clock reads ``time_s``."""
        delay = time_s - self.clock.now()
        if delay > 0.0:
            time.sleep(delay)

    def _drain_inbox(self) -> None:
        """On the simulator thread: apply what the loop thread queued since the last batch."""
        sim = self.sim
        while self.camera_toggles:
            sim.set_camera_active(*self.camera_toggles.popleft())
        while self.setpoints:
            sim.push_setpoint(self.setpoints.popleft())

    def _batch(self, until_s: float) -> list[SimOutput]:
        paced = isinstance(self.clock, PacedClock)
        if paced:  # the world is not past this batch's end before the batch has computed it
            self.clock.cap_at(until_s)
        try:
            self._drain_inbox()
            outputs = self.sim.advance_to(until_s)
        finally:
            if paced:
                self.clock.cap_at(None)
        self._batch_end = time.perf_counter()
        return outputs

    async def _run_lockstep(self) -> None:
        clock = self.clock
        assert isinstance(clock, LockstepClock)
        sim = self.sim
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
        clock = self.clock
        loop = asyncio.get_running_loop()
        sim = self.sim
        batch_s = self.config.realtime_batch_s
        cycle_start = time.perf_counter()
        try:
            while True:
                target = min(sim.next_event_s(), sim.time_s + batch_s)
                started_s = sim.time_s
                outputs = await loop.run_in_executor(self.executor, self._batch, target)
                resumed = time.perf_counter()
                handover = resumed - self._batch_end
                stalled = handover if handover > STALL_S else 0.0
                self.pacer.after_cycle(sim, sim.time_s - started_s,
                                       resumed - cycle_start - stalled)
                await clock.sleep_until(sim.time_s)
                cycle_start = time.perf_counter()  # (waiting for the clock is no loss)
                self._publish(outputs)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self._fail(exc)
