"""Perception yields to control when the event loop runs late (real time only).

On a busy machine the kernel gives the autopilot's process a share of a core, whatever its
threads' priorities: background threads at a lower nice only split that share with the event
loop's thread. When perception and the console want more than the share leaves after control,
the loop's timers fire late (control ticks late) however low their threads run. So the runtime
sheds work itself before the kernel does it for control: the watchdog's beat measures how late
the loop answers, and while it is late, fewer frames are taken (the others are skipped before
any work is done on them), growing back when the loop is on time (additive increase,
multiplicative decrease, as TCP's congestion control).

Who yields first: the console's viewers. One level (``share``, 1 on time) sets every lane's
share of frames: a viewer lane (``console:<camera>``) takes ``2·share − 1`` of its frames (down
to ``viewer_min_share``), so the operator's picture thins out first; perception's lanes take
``2·share`` (down to ``min_share``), so the flight's own detections are shed only once the
viewers are at their floor and the loop is still late.
"""

from __future__ import annotations

from dataclasses import dataclass

#: lanes of this prefix are viewers (the console's video), which yield before perception
VIEWER_PREFIX = "console:"


@dataclass(frozen=True, slots=True)
class GovernorSettings:
    late_s: float = 0.008  # a beat this late: take fewer frames
    on_time_s: float = 0.003  # a beat this early: take more
    decrease: float = 0.75  # the level kept after a late beat
    increase: float = 0.04  # the level added after an on-time beat
    min_share: float = 0.15  # perception never takes fewer frames than this (it must still see)
    viewer_min_share: float = 0.1  # nor the console's viewers (a picture every few frames)


class LoadGovernor:
    @classmethod
    def from_config(cls, cfg) -> LoadGovernor | None:
        """From ``runtime.yield_to_control`` (None when it is off)."""
        if not cfg.enabled:
            return None
        return cls(GovernorSettings(cfg.late_ms / 1e3, cfg.on_time_ms / 1e3,
                                    min_share=cfg.min_share,
                                    viewer_min_share=cfg.viewer_min_share))

    def __init__(self, settings: GovernorSettings = GovernorSettings()) -> None:
        self.settings = settings
        #: the level every lane's share follows (1: every frame)
        self.share = 1.0
        #: below this the level changes nothing more (perception at its floor)
        self._floor = settings.min_share / 2
        self._credit: dict[str, float] = {}
        self.skipped: dict[str, int] = {}
        #: the lowest share of frames perception's lanes were asked to take
        self.lowest_share = 1.0
        self.late_beats = 0

    def observe_lag(self, lag_s: float) -> None:
        s = self.settings
        if lag_s >= s.late_s:
            self.share = max(self._floor, self.share * s.decrease)
            self.lowest_share = min(self.lowest_share, self._perception_share())
            self.late_beats += 1
        elif lag_s <= s.on_time_s:
            self.share = min(1.0, self.share + s.increase)

    def lane_share(self, lane: str) -> float:
        """The share of ``lane``'s frames taken at the present level."""
        if lane.startswith(VIEWER_PREFIX):
            return max(self.settings.viewer_min_share, 2.0 * self.share - 1.0)
        return self._perception_share()

    def _perception_share(self) -> float:
        return max(self.settings.min_share, min(1.0, 2.0 * self.share))

    def take(self, lane: str) -> bool:
        """Take this frame of ``lane``? (An even spread: a share of 0.5 takes every other.)"""
        credit = self._credit.get(lane, 1.0) + self.lane_share(lane)
        if credit >= 1.0:
            self._credit[lane] = credit - 1.0
            return True
        self._credit[lane] = credit
        self.skipped[lane] = self.skipped.get(lane, 0) + 1
        return False
