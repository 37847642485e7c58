"""Where a run's CPU time goes, stage by stage (``autopilot run --stages``, ``autopilot bench
speed``): each stage's CPU time on the thread that did the work (``time.thread_time``, so a
thread waiting for another costs nothing), kept per thread and summed on reading.

The stages are charged where the work is done, at a coarse grain (a batch of physics steps, a
control tick, a frame), so that counting costs well under 1 % of a run:

==================  ===========================================================================
physics             MuJoCo's steps, the airframe's rotors and forces, scripted motion
flight stack        the simulated autopilot's control ticks (estimator, position, attitude,
                    rate loops, its sensors' update)
sensors             telemetry, ground truth and rover readings captured, the cameras' scenes
                    snapshot (``mjv_updateScene``)
render.CAM          drawing camera CAM and reading its pixels back (MuJoCo, OpenGL calls)
rasteriser          Mesa llvmpipe's own threads (software OpenGL; all cameras)
camera model.CAM    distortion, rolling shutter, blur, exposure, noise
codec.CAM           the JPEG or H.264 round trip
detection.NAME      a pipeline's detector (one entry per pipeline)
estimation          the pipelines' estimators (tracks, filters)
control             the runtime's control ticks (behaviours, setpoints, failsafes)
logging             flight-log records encoded and written (its writer thread too)
metrics             the end-of-run metrics from the log
==================  ===========================================================================

Off unless :meth:`Stages.start` is called: a stage then costs two clock reads (about 2 µs).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Iterator


class Stages:
    def __init__(self) -> None:
        #: counting? (read by the charging code before it reads the clock)
        self.on = False
        self._lock = threading.Lock()
        #: (thread name, its table, the thread): a table per thread that has counted
        self._tables: list[tuple[str, defaultdict[str, int], threading.Thread]] = []
        self._local = threading.local()
        self._raster_start_ns = 0
        self._raster_ns = 0
        #: each thread's whole CPU time: at the start (by thread id), and the latest seen
        self._thread_start_ns: dict[int, int] = {}
        self._thread_ns: dict[int, tuple[str, int]] = {}
        #: each task's (every thread's, Mesa's too) time spent runnable waiting for a core
        self._wait_start_ns: dict[str, int] = {}
        self._wait_ns: dict[str, int] = {}

    def start(self) -> None:
        """Count from now (what was counted before is forgotten)."""
        with self._lock:
            # (the tables of threads that have ended go: a long process runs many flights)
            self._tables = [entry for entry in self._tables if entry[2].is_alive()]
            for _, table, _ in self._tables:
                table.clear()
        self._raster_start_ns, self._raster_ns = rasteriser_cpu_ns(), 0
        self._thread_ns = {}
        self._thread_start_ns = {ident: ns for ident, (_, ns) in _threads_cpu_ns().items()}
        self._wait_start_ns, self._wait_ns = _tasks_waiting_ns(), {}
        self.on = True

    def sample_threads(self) -> None:
        """Read every thread's CPU time now, the rasteriser's too: threads end (a renderer
        released takes Mesa's with it, a pool shut down its workers) taking theirs with them.
        Called before such a release, and by :meth:`stop`."""
        if not self.on:
            return
        self._raster_ns = max(self._raster_ns, rasteriser_cpu_ns() - self._raster_start_ns)
        for ident, (name, ns) in _threads_cpu_ns().items():
            ns -= self._thread_start_ns.get(ident, 0)
            if ns > self._thread_ns.get(ident, ("", -1))[1]:
                self._thread_ns[ident] = (name, ns)
        for tid, ns in _tasks_waiting_ns().items():
            ns -= self._wait_start_ns.get(tid, 0)
            if ns > self._wait_ns.get(tid, -1):
                self._wait_ns[tid] = ns

    def run_queue_wait_s(self) -> float | None:
        """How long the process's threads (all, Mesa's too) were runnable but waited for a
        core while counting, summed, as last sampled (None: not known on this system)."""
        return sum(self._wait_ns.values()) / 1e9 if self._wait_ns else None

    def threads(self) -> dict[str, float]:
        """Each thread's whole CPU time while counting, counted in a stage or not (by name; a
        pool's threads together), as last sampled."""
        out: defaultdict[str, float] = defaultdict(float)
        for name, ns in self._thread_ns.values():
            out[name] += ns / 1e9
        return dict(out)

    def stop(self) -> dict[str, float]:
        """Stop counting; each stage's CPU seconds, the rasteriser's included."""
        self.sample_threads()
        self.on = False
        out = self.totals()
        if self._raster_ns > 0:
            out["rasteriser"] = self._raster_ns / 1e9
        return out

    def totals(self) -> dict[str, float]:
        """Each stage's CPU seconds so far (all threads)."""
        out: defaultdict[str, float] = defaultdict(float)
        with self._lock:
            tables = list(self._tables)
        for _, table, _ in tables:
            for name, ns in list(table.items()):
                out[name] += ns / 1e9
        return dict(out)

    def stage(self, name: str) -> contextlib.AbstractContextManager[None]:
        """Charge the block's CPU time to ``name`` when counting: its own time only — a stage
        entered within it is charged to that stage, not to both. (Not counting: a context
        that does nothing, for a fraction of a microsecond.)"""
        return self._counted(name) if self.on else _NOTHING

    def call(self, name: str, fn, *args):
        """``fn(*args)`` (its result), its CPU time charged to ``name`` when counting."""
        if not self.on:
            return fn(*args)
        with self._counted(name):
            return fn(*args)

    @contextlib.contextmanager
    def _counted(self, name: str) -> Iterator[None]:
        table, stack = self._thread_state()
        now = time.thread_time_ns()
        if stack:  # the enclosing stage stops counting here
            table[stack[-1][0]] += now - stack[-1][1]
        stack.append([name, now])
        try:
            yield
        finally:
            now = time.thread_time_ns()
            inner, since = stack.pop()
            table[inner] += now - since
            if stack:
                stack[-1][1] = now

    def _thread_state(self) -> tuple[defaultdict[str, int], list[list]]:
        local = self._local
        if getattr(local, "table", None) is None:
            local.table, local.stack = defaultdict(int), []
            thread = threading.current_thread()
            name = thread.name.rsplit("_", 1)[0]  # (a pool's threads: render_0 → render)
            with self._lock:
                self._tables.append((name, local.table, thread))
        return local.table, local.stack


