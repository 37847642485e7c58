"""Delayed measurements fused at their capture time: the inputs and measurements of the last
``history_s`` are kept in time order with the filter's state after each; one that arrives
older than the newest is inserted where it belongs, the state is restored to just before it,
and it and everything after it are fused again (a UWB range 30 ms late, a rover report 150 ms
late). Older than the history, or than the oldest state kept: dropped.

The filter brings three callbacks: ``apply(event, late)`` fuses one (``late``: it arrived out
of order), ``snapshot()`` and ``restore(snapshot)`` save and set its state (``restore(None)``:
the state before anything)."""

from __future__ import annotations

import bisect
from collections.abc import Callable
from typing import Any, Protocol


class TimedEvent(Protocol):
    time_s: float


class DelayedFusion:
    def __init__(self, history_s: float, apply: Callable[[Any, bool], None],
                 snapshot: Callable[[], Any], restore: Callable[[Any], None]) -> None:
        self.history_s = history_s
        self._apply, self._snapshot, self._restore = apply, snapshot, restore
        self._events: list[TimedEvent] = []
        self._snapshots: list[Any] = []  # the state after each event
        self._base: Any = None  # the state before the first kept event
        #: fusing again what came after a late event (already counted and reported once)
        self.replaying = False

    def add(self, event: TimedEvent) -> bool:
        """Fuse ``event`` at its time; False when it is too old to be (dropped)."""
        events = self._events
        if not events or event.time_s >= events[-1].time_s:
            events.append(event)
            self._apply(event, False)
            self._snapshots.append(self._snapshot())
            self._trim()
            return True
        horizon = events[-1].time_s - self.history_s
        if event.time_s < horizon or (self._base is not None
                                      and event.time_s < self._base.time_s):
            return False
        i = bisect.bisect_right([e.time_s for e in events], event.time_s)
        events.insert(i, event)
        self._restore(self._snapshots[i - 1] if i > 0 else self._base)
        del self._snapshots[i:]
        for k in range(i, len(events)):
            self.replaying = k > i
            self._apply(events[k], k == i)
            self._snapshots.append(self._snapshot())
        self.replaying = False
        return True

    def _trim(self) -> None:
        horizon = self._events[-1].time_s - self.history_s
        n = 0
        while n < len(self._events) - 1 and self._events[n].time_s < horizon:
            n += 1
        if n:
            self._base = self._snapshots[n - 1]
            del self._events[:n]
            del self._snapshots[:n]
