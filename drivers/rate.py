"""Taking a stream's samples at a lower rate."""

from __future__ import annotations

import math


class RateSampler:
    """Which samples of a stream to take: ``rate_hz`` per second on average, evenly spread;
    every sample when the rate is at or above the stream's (``source_rate_hz``: half a
    source period of slack; 0 when it is not known). A clock that went back by more than two
    periods (a new run's) starts the sampling over."""

    def __init__(self, rate_hz: float, source_rate_hz: float = 0.0) -> None:
        self._period_s = 1.0 / rate_hz if rate_hz > 0 else math.inf
        self._slack_s = 0.5 / source_rate_hz if source_rate_hz > 0 else 0.0
        self._due_s = -math.inf

    def take(self, time_s: float) -> bool:
        if math.isinf(self._period_s):
            return False
        if time_s < self._due_s - self._slack_s:
            if time_s >= self._due_s - 2.0 * self._period_s:
                return False
            self._due_s = -math.inf  # (the clock went back)
        # the next one is due a period after this one was due (the rate holds on average);
        # after a gap (or at the start), a period after this one
        due = self._due_s + self._period_s
        self._due_s = due if due >= time_s else time_s + self._period_s
        return True
