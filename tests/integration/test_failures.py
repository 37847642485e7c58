"""Simulator failures become clear, typed errors, never a silent fly-away."""

import contextlib

import numpy as np
import pytest

from drivers.base import ConnectionLost
from drivers.sim.simulator import SimulationDiverged, Simulator

from .simtools import run, simulator, take_off


def test_nan_state_raises_simulation_diverged(sim_config):
    sim = Simulator(sim_config)
    try:
        sim.advance_to(0.5)
        sim.data.qvel[:] = np.nan
        with pytest.raises(SimulationDiverged, match=r"diverged \(BADQVEL\) at t=0\.5"):
            sim.advance_to(1.0)
    finally:
        sim.close()


def test_divergence_ends_streams_and_commands_with_connection_lost(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            drv.simulator.data.qacc_warmstart[:] = np.inf
            drv.simulator.data.qvel[:] = 1e12
            with pytest.raises(ConnectionLost, match="diverged"):
                await _drain(drv.telemetry())
            with pytest.raises(ConnectionLost, match="diverged"):
                await drv.land()

    run(main())


async def _drain(stream):
    async with contextlib.aclosing(stream):
        async for _ in stream:
            pass


def test_commands_before_connect_are_refused(sim_config):
    from drivers.sim.driver import SimDriver

    async def main():
        drv = SimDriver(sim_config)
        with pytest.raises(ConnectionLost, match="not connected"):
            await drv.arm()

    run(main())
