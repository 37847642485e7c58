"""The simulator's AUTO.PRECLAND on its lockstep clock: the landing target lost during the
descent sends it back to the start, then climbing to search; seen again, it approaches and
lands on it (PX4's precland.cpp states, PLD_* parameters)."""

from __future__ import annotations

import asyncio
import contextlib

import numpy as np

from autopilot.flight_ops import wait_for_state
from drivers.base import FlightMode, LandingTarget

from .simtools import run, simulator, take_off


def test_lost_during_the_descent_then_searched_for_and_landed_on(no_camera_config):
    config = no_camera_config.model_copy(update={"params": {
        "PLD_SRCH_ALT": 6.0, "PLD_SRCH_TOUT": 20.0, "PLD_BTOUT": 1.0}})
    target = (3.0, 2.0, 0.0)

    async def main():
        async with simulator(config) as sim:
            texts: list[str] = []

            async def listen():
                async with contextlib.aclosing(sim.events(buffer=256)) as events:
                    async for _, text in events:
                        texts.append(text)

            listener = asyncio.ensure_future(listen())
            seen = True

            async def stream():
                while True:
                    if seen:
                        await sim.send_landing_target(LandingTarget(sim.clock.now(), target))
                    await sim.clock.sleep(0.05)

            streamer = asyncio.ensure_future(stream())
            try:
                await take_off(sim, 4.0)
                await sim.precision_land()
                await wait_for_state(sim, lambda s: s.mode is FlightMode.PRECLAND, 2.0,
                                     "PRECLAND")
                # over the target and descending; then it is lost at 2.5 m
                await wait_for_state(sim, lambda s: s.altitude_m < 2.5 and np.hypot(
                    s.position_ned_m[0] - target[0], s.position_ned_m[1] - target[1]) < 0.3,
                    40.0, "descending over the target")
                seen = False
                await wait_for_state(sim, lambda s: s.altitude_m > 5.0, 30.0,
                                     "climbing to PLD_SRCH_ALT")
                seen = True
                await wait_for_state(sim, lambda s: not s.armed, 90.0, "landed, disarmed")
                rest = sim.latest_state.position_ned_m
                assert np.hypot(rest[0] - target[0], rest[1] - target[1]) < 0.1
                for text in ("Lost landing target while landing (descending).",
                             "Climbing to search altitude."):
                    assert text in texts
                assert "Falling back to normal land." not in texts
            finally:
                streamer.cancel()
                listener.cancel()

    run(main())
