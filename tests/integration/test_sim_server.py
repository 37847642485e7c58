"""``autopilot sim``'s own lines (real time, loopback)."""

from __future__ import annotations

import asyncio

import pytest

from autopilot.config import load_config
from autopilot.sim_server import READY, serve

pytestmark = pytest.mark.serial  # 'autopilot sim' in real time

INSTANCE = 11  # ports clear of the other tests' simulators


def test_it_says_ready_for_takeoff_once_the_vehicle_is_armable():
    lines: list[str] = []

    async def main():
        stop = asyncio.Event()
        server = asyncio.ensure_future(serve(
            load_config(overrides=["vehicle.cameras.down.enabled=false"]), None,
            instance=INSTANCE, videos=None, log=lines.append, stop=stop))
        try:
            for _ in range(300):  # the simulator boots, its estimator converges
                if any(READY in line for line in lines):
                    break
                await asyncio.sleep(0.05)
            await asyncio.sleep(1.0)  # (and says it only once)
        finally:
            stop.set()
            await server

    asyncio.run(main())
    ready = [line for line in lines if READY in line]
    assert len(ready) == 1, lines
    # as the vehicle's other console lines: its boot time, then the wall clock
    boot_s, _, rest = ready[0].removeprefix("[").partition(" s | ")
    assert float(boot_s) >= 0.0
    assert rest.endswith(f"] {READY}")
