"""Helpers for tests of the simulator's MAVLink face and the MAVLink drivers (real time)."""

from __future__ import annotations

import asyncio
import contextlib

from drivers.mavlink.face import MavlinkFace
from drivers.sim.driver import SimDriver

INSTANCE = 7  # ports 14587 / 18577 and client port 14547: clear of a running SITL
CLIENT_URL = f"udpin://127.0.0.1:{14540 + INSTANCE}"

#: the simulator's link_loss fault for an external client's test (from the arming on): 10 % of
#: the datagrams lost each way, some duplicated, reordered and late
LOSSY_LINK = [{"kind": "link_loss", "fraction": 0.1, "duplicate": 0.05, "reorder": 0.05,
               "latency_s": 0.03}]


@contextlib.asynccontextmanager
async def served(config, scenario=(), face_class=MavlinkFace, **kwargs):
    """The simulator in real time behind its MAVLink face (instance :data:`INSTANCE`; PX4's,
    or ``face_class``)."""
    vehicle = SimDriver(config, scenario=scenario, lockstep=False)
    await vehicle.connect()
    face = face_class(vehicle, instance=INSTANCE, gcs_port=14557 + INSTANCE,
                       events=vehicle.events(), **kwargs)
    try:
        await face.start()
        yield vehicle, face
    finally:
        await face.close()
        await vehicle.close()


@contextlib.asynccontextmanager
async def collected(stream):
    """Every item of the async iterator ``stream`` (a driver's telemetry, its status texts),
    appended to the list this yields while the block runs; the stream is closed after."""
    items: list = []

    async def collect() -> None:
        async with contextlib.aclosing(stream) as source:
            async for item in source:
                items.append(item)

    task = asyncio.ensure_future(collect())
    try:
        yield items
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
