"""Real time on a machine that may be too slow or too busy for it: after each cycle of the
simulated vehicle (a batch of physics, and handing its outputs over), the clock is held back by
what the CPU lost, the real-time factor is measured, a low one is said, and rendering is shed
while behind (if asked). See :mod:`drivers.sim.driver` for what this means for the vehicle."""

from __future__ import annotations

import logging
import math
import time

from drivers.clock import PacedClock
from drivers.sim.simulator import Simulator

log = logging.getLogger(__name__)

#: below this share of real time (over :data:`PACE_WINDOW_S` of wall time) the simulator says so
SLOW_FACTOR = 0.9
#: the wall-clock window over which the real-time factor is measured
PACE_WINDOW_S = 2.0
#: once behind, rendering stays shed for at least this long (simulated seconds): shedding makes
#: the next batches fast, and frames flickering on and off every batch would help nobody
SHED_HOLD_S = 0.5
#: a world this far behind the wall clock catches up by itself; beyond it the clock is held back
CATCH_UP_S = 0.1


class Pacer:
    def __init__(self, clock: PacedClock, warn_every_s: float | None,
                 shed_rendering: bool) -> None:
        self.clock = clock
        #: say "simulator at 0.6× real time" once (None) or every this many seconds
        self.warn_every_s = warn_every_s
        #: skip rendering frames while the simulator cannot keep up
        self.shed_rendering = shed_rendering
        #: the newest real-time factor (simulated / wall seconds over PACE_WINDOW_S), and the
        #: lowest seen
        self.pace_factor = math.nan
        self.slowest_pace_factor = math.nan
        self._window: tuple[float, float] | None = None  # (wall, simulated) at its start
        self._warned_s = -math.inf
        self._shed_until_s = -math.inf

    def after_cycle(self, sim: Simulator, simulated_s: float, cycle_s: float) -> None:
        """After a cycle that simulated ``simulated_s`` in ``cycle_s`` of wall time. Not
        counted (``cycle_s`` leaves it out): a hand-over from the simulator's thread to the
        event loop so long that the event loop stalled, not the CPU being slow; that time is
        caught up, as a vehicle flies on while its autopilot stalls."""
        clock = self.clock
        lost = cycle_s - simulated_s
        behind = clock.now() - sim.time_s
        # a world a little behind catches up on the next batches, as it always did (a batch
        # that renders a frame may take longer than the 10 ms it simulates on any machine);
        # only what is beyond CATCH_UP_S is held back, and never behind the world's own time
        excess = behind - CATCH_UP_S
        if lost > 0.0 and excess > 0.0:
            clock.hold_back(min(lost, excess))
        # shed while the last measured real-time factor is low, not on one slow batch (a batch
        # that renders a frame may take longer than the 10 ms it simulates on any machine, and
        # the next ones make it up)
        if self.shed_rendering and self.pace_factor < SLOW_FACTOR:
            self._shed_until_s = sim.time_s + SHED_HOLD_S
        if self.shed_rendering:
            sim.captures.shed_rendering = sim.time_s < self._shed_until_s
        self._measure(sim, time.perf_counter())

    def _measure(self, sim: Simulator, wall: float) -> None:
        if self._window is None:
            self._window = (wall, sim.time_s)
            return
        wall0, sim0 = self._window
        if wall - wall0 < PACE_WINDOW_S:
            return
        self._window = (wall, sim.time_s)
        self.pace_factor = factor = (sim.time_s - sim0) / (wall - wall0)
        if not factor >= self.slowest_pace_factor:
            self.slowest_pace_factor = factor
        if factor >= SLOW_FACTOR:
            return
        if self.warn_every_s is None:
            if self._warned_s > -math.inf:
                return
            log.warning("simulator at %.1f× real time: this machine cannot run it in real time "
                        "now; the simulated world (its clock, telemetry and frames) slows down "
                        "with it", factor)
        elif wall - self._warned_s >= self.warn_every_s:
            shed = sum(cam.shed for cam in sim.cameras.values())
            log.warning("simulator at %.1f× real time: the vehicle's clock lags the wall clock "
                        "by %.1f s in all (no real flight controller's does)%s", factor,
                        self.clock.held_back_s,
                        f"; {shed} frames not rendered to keep up" if self.shed_rendering
                        else "")
        else:
            return
        self._warned_s = wall
