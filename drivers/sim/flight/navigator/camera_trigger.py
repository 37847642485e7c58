"""Camera triggering (PX4's ``camera_trigger``): one photo, photos every interval
(IMAGE_START_CAPTURE, DO_SET_CAM_TRIGG_INTERVAL) or every distance travelled
(DO_SET_CAM_TRIGG_DIST), whatever the mode (a survey flown in OFFBOARD triggers too); each
becomes a ``photo`` :class:`~drivers.sim.flight.navigator.context.NavEvent`."""

from __future__ import annotations

import math

import numpy as np

from drivers.sim.flight.navigator.context import Estimate, NavContext, or_default


class CameraTrigger:
    def __init__(self, ctx: NavContext) -> None:
        self.ctx = ctx
        self._index = 0
        self._interval_s = 0.0
        self._next_s = math.inf
        self._left = 0  # 0: unlimited while the interval runs
        self._distance_m = 0.0
        self._since_photo_m = 0.0
        self._last_xy: np.ndarray | None = None

    def take_photo(self) -> None:
        self.ctx.emit("photo", self._index)
        self._index += 1
        self._since_photo_m = 0.0

    def stop(self) -> None:
        self._interval_s, self._next_s, self._left = 0.0, math.inf, 0

    def start(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE: one photo (count 1 or no interval), or one every
        ``interval_s`` (``count`` of them; 0: until stopped; negative: stop)."""
        if count < 0:
            self.stop()
            return
        interval = or_default(interval_s, 0.0)
        if count == 1 or interval <= 0:
            self.take_photo()
            return
        self.take_photo()
        self._interval_s = interval
        self._next_s = self.ctx.now + interval
        self._left = count - 1 if count > 0 else 0
        if count > 0 and self._left == 0:
            self._next_s = math.inf

    def set_distance(self, distance_m: float, trigger_now: bool = False) -> None:
        """DO_SET_CAM_TRIGG_DIST: a photo every ``distance_m`` travelled (0: stop)."""
        self._distance_m = max(0.0, or_default(distance_m, 0.0))
        self._since_photo_m = 0.0
        if trigger_now and self._distance_m > 0:
            self.take_photo()

    def tick(self, now: float, est: Estimate) -> None:
        xy = est.position_ned_m[:2]
        if self._last_xy is not None and self._distance_m > 0:
            self._since_photo_m += float(np.hypot(*(xy - self._last_xy)))
            if self._since_photo_m >= self._distance_m:
                self.take_photo()
        self._last_xy = np.array(xy, dtype=float)
        if now >= self._next_s:
            self.take_photo()
            if self._left > 0:
                self._left -= 1
                if self._left == 0:
                    self._next_s = math.inf
                    return
            self._next_s += self._interval_s
