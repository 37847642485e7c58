"""The simulated AR.Drone 2.0 on a running simulator (a :class:`~drivers.sim.driver.SimDriver`
whose firmware is ``ardrone``), between its protocol engine and whatever carries the bytes —
the drone's sockets (:mod:`autopilot.ardrone_server`) or the in-process link
(:mod:`drivers.sim.ardrone_driver`): AT datagrams are decoded
(:class:`~drivers.sim.ardrone_face.ArdroneFace`) and their commands run on the simulator in
order, between physics batches; a navdata packet is built for each telemetry sample, the
simulator's telemetry at the rate the navdata mode asks (15 Hz demo, 200 Hz full).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from drivers.ardrone.config import DroneConfig
from drivers.base import VehicleError
from drivers.sim.ardrone_face import ArdroneFace
from drivers.sim.driver import SimDriver
from drivers.sim.flight.commander import CommandRejected


class SimulatedArdrone:
    def __init__(self, vehicle: SimDriver) -> None:
        self.vehicle = vehicle
        sim = vehicle.simulator
        self._pending: list[tuple] = []
        self.face = ArdroneFace(command=lambda *c: self._pending.append(c),
                                limits=sim.flight.limits, config=DroneConfig())
        self.face.apply_all()
        self._rate_hz = self.face.navdata_rate_hz
        sim.set_telemetry_rate(self._rate_hz)
        self._batches: asyncio.Queue = asyncio.Queue()
        self._task: asyncio.Task | None = None
        #: commands the firmware refused (as the drone ignores them)
        self.rejected = 0

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run(), name="ardrone-commands")

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    def take(self, datagram: bytes) -> None:
        """One AT datagram received: its commands run next, in order."""
        self.face.on_datagram(datagram)
        rate = self.face.navdata_rate_hz
        changed = rate != self._rate_hz
        if self._pending or changed:
            self._rate_hz = rate
            self._batches.put_nowait((tuple(self._pending), rate if changed else None))
            self._pending.clear()

    async def _run(self) -> None:
        runner, sim = self.vehicle.runner, self.vehicle.simulator

        def run(batch, rate_hz: float | None) -> int:
            refused = 0
            if rate_hz is not None:
                sim.set_telemetry_rate(rate_hz)
            for name, *args in batch:
                try:
                    sim.command(name, *args)
                except CommandRejected:
                    refused += 1
            return refused

        while True:
            batch, rate_hz = await self._batches.get()
            try:
                self.rejected += await runner.call(run, batch, rate_hz)
            except VehicleError:
                return

    async def navdata(self) -> AsyncIterator[bytes]:
        """A navdata packet per telemetry sample, as the drone sends it (each one: samples
        delivered together — 200 Hz full navdata on a batch of physics — are not dropped)."""
        vehicle, firmware = self.vehicle, self.vehicle.simulator.flight
        async with contextlib.aclosing(vehicle.telemetry(buffer=64)) as states:
            async for state in states:
                status = await vehicle.runner.call(firmware.status)
                yield self.face.navdata(state, status)
