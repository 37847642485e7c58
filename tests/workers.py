"""The test run's workers (pytest-xdist, ``-n 2`` in pyproject.toml): the tests that fly the
simulator behind its MAVLink face, or listen on a fixed port, take theirs from the worker they
run on, so that two workers never bind the same port.

Worker 0 (and a run without xdist) keeps the ports the tests were written with (SITL instance
7–11 and its neighbours); worker 1 takes them 220 higher (instances 227–231: MAV_SYS_ID stays
below 256, and clear of the instances 20–199 that ``autopilot bench load`` draws from)."""

from __future__ import annotations

import os

_OFFSETS = (0, 220)


def _worker_index() -> int:
    name = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(name.removeprefix("gw") or 0)
    if index >= len(_OFFSETS):
        raise RuntimeError(f"xdist worker {name}: the tests' fixed ports allow {len(_OFFSETS)} "
                           "workers (-n 2)")
    return index


#: added to every fixed port and simulator instance a test uses
PORT_OFFSET = _OFFSETS[_worker_index()]
