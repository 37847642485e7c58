"""Background threads yield to the control path when the CPU is short.

Video decoding, detection, the flight log's and the console's encoding and photo writing can
shed work (frames are taken from latest-value slots); telemetry, control and setpoints, on the
event loop's thread, cannot. When other processes leave the autopilot less CPU than it wants,
the kernel shares it out by weight: each background thread lowers its own priority (Linux
gives each thread its own nice value) so that the event loop's thread keeps its rate while
perception sheds frames, as PX4 runs its controllers above its loggers. Elsewhere (no
per-thread priority) this does nothing.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading

#: how much lower than the event loop's thread background threads run (0: as high);
#: ``runtime.background_nice`` sets it for a run
_background_nice = 10


def set_background_nice(nice: int) -> None:
    global _background_nice
    _background_nice = max(0, min(19, int(nice)))


def lower_this_thread() -> None:
    """Lower the calling thread's priority by the background nice (once per thread; a
    ThreadPoolExecutor's ``initializer``)."""
    if not _background_nice or not sys.platform.startswith("linux"):
        return  # elsewhere a thread id is no process id: the call would renice the process
    with contextlib.suppress(OSError, OverflowError, ValueError):  # not permitted: run as is
        tid = threading.get_native_id()
        now = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, now + _background_nice))
