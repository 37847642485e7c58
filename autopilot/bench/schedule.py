"""Many lockstep flights, spread over the machine's cores, with how long they will take said
before they start.

A flight is a whole ``autopilot run`` on the simulator's lockstep clock (deterministic for its
seed), so where it flies changes nothing of its result: flights go to worker processes, one per
usable core (``workers``; 1 flies them here, one after the other), and come back in the order
they were asked for. A run keeps about one and a half cores busy (the simulation and the
autopilot's event loop, the render thread and the rasteriser's threads): one at a time leaves a
core partly idle, one per core keeps both busy.

How long: each flight's wall time on this machine is kept, per kind of flight (its mission and
sensor profile, the variant and the number of workers it shared the machine with), in the
user's cache (``$XDG_CACHE_HOME/autopilot/flight_times.json``, or the file
``$AUTOPILOT_FLIGHT_TIMES`` names); the estimate before a batch
starts is the sum of the kinds' last times over the workers, and after each flight it is
re-made from the flights done. A kind never flown here has no estimate until its first flight
ends (the line says so).
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

#: how much of a kind's history a new time counts for (the rest: the times before it)
_NEW_WEIGHT = 0.5


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity; the count of cores elsewhere)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def workers_for(workers: int | None, flights: int) -> int:
    """``workers`` (default: one per usable core), never more than there are flights."""
    return max(1, min(workers or usable_cores(), flights))


def _history_path() -> Path:
    """``$AUTOPILOT_FLIGHT_TIMES`` if set (the tests' own), else the user's cache."""
    if os.environ.get("AUTOPILOT_FLIGHT_TIMES"):
        return Path(os.environ["AUTOPILOT_FLIGHT_TIMES"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "autopilot" / "flight_times.json"


class FlightTimes:
    """Wall seconds per kind of flight on this machine (see the module's notes). A cache that
    cannot be read or written is no cache: nothing fails for it."""

    def __init__(self, path: Path | None = None):
        self.path = path or _history_path()
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            self.times = {str(k): float(v) for k, v in data.items()
                          if isinstance(v, int | float) and v > 0}
        except (OSError, ValueError, AttributeError):
            self.times = {}

    def get(self, kind: str) -> float | None:
        return self.times.get(kind)

    def add(self, kind: str, wall_s: float) -> None:
        old = self.times.get(kind)
        self.times[kind] = wall_s if old is None else _NEW_WEIGHT * wall_s + (1 - _NEW_WEIGHT) * old

    def save(self) -> None:
        with contextlib.suppress(OSError):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(json.dumps(self.times, indent=1, sort_keys=True), encoding="utf-8")
            tmp.replace(self.path)


def kind_of(mission: str, profile: str, variant: str, workers: int) -> str:
    """The key a flight's time is kept under."""
    return f"{Path(mission).stem}|{profile}|{variant}|{workers} workers"


def duration_text(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


@dataclass(frozen=True, slots=True)
class Estimate:
    """What a batch will take: ``seconds`` for the flights whose kind has a time here,
    ``unknown`` flights whose kind has none."""
    flights: int
    workers: int
    seconds: float
    unknown: int

    def text(self) -> str:
        head = f"{self.flights} flight{'s' * (self.flights != 1)} on {self.workers} " \
               f"worker{'s' * (self.workers != 1)}"
        if self.unknown == self.flights:
            return (f"{head}: no earlier flight of this kind on this machine to tell how long "
                    "they take; the time left is told once the first one ends")
        more = f" and {self.unknown} never flown here" if self.unknown else ""
        return f"{head}: about {duration_text(self.seconds)}{more} (from earlier flights here)"


def makespan(durations: Sequence[float], workers: int) -> float:
    """How long ``durations`` take on ``workers``, each flight taken in order by the first
    worker free (as a process pool takes them)."""
    free = [0.0] * max(1, workers)
    for d in durations:
        heapq.heapreplace(free, free[0] + d)
    return max(free)


def estimate(kinds: Sequence[str], workers: int, times: FlightTimes) -> Estimate:
    known = [times.get(k) for k in kinds]
    return Estimate(len(kinds), workers, makespan([t for t in known if t is not None], workers),
                    sum(t is None for t in known))


class Progress:
    """The time left after each flight: the flights not yet done laid out on the workers,
    each taking its kind's time (this batch's flights counted in), a kind with none the mean
    of the flights done. It counts the flights in the air as not begun: an upper figure."""

    def __init__(self, kinds: Sequence[str], workers: int, times: FlightTimes):
        self.kinds, self.workers, self.times = list(kinds), workers, times
        self.pending = set(range(len(self.kinds)))
        self.walls: list[float] = []
        self.started = time.perf_counter()

    def flown(self, index: int, wall_s: float | None) -> str:
        """``wall_s`` None: a flight that failed (its time is not kept)."""
        self.pending.discard(index)
        if wall_s is not None:
            self.times.add(self.kinds[index], wall_s)
            self.walls.append(wall_s)
        done, total = len(self.kinds) - len(self.pending), len(self.kinds)
        if not self.pending:
            return f"{done}/{total} done in {duration_text(time.perf_counter() - self.started)}"
        mean = sum(self.walls) / len(self.walls) if self.walls else None
        left = [self.times.get(self.kinds[i]) or mean for i in sorted(self.pending)]
        if any(t is None for t in left):
            return f"{done}/{total} done"
        return f"{done}/{total} done, about {duration_text(makespan(left, self.workers))} left"


def fly_summary(mission: str, overrides: Sequence[str]) -> dict:
    """One flight, in this process: ``autopilot run``'s summary (no log written)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from autopilot.mission import load_mission
    from autopilot.run import fly

    return asyncio.run(fly(load_mission(mission, list(overrides)), None))


def _timed(fn: Callable, args: tuple) -> tuple[object, float]:
    started = time.perf_counter()
    result = fn(*args)
    return result, time.perf_counter() - started


def run_all(jobs: Sequence[tuple], kinds: Sequence[str], workers: int,
            fn: Callable = fly_summary, *, announce: Callable[[str], None] = lambda _: None,
            log: Callable[[str], None] = lambda _: None,
            describe: Callable[[int, object], str] | None = None,
            on_error: Callable[[int, BaseException], object] | None = None,
            times: FlightTimes | None = None) -> Iterator[tuple[int, object]]:
    """``fn(*job)`` for each job (``fn`` importable by a worker process), on ``workers``
    processes (1: here); yields ``(index, result)`` as they end. ``kinds[i]`` is job i's kind
    of flight: the estimate goes to ``announce`` before the first starts, the time left to
    ``log`` after each, once the caller has taken its result (after ``describe(i, result)``,
    if given). A job that raises (or whose
    worker died) ends the batch with its error, unless ``on_error(i, error)`` makes a result of
    it."""
    times = times or FlightTimes()

    def flown(i: int, result: object, wall_s: float | None) -> None:
        line = progress.flown(i, wall_s)
        log(f"{describe(i, result)}; {line}" if describe else line)

    announce(estimate(kinds, workers, times).text())
    progress = Progress(kinds, workers, times)
    try:
        if workers <= 1:
            for i, job in enumerate(jobs):
                try:
                    result, wall_s = _timed(fn, job)
                except Exception as exc:
                    if on_error is None:
                        raise
                    result, wall_s = on_error(i, exc), None
                yield i, result
                flown(i, result, wall_s)
            return
        ctx = get_context("spawn")  # MuJoCo's GL contexts do not survive a fork
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            pending = {pool.submit(_timed, fn, job): i for i, job in enumerate(jobs)}
            try:
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        i = pending.pop(future)
                        try:
                            result, wall_s = future.result()
                        except Exception as exc:  # (a worker that died: a crash, memory)
                            if on_error is None:
                                raise
                            result, wall_s = on_error(i, exc), None
                        yield i, result
                        flown(i, result, wall_s)
            finally:
                for future in pending:
                    future.cancel()
    finally:
        times.save()


def run_ordered(jobs: Sequence[tuple], kinds: Sequence[str], workers: int,
                fn: Callable = fly_summary, **kwargs) -> list:
    """:func:`run_all`'s results in the jobs' order."""
    results: list = [None] * len(jobs)
    for i, result in run_all(jobs, kinds, workers, fn, **kwargs):
        results[i] = result
    return results
