"""Process-wide settings for the autopilot's hot loop."""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import sys

# glibc mallopt() parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def keep_large_buffers_in_heap(mmap_threshold_b: int = 16 << 20,
                               trim_threshold_b: int = 128 << 20) -> bool:
    """Stop glibc from giving every image-sized buffer its own fresh ``mmap``.

    A 640×480 frame, its HSV copy and each mask are 0.3–0.9 MB: above glibc's default mmap
    threshold, so each is mapped on allocation and unmapped on free, and every first touch of
    every 4 kB page is a page fault. That made OpenCV's colour conversion and morphology on a
    full frame twice as slow as the arithmetic (2.7 ms instead of 1.3 ms here). With the
    thresholds raised, such buffers are recycled from the heap; the price is that up to
    ``trim_threshold_b`` of freed memory stays with the process. Returns whether it applied
    (glibc only; elsewhere nothing changes).
    """
    if not sys.platform.startswith("linux"):
        return False
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, mmap_threshold_b)
                    and libc.mallopt(_M_TRIM_THRESHOLD, trim_threshold_b))
    return False


def release_freed_memory() -> bool:
    """Give the heap a flight freed back to the system (glibc's ``malloc_trim``).

    With the thresholds above, what a flight's frames, masks and log buffers freed stays in the
    process's heap (about 100 MB after a mission with cameras): the next flight reuses it, but
    between flights, and in a companion computer's process that flies mission after mission, it
    is memory nobody uses. :func:`autopilot.run.fly` calls this when a flight is over. Returns
    whether it applied (glibc only).
    """
    if not sys.platform.startswith("linux"):
        return False
    with contextlib.suppress(OSError, AttributeError):
        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    return False


#: How long a thread running Python may keep the GIL while another waits for it.
GIL_SWITCH_INTERVAL_S = 0.001


def configure_for_flight() -> None:
    """Process settings for flying: image buffers kept in the heap (above), and a shorter GIL
    switch interval. Python lets a thread that is running Python code keep the GIL for 5 ms
    before handing it to a thread that wants it back (one returning from OpenCV, MuJoCo or a
    socket); with the simulator's flight stack, the detector and the event loop in one
    process, those waits land on the frame-to-setpoint path. 1 ms bounds them (measured on a
    2-core machine in real time: latency p95 36.6–37.9 ms instead of 36.3–40.1 ms). And a
    crash in native code (MuJoCo, OpenCV, MAVSDK's C++ core, FFmpeg) prints every thread's
    Python stack on stderr before the process dies (Python's faulthandler), so that a flight's
    output says where it died."""
    keep_large_buffers_in_heap()
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    if not faulthandler.is_enabled() and sys.stderr is not None:
        with contextlib.suppress(AttributeError, ValueError, OSError):  # (no real stderr)
            faulthandler.enable(all_threads=True)


class StealMeter:
    """Share of the machine's CPU time taken by the hypervisor (``steal`` in ``/proc/stat``)
    since this meter was made. On a shared virtual machine, speed and latency figures drop
    with steal, so benchmarks report it next to their numbers. None where there is no
    ``/proc/stat`` (not Linux)."""

    def __init__(self) -> None:
        self._start = _cpu_ticks()

    def percent(self) -> float | None:
        end = _cpu_ticks()
        if self._start is None or end is None or end[0] <= self._start[0]:
            return None
        return 100.0 * (end[1] - self._start[1]) / (end[0] - self._start[0])


def _cpu_ticks() -> tuple[int, int] | None:
    """(all CPU time, stolen time) in clock ticks, summed over the machine's CPUs."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            fields = f.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu" or len(fields) < 9:
        return None
    # user nice system idle iowait irq softirq steal [guest guest_nice: already in user/nice]
    ticks = [int(v) for v in fields[1:9]]
    return sum(ticks), ticks[7]
