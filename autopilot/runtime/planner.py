"""The planning worker: in real time, goto, orbit and survey paths are planned in a worker
process (the vehicle holds meanwhile; a process, so that no plan holds the event loop's
interpreter). In lockstep a step plans at once (the same plan at the same simulated moment)."""

from __future__ import annotations

import contextlib
import multiprocessing
import sys
from concurrent.futures import Future, ProcessPoolExecutor

from drivers.threads import lower_this_thread


@contextlib.contextmanager
def program_hidden():
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


def warm_planner() -> None:
    """The planning worker's first job: the planners imported before the first plan."""
    import autopilot.behaviors.trajectory
    import autopilot.steps  # noqa: F401


class PlanningWorker:
    """One worker process, started with the first job (or :meth:`warm`, as the run starts:
    a process takes a second or two to start)."""

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None

    def submit(self, job) -> Future:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                initializer=lower_this_thread)
            with program_hidden():  # (its worker starts with this first job)
                return self._pool.submit(job)
        return self._pool.submit(job)

    def warm(self) -> None:
        self.submit(warm_planner)

    def close(self) -> None:
        """A plan still being made ends within a second."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