#: the process's stages
STAGES = Stages()
_NOTHING = contextlib.nullcontext()


def _threads_cpu_ns() -> dict[int, tuple[str, int]]:
    """Each live Python thread's CPU time so far: id → (name, a pool's without its number).

    Read from ``/proc`` by the thread's kernel id, never through ``pthread_getcpuclockid``:
    a thread may end between listing it and asking, and asking for a thread that has ended
    reads freed memory (it crashed ``autopilot run --stages`` with SIGSEGV as its pools shut
    down); a thread gone from ``/proc`` is simply not counted. Linux only (elsewhere: none)."""
    if not sys.platform.startswith("linux"):
        return {}
    out = {}
    for thread in threading.enumerate():
        tid = thread.native_id
        if tid is None or thread.ident is None:
            continue
        ns = _task_cpu_ns(tid)
        if ns is not None:
            out[thread.ident] = (thread.name.rsplit("_", 1)[0] if thread.name[-1:].isdigit()
                                 else thread.name, ns)
    return out


def _task_stat(tid: int | str) -> tuple[str, list[str]] | None:
    """A thread's name and the fields after it in ``/proc/self/task/TID/stat`` (None: gone)."""
    try:
        with open(f"/proc/self/task/{tid}/stat") as f:
            stat = f.read()
    except OSError:
        return None
    return stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()


def _ticks_ns(fields: list[str]) -> int:
    """utime + stime (clock ticks) in nanoseconds."""
    return (int(fields[11]) + int(fields[12])) * 1_000_000_000 // os.sysconf("SC_CLK_TCK")


def _task_cpu_ns(tid: int | str) -> int | None:
    """A thread's CPU time: the scheduler's nanosecond count (``/proc/…/sched``, kernels with
    scheduler debugging, most) or else ``stat``'s clock ticks (10 ms); None: gone."""
    try:
        with open(f"/proc/self/task/{tid}/sched") as f:
            for line in f:
                if line.startswith("se.sum_exec_runtime"):
                    return round(float(line.split(":", 1)[1]) * 1e6)  # (ms)
    except (OSError, ValueError):
        pass
    found = _task_stat(tid)
    return None if found is None else _ticks_ns(found[1])


def _tasks_waiting_ns() -> dict[str, int]:
    """Each of the process's tasks' run-queue wait so far (``/proc/self/task/TID/schedstat``,
    its second field; Linux with scheduler statistics, else none)."""
    if not sys.platform.startswith("linux"):
        return {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return {}
    out = {}
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[1])
        except (OSError, ValueError, IndexError):
            continue
    return out


def rasteriser_cpu_ns() -> int:
    """CPU time of Mesa's llvmpipe threads so far (Linux: /proc; 0 where it cannot be read)."""
    if not sys.platform.startswith("linux"):
        return 0
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return 0
    total = 0
    for tid in tids:
        found = _task_stat(tid)
        if found is not None and found[0].startswith("llvmpipe"):
            total += _task_cpu_ns(tid) or 0
    return total
