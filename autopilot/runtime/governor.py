"""Perception yields to control when the event loop runs late (real time only).

On a busy machine the kernel gives the autopilot's process a share of a core, whatever its
threads' priorities: background threads at a lower nice only split that share with the event
loop's thread. When perception and the console want more than the share leaves after control,
the loop's timers fire late (control ticks late) however low their threads run. So the runtime
sheds work itself before the kernel does it for control: the watchdog's beat measures how late
the loop answers, and while it is late, perception takes only a fraction of the frames (the
others are skipped before any work is done on them), growing back when the loop is on time
(additive increase, multiplicative decrease, as TCP's congestion control).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class GovernorSettings:
    late_s: float = 0.008  # a beat this late: take fewer frames
    on_time_s: float = 0.003  # a beat this early: take more
    decrease: float = 0.75  # the share kept after a late beat
    increase: float = 0.04  # the share added after an on-time beat
    min_share: float = 0.15  # never fewer frames than this (perception must still see)


class LoadGovernor:
    @classmethod
    def from_config(cls, cfg) -> LoadGovernor | None:
        """From ``runtime.yield_to_control`` (None when it is off)."""
        if not cfg.enabled:
            return None
        return cls(GovernorSettings(cfg.late_ms / 1e3, cfg.on_time_ms / 1e3,
                                    min_share=cfg.min_share))

    def __init__(self, settings: GovernorSettings = GovernorSettings()) -> None:
        self.settings = settings
        self.share = 1.0
        self._credit: dict[str, float] = {}
        self.skipped: dict[str, int] = {}
        self.lowest_share = 1.0
        self.late_beats = 0

    def observe_lag(self, lag_s: float) -> None:
        s = self.settings
        if lag_s >= s.late_s:
            self.share = max(s.min_share, self.share * s.decrease)
            self.lowest_share = min(self.lowest_share, self.share)
            self.late_beats += 1
        elif lag_s <= s.on_time_s:
            self.share = min(1.0, self.share + s.increase)

    def take(self, lane: str) -> bool:
        """Take this frame of ``lane``? (An even spread: a share of 0.5 takes every other.)"""
        credit = self._credit.get(lane, 1.0) + self.share
        if credit >= 1.0:
            self._credit[lane] = credit - 1.0
            return True
        self._credit[lane] = credit
        self.skipped[lane] = self.skipped.get(lane, 0) + 1
        return False
