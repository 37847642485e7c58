"""A lockstep run is a pure function of its seed."""

import asyncio
import contextlib
import hashlib

import numpy as np

from drivers.base import Setpoint

from ..conftest import sim_with
from .simtools import Offboard, run, simulator, take_off


def _flight(sim_config, seed):
    async def main():
        async with simulator(sim_config, seed=seed) as drv:
            log = []

            async def watch():
                async with contextlib.aclosing(drv.telemetry(buffer=64)) as stream:
                    async for s in stream:
                        log.append((s.time_s, *s.position_ned_m, *s.attitude_q,
                                    s.distance_to_ground_m, s.battery.voltage_v))

            watcher = asyncio.ensure_future(watch())
            frames = []
            async with contextlib.aclosing(drv.frames("down")) as stream:
                async for frame in stream:
                    frames.append(hashlib.sha1(frame.image.tobytes()).hexdigest())
                    if len(frames) == 5:
                        break
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            offboard.setpoint = Setpoint.position(*(here + np.array([1.5, -1.0, -0.5])))
            await drv.clock.sleep(3.0)
            await offboard.aclose()
            watcher.cancel()
            return np.array(log), frames

    return run(main())


def test_same_seed_same_flight_different_seed_different(sim_config):
    cfg = sim_with(sim_config, **{"wind.gust_mps": 1.0})
    log_a, frames_a = _flight(cfg, 7)
    log_b, frames_b = _flight(cfg, 7)
    log_c, _ = _flight(cfg, 8)
    assert len(log_a) > 300
    assert np.array_equal(log_a, log_b)
    assert frames_a == frames_b
    n = min(len(log_a), len(log_c))
    assert not np.array_equal(log_a[:n], log_c[:n])
