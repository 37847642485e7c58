"""The simulated AR.Drone 2.0 on a running simulator (a :class:`~drivers.sim.driver.SimDriver`
whose firmware is ``ardrone``), between its protocol engine and whatever carries the bytes —
the drone's sockets (:mod:`autopilot.ardrone_server`) or the in-process link
(:mod:`drivers.sim.ardrone_driver`): AT datagrams are decoded
(:class:`~drivers.sim.ardrone_face.ArdroneFace`) and their commands run on the simulator in
order, between physics batches; a navdata packet is built for each telemetry sample.
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
        if self._pending:
            self._batches.put_nowait(tuple(self._pending))
            self._pending.clear()

    async def _run(self) -> None:
        runner, sim = self.vehicle.runner, self.vehicle.simulator

        def run(batch) -> int:
            refused = 0
            for name, *args in batch:
                try:
                    sim.command(name, *args)
                except CommandRejected:
                    refused += 1
            return refused

        while True:
            batch = await self._batches.get()
            try:
                self.rejected += await runner.call(run, batch)
            except VehicleError:
                return

    async def navdata(self) -> AsyncIterator[bytes]:
        """A navdata packet per telemetry sample, as the drone sends it."""
        vehicle, firmware = self.vehicle, self.vehicle.simulator.flight
        async with contextlib.aclosing(vehicle.telemetry()) as states:
            async for state in states:
                status = await vehicle.runner.call(firmware.status)
                yield self.face.navdata(state, status)
