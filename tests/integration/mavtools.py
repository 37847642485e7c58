"""Helpers for tests of the simulator's MAVLink face and the MAVLink drivers (real time)."""

from __future__ import annotations

import contextlib

from drivers.mavlink.face import MavlinkFace
from drivers.sim.driver import SimDriver

INSTANCE = 7  # ports 14587 / 18577 and client port 14547: clear of a running SITL
CLIENT_URL = f"udpin://127.0.0.1:{14540 + INSTANCE}"


@contextlib.asynccontextmanager
async def served(config, scenario=(), **kwargs):
    """The simulator in real time behind its MAVLink face (instance :data:`INSTANCE`)."""
    vehicle = SimDriver(config, scenario=scenario, lockstep=False)
    await vehicle.connect()
    face = MavlinkFace(vehicle, instance=INSTANCE, gcs_port=14557 + INSTANCE,
                       events=vehicle.events(), **kwargs)
    try:
        await face.start()
        yield vehicle, face
    finally:
        await face.close()
        await vehicle.close()
