"""A simulated vehicle's link under the ``link_loss`` fault, for the protocol faces that
serve it over a network (:mod:`drivers.mavlink.face`, :mod:`autopilot.ardrone_server`)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable


class LinkImpairment:
    """The simulator's ``link_loss`` fault (:mod:`drivers.sim.faults`) on a protocol face's
    datagrams (the MAVLink face's, the simulated AR.Drone's),
    both ways: lost (``fraction``), delivered twice (``duplicate``), held back behind later ones
    (``reorder``: 20–150 ms) and late (``latency_s``), drawn from the fault schedule's seeded
    generator."""

    def __init__(self, vehicle, stats) -> None:
        self.vehicle = vehicle
        self.stats = stats
        self._delayed: list[asyncio.TimerHandle] = []  # datagrams held back

    def fault(self):
        """The simulated vehicle's active ``link_loss`` fault (None: a clean link)."""
        try:
            sim = self.vehicle.simulator
        except Exception:  # not a simulator, or not connected
            return None
        faults = getattr(sim, "faults", None)
        if not faults or not faults.of("link_loss"):
            return None
        active = faults.active("link_loss", sim.fault_time_s())
        return active[0] if active else None

    def carry(self, fault, deliver: Callable[[], None]) -> None:
        """One datagram across the impaired link (``deliver`` it, or not, or twice, later)."""
        rng = self.vehicle.simulator.faults.link_rng
        if rng.random() < fault.fraction:
            self.stats.link_dropped += 1
            return
        delay = fault.latency_s
        if fault.reorder and rng.random() < fault.reorder:
            delay += float(rng.uniform(0.02, 0.15))
        copies = 2 if fault.duplicate and rng.random() < fault.duplicate else 1
        for _ in range(copies):
            if delay > 0.0:
                loop = asyncio.get_running_loop()
                if len(self._delayed) > 256:  # forget the ones delivered already
                    now = loop.time()
                    self._delayed = [h for h in self._delayed if h.when() > now]
                self._delayed.append(loop.call_later(delay, deliver))
            else:
                deliver()

    def close(self) -> None:
        for handle in self._delayed:
            handle.cancel()
        self._delayed = []
