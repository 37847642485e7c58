"""The event loop's watchdog: how late the loop answers (its lag), and stalls.

A coroutine on the loop wakes every ``period_s`` (wall clock) and records how late it woke:
the loop's lag, which every other coroutine (setpoint streaming, telemetry, control) suffers
too. A thread watches that heartbeat: when the loop has not beaten for ``stall_s`` it logs the
stall *while it lasts*, with where the loop thread is stuck (its stack), since a loop that never
comes back can report nothing itself. When the loop comes back, ``on_stall(seconds)`` is called
on it.

What a stall does to the flight is by design the vehicle's: setpoints stop with the loop, and
PX4's offboard-loss failsafe (COM_OF_LOSS_T, then COM_OBL_RC_ACT) holds or lands. The runtime,
told of a stall longer than its setpoint expiry in real time, does not resume the step blindly:
the step fails into the mission's fallback.
"""

from __future__ import annotations

import asyncio
import logging
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable

import numpy as np

log = logging.getLogger(__name__)


class LoopWatchdog:
    def __init__(self, stall_s: float, on_stall: Callable[[float], None] | None = None, *,
                 period_s: float = 0.05, history: int = 72000, quiet: bool = False,
                 on_beat: Callable[[float], None] | None = None) -> None:
        self.stall_s = stall_s
        #: stalls logged at debug level only (lockstep: simulated time waits for the loop, so
        #: a stall costs the flight nothing)
        self._level = logging.DEBUG if quiet else logging.WARNING
        self.on_stall = on_stall
        self.on_beat = on_beat  # (each beat's lag, s)
        self.period_s = period_s
        #: the loop's lag at each beat (s), the newest ``history`` (an hour at 20 Hz)
        self.lags_s: deque[float] = deque(maxlen=history)
        self.stalls_s: list[float] = []
        self._beat = time.monotonic()
        self._loop_thread: int | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def lag_percentile_ms(self, q: float) -> float | None:
        if not self.lags_s:
            return None
        return float(np.percentile(np.fromiter(self.lags_s, float), q)) * 1e3

    async def run(self) -> None:
        """Beat until cancelled (and watch from a thread meanwhile)."""
        self._loop_thread = threading.get_ident()
        self._beat = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._watch, name="loop-watchdog", daemon=True)
        self._thread.start()
        try:
            while True:
                due = time.monotonic() + self.period_s
                await asyncio.sleep(self.period_s)
                now = time.monotonic()
                lag = max(now - due, 0.0)
                self.lags_s.append(lag)
                self._beat = now
                if self.on_beat is not None:
                    self.on_beat(lag)
                if lag >= self.stall_s:
                    self.stalls_s.append(lag)
                    log.log(self._level, "the event loop was stalled for %.2f s", lag)
                    if self.on_stall is not None:
                        self.on_stall(lag)
        finally:
            self._stop.set()
            self._thread.join(timeout=1.0)

    def _watch(self) -> None:
        reported = 0.0
        while not self._stop.wait(self.period_s):
            silent = time.monotonic() - self._beat - self.period_s
            if silent < self.stall_s:
                reported = 0.0
                continue
            if silent >= max(reported * 2.0, self.stall_s):  # at 1×, 2×, 4×, … the limit
                reported = silent
                frame = sys._current_frames().get(self._loop_thread)
                where = "".join(traceback.format_stack(frame, limit=6)) if frame else "?"
                log.log(self._level + 10, "the event loop has not answered for %.1f s "
                        "(setpoints stopped: the vehicle's offboard failsafe takes over); it is "
                        "at:\n%s", silent, where)
