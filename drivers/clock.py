"""Clocks: the single time base that stamps every sample.

* :class:`MonotonicClock` — wall time (``time.monotonic``), for hardware and for the simulator
  running in real time.
* :class:`PacedClock` — the real-time simulator's clock: wall time that the simulator holds back
  when the CPU cannot step the world as fast as the wall clock runs, so that the world (its
  clock, its telemetry and its frames) slows down together rather than falling behind its clock.
* :class:`LockstepClock` — simulated time that only the simulator advances, as fast as the CPU
  allows. Time stands still while any coroutine still has work to do: the simulator advances it
  only once the event loop has gone idle and no blocking job started through
  :meth:`Clock.run_blocking` is running. A lockstep run is therefore deterministic for a given
  seed, and computation takes no simulated time, unless it is given a budget: a blocking job
  run with ``budget_s`` is modelled as taking exactly that long. Time may move on while it
  runs (the simulator steps in parallel with it), its result is delivered ``budget_s`` after
  it started, and time does not pass that instant until the job has finished.

Code that must behave the same under both clocks sleeps, times out and runs blocking work
through its clock (``clock.sleep``, ``clock.wait_for``, ``clock.run_blocking``), never through
``asyncio.sleep``/``asyncio.wait_for``/``loop.run_in_executor`` directly.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import functools
import heapq
import itertools
import threading
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import Executor
from typing import Any, TypeVar

T = TypeVar("T")


class Clock(abc.ABC):
    #: True when time only moves as the simulator steps.
    lockstep: bool = False

    @abc.abstractmethod
    def now(self) -> float:
        """Current time in seconds."""

    @abc.abstractmethod
    async def sleep_until(self, time_s: float) -> None: ...

    async def sleep(self, duration_s: float) -> None:
        await self.sleep_until(self.now() + duration_s)

    async def run_blocking(self, fn: Callable[..., T], /, *args: Any,
                           executor: Executor | None = None,
                           budget_s: float | Callable[[T], float] | None = None) -> T:
        """Run blocking or CPU-heavy ``fn(*args)`` in an executor (the loop's default if None).

        ``budget_s`` is how long the job is modelled to take on a lockstep clock, or a function
        of its result that says so (e.g. the time it really took); in real time it takes as
        long as it takes, and the budget is ignored."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(executor, functools.partial(fn, *args))

    async def wait_for(self, aw: Awaitable[T], timeout_s: float) -> T:
        """Like ``asyncio.wait_for``, with the timeout measured on this clock."""
        task = asyncio.ensure_future(aw)
        timer = asyncio.ensure_future(self.sleep(timeout_s))
        try:
            await asyncio.wait({task, timer}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            timer.cancel()
            if not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        if task.cancelled():
            raise TimeoutError(f"timed out after {timeout_s:g} s")
        return task.result()


class MonotonicClock(Clock):
    """Wall-clock time from ``time.monotonic()``, shifted so that it starts at ``start_s``."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._offset = time.monotonic() - start_s

    def restart(self, start_s: float = 0.0) -> None:
        """Make ``now()`` read ``start_s`` at this instant."""
        self._offset = time.monotonic() - start_s

    def now(self) -> float:
        return time.monotonic() - self._offset

    async def sleep_until(self, time_s: float) -> None:
        await asyncio.sleep(max(0.0, time_s - self.now()))

    async def wait_for(self, aw: Awaitable[T], timeout_s: float) -> T:
        return await asyncio.wait_for(aw, timeout_s)


class PacedClock(MonotonicClock):
    """Wall time, held back by the simulator when it cannot keep up.

    It reads the wall clock less the time the simulator has lost to a slow CPU: while the
    simulator computes a stretch of the world it is capped at that stretch's end
    (:meth:`cap_at`: it stands still there if the computing takes longer than the stretch),
    and time lost otherwise can be taken back (:meth:`hold_back`: it stands still until the
    wall clock has caught up with the shift). It never goes backwards. Read from any thread.
    Sleeps and timeouts wait until this clock (not the wall clock) reaches their deadline, so
    a slowed world times out as slowly as it moves."""

    def __init__(self, start_s: float = 0.0, slack_s: float = 0.0) -> None:
        super().__init__(start_s)
        #: how far past its cap the clock may run before it stands still: a world that far
        #: behind catches up by itself on its next stretches (one slow stretch, e.g. one that
        #: renders a frame, is no slow CPU)
        self.slack_s = slack_s
        self._lock = threading.Lock()
        self._last = start_s
        self._cap: float | None = None
        #: seconds this clock has been held back behind the wall clock in all
        self.held_back_s = 0.0

    def restart(self, start_s: float = 0.0) -> None:
        with self._lock:
            super().restart(start_s)
            self._last = start_s
            self._cap = None
            self.held_back_s = 0.0

    def now(self) -> float:
        with self._lock:
            self._last = max(self._last, self._capped())
            return self._last

    def cap_at(self, time_s: float | None) -> None:
        """Never read past ``time_s`` until capped again (None: uncapped)."""
        with self._lock:
            self._capped()  # (the time spent at the old cap is held back before it goes)
            self._cap = time_s

    def _capped(self) -> float:
        t = time.monotonic() - self._offset
        if self._cap is not None and t > self._cap + self.slack_s:
            limit = self._cap + self.slack_s
            self._offset += t - limit
            self.held_back_s += t - limit
            t = limit
        return t

    def hold_back(self, seconds: float) -> None:
        """The simulated world lost ``seconds`` to the CPU: its time runs that much later."""
        if seconds > 0.0:
            with self._lock:
                self._offset += seconds
                self.held_back_s += seconds

    async def sleep_until(self, time_s: float) -> None:
        while (delay := time_s - self.now()) > 0.0:  # noqa: ASYNC110 - a clock, not an event
            await asyncio.sleep(delay)
        await asyncio.sleep(0)

    async def wait_for(self, aw: Awaitable[T], timeout_s: float) -> T:
        return await Clock.wait_for(self, aw, timeout_s)


class LockstepClock(Clock):
    """Simulated time, advanced by the simulator driver (see module docstring).

    The driver's stepping task calls :meth:`settle` (wait until everyone else is blocked),
    asks :meth:`next_deadline`, steps the physics, waits for :meth:`jobs_done` and then calls
    :meth:`advance`.
    """

    lockstep = True

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._busy = 0
        self._idle: asyncio.Event | None = None
        self._jobs: list[tuple[float, asyncio.Future[Any]]] = []  # budgeted: (deadline, job)

    def now(self) -> float:
        return self._now

    async def sleep_until(self, time_s: float) -> None:
        if time_s <= self._now:
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (time_s, next(self._seq), future))
        await future

    async def run_blocking(self, fn: Callable[..., T], /, *args: Any,
                           executor: Executor | None = None,
                           budget_s: float | Callable[[T], float] | None = None) -> T:
        if callable(budget_s):
            # the charge is known only from the result: time stands still while the job runs
            # (an unbudgeted job holds the simulator in settle), then the result arrives that
            # long after the job started
            started = self._now
            result = await self.run_blocking(fn, *args, executor=executor)
            charge = budget_s(result)
            if not charge >= 0.0:
                raise ValueError(f"budget_s must be >= 0, got {charge}")
            await self.sleep_until(started + charge)
            return result
        if budget_s is not None:
            if not budget_s >= 0.0:
                raise ValueError(f"budget_s must be >= 0, got {budget_s}")
            loop = asyncio.get_running_loop()
            job = loop.run_in_executor(executor, functools.partial(fn, *args))
            entry = (self._now + budget_s, job)
            self._jobs.append(entry)
            try:
                # the simulator stops at the deadline and waits there for the job (jobs_done)
                await self.sleep_until(entry[0])
                return await job
            finally:
                self._jobs.remove(entry)
        self._busy += 1
        try:
            return await super().run_blocking(fn, *args, executor=executor)
        finally:
            self._busy -= 1
            if self._busy == 0 and self._idle is not None:
                self._idle.set()

    # -- the simulator's side --------------------------------------------------------------

    def next_deadline(self) -> float | None:
        """Earliest time a sleeping coroutine wants to wake, or None."""
        while self._sleepers and self._sleepers[0][2].done():  # cancelled sleeps
            heapq.heappop(self._sleepers)
        return self._sleepers[0][0] if self._sleepers else None

    async def jobs_done(self, time_s: float) -> None:
        """Wait for every budgeted job whose result is due by ``time_s`` (call before
        :meth:`advance`: time may not pass a job's deadline while it is still running)."""
        due = [job for deadline, job in self._jobs if deadline <= time_s and not job.done()]
        if due:
            await asyncio.wait(due)

    def advance(self, time_s: float) -> None:
        """Move time forward and wake every sleeper that is due."""
        if time_s < self._now:
            raise ValueError(f"lockstep time cannot go back ({time_s} < {self._now})")
        self._now = time_s
        while self._sleepers and self._sleepers[0][0] <= time_s:
            _, _, future = heapq.heappop(self._sleepers)
            if not future.done():
                future.set_result(None)

    async def settle(self) -> None:
        """Return once every other coroutine is blocked and no blocking job is running.

        "Blocked" means the event loop has nothing ready to run but this coroutine. CPython's
        loop exposes its ready queue as ``_ready``; on a loop without it we yield a fixed number
        of times instead, which is good enough for short hand-over chains.
        """
        loop = asyncio.get_running_loop()
        ready = getattr(loop, "_ready", None)
        if self._idle is None:
            self._idle = asyncio.Event()
        while True:
            if self._busy:
                self._idle.clear()
                await self._idle.wait()
                continue
            await asyncio.sleep(0)
            if self._busy:
                continue
            if ready is None:
                for _ in range(16):
                    await asyncio.sleep(0)
                return
            if not ready:
                return
