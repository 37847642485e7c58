"""A rangefinder's readings with their outliers voted out.

A single-beam lidar now and then reads its maximum range (a missed return) or something short
of the ground (dust, debris, a blade in the beam), and loses the surface for a reading or two.
A landing that took one such reading at its word would commit or touch down too early, or
climb. The median of the last few new readings ignores a lone outlier at the cost of a
couple of readings' lag (40 ms at 50 Hz); when most recent readings are missing, there is no
height (the callers then fall back on their estimate's).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np


class RangeMedian:
    """The median of the last ``count`` new readings no older than ``window_s``."""

    def __init__(self, count: int = 5, window_s: float = 0.5) -> None:
        self.window_s = window_s
        self._readings: deque[tuple[float, float]] = deque(maxlen=count)
        self._last = math.nan

    def add(self, time_s: float, reading_m: float) -> float:
        """Add a reading (telemetry repeats a reading until the next: repeats are one) and
        return the median at ``time_s``."""
        if reading_m != self._last or math.isnan(reading_m):
            self._readings.append((time_s, reading_m))
        self._last = reading_m
        return self.value(time_s)

    def value(self, time_s: float) -> float:
        recent = [r for t, r in self._readings if time_s - t <= self.window_s]
        finite = [r for r in recent if math.isfinite(r)]
        if not finite or 2 * len(finite) < len(recent):
            return math.nan
        return float(np.median(finite))
