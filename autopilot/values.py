"""Debug values: seed 000's ``name::value`` panel. Any part of the autopilot — a behaviour, a
pipeline, a controller, a user's own code — publishes a named value, and the console shows the
newest of each (``tgt.x::10``)::

    from autopilot import values
    values.publish("follow.range_m", 2.03)
    values.publish("tgt.x", 10, unit="px")

There is one board per process, as there is one logging tree: publishing is a dictionary
write under a lock (safe from executor threads, never blocking the control loop), and a
publisher needs no handle on the runtime. The runtime clears the board when a run starts and
when it ends, and publishes its own values (status, mode, battery, altitude, detection score).
Values are numbers, booleans or short strings; anything else is shown as its ``str``.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

MAX_VALUES = 500  # names kept; more are refused (a runaway publisher cannot eat the memory)
MAX_TEXT = 80


@dataclass(frozen=True, slots=True)
class Value:
    name: str
    value: float | int | bool | str
    unit: str
    time_s: float  # time.monotonic() when published


class ValueBoard:
    def __init__(self) -> None:
        self._values: dict[str, Value] = {}
        self._lock = threading.Lock()
        self.refused = 0

    def publish(self, name: str, value: object, unit: str = "") -> None:
        if isinstance(value, bool | int | str):
            shown = value if not isinstance(value, str) else value[:MAX_TEXT]
        elif isinstance(value, float):
            shown = value if math.isfinite(value) else str(value)
        else:
            try:
                shown = float(value)  # numpy scalars
                if not math.isfinite(shown):
                    shown = str(shown)
            except (TypeError, ValueError):
                shown = str(value)[:MAX_TEXT]
        item = Value(str(name)[:MAX_TEXT], shown, unit, time.monotonic())
        with self._lock:
            if item.name not in self._values and len(self._values) >= MAX_VALUES:
                self.refused += 1
                return
            self._values[item.name] = item

    def remove(self, prefix: str) -> None:
        """Forget every value whose name starts with ``prefix``."""
        with self._lock:
            for name in [n for n in self._values if n.startswith(prefix)]:
                del self._values[name]

    def snapshot(self) -> dict[str, Value]:
        with self._lock:
            return dict(self._values)

    def clear(self) -> None:
        with self._lock:
            self._values.clear()


_board = ValueBoard()


def board() -> ValueBoard:
    """The process's value board."""
    return _board


def publish(name: str, value: object, unit: str = "") -> None:
    """Show ``name::value`` on the console's panel (the newest value of each name)."""
    _board.publish(name, value, unit)
