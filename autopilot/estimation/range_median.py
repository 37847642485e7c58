"""A rangefinder's readings with their outliers voted out.

A single-beam lidar now and then reads its maximum range (a missed return) or something short
of the ground (dust, debris, a blade in the beam), and loses the surface for a reading or two.
A landing that took one such reading at its word would commit or touch down too early, or
climb. The newest reading is taken when it agrees with the few before it, each carried
forward to now by the vehicle's vertical velocity (so a steady descent costs no lag), by their
median (a minority of outliers among them cannot move it); otherwise that median stands in
for it. A real step (flying over a deck's edge) is followed once the readings after it
outvote those before. When most recent readings are missing, there is no height (the callers
then fall back on their estimate's).
"""

from __future__ import annotations

import math
from collections import deque
from statistics import median


class RangeMedian:
    """The newest of the last ``count`` new readings no older than ``window_s``, checked
    against the others (the newest alone while fewer than three are that recent)."""

    def __init__(self, count: int = 9, window_s: float = 0.5, tolerance_m: float = 0.1,
                 tolerance_fraction: float = 0.02) -> None:
        self.window_s = window_s
        self.tolerance_m = tolerance_m
        self.tolerance_fraction = tolerance_fraction
        self._readings: deque[tuple[float, float]] = deque(maxlen=count)
        self._last = math.nan

    def add(self, time_s: float, reading_m: float, down_velocity_m_s: float = 0.0) -> float:
        """Add a reading (telemetry repeats a reading until the next: repeats are one) and
        return the height to use at ``time_s`` (NaN: none); ``down_velocity_m_s``: the
        vehicle's (NED z), which shortens the range as it descends."""
        if reading_m != self._last or math.isnan(reading_m):
            self._readings.append((time_s, reading_m))
        self._last = reading_m
        return self.value(time_s, down_velocity_m_s)

    def value(self, time_s: float, down_velocity_m_s: float = 0.0) -> float:
        recent = [(t, r) for t, r in self._readings if time_s - t <= self.window_s]
        if len(recent) < 3:  # too few to vote on (after a gap): the newest
            return recent[-1][1] if recent else math.nan
        finite = [(t, r) for t, r in recent if math.isfinite(r)]
        if 2 * len(finite) < len(recent):
            return math.nan
        v = down_velocity_m_s if math.isfinite(down_velocity_m_s) else 0.0
        newest_t, newest = recent[-1]
        predicted = max(median(r - v * (newest_t - t) for t, r in finite if t < newest_t)
                        if len(finite) > 1 else newest, 0.0)
        tolerance = self.tolerance_m + self.tolerance_fraction * predicted
        if math.isfinite(newest) and abs(newest - predicted) <= tolerance:
            return newest
        return predicted
