"""``autopilot sim`` as a process of its own, for tests of external clients (real time)."""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence

import pytest

try:  # looked up here: between fork and exec, the child loads nothing
    _prctl = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # not Linux
    _prctl = None


def die_with_parent() -> None:
    """``preexec_fn`` for a test's child process: it gets SIGTERM when the test's process dies
    (Linux's PR_SET_PDEATHSIG), so a worker that crashes leaves no simulator or client running
    on the fixed ports the next tests use."""
    if _prctl is not None:
        _prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


@contextlib.contextmanager
def sim_process(args: Sequence[str], ready: str, timeout_s: float = 180.0
                ) -> Iterator[subprocess.Popen]:
    """``autopilot sim ARGS`` until the block ends; yields once a line of its output holds
    ``ready`` (the test fails with that output if it exits or never says so). Its output is
    read on to the end, so that a full pipe never stalls it."""
    proc = subprocess.Popen([sys.executable, "-m", "autopilot", "sim", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            preexec_fn=die_with_parent)
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if ready in line:
            break
    if proc.poll() is not None or not lines or ready not in lines[-1]:
        proc.kill()
        pytest.fail(f"autopilot sim {' '.join(args)} did not start: " + "".join(lines))
    threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()
    try:
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
