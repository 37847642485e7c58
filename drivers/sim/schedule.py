"""Periodic captures on the physics step grid."""

from __future__ import annotations

import math

_EPS = 1e-9


class Schedule:
    """The k-th capture is the first physics step at or after k·period (in steps), so the
    average rate is exact and stamps are true step times."""

    def __init__(self, period_steps: float) -> None:
        self._period = period_steps
        self._origin = 0
        self._count = 0
        #: the step of the next capture
        self.next_step = 0

    @property
    def period_steps(self) -> float:
        return self._period

    def retime(self, period_steps: float, step: int) -> None:
        """A new period from ``step`` on: the next capture at ``step`` (or the one already due
        sooner), then one every ``period_steps``."""
        self._period = period_steps
        self._origin = min(step, self.next_step)
        self._count = 0
        self.next_step = self._origin

    def advance(self, step: int) -> None:
        """Past the capture at ``step``: to the first capture after it."""
        while self.next_step <= step:
            self._count += 1
            self.next_step = self._origin + math.ceil(self._count * self._period - _EPS)
