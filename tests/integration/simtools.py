"""Helpers for closed-loop tests on the simulator's lockstep clock."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import numpy as np

from autopilot.flight_ops import stream_setpoints, wait_for_state
from autopilot.flightlog import records as ch
from drivers.base import FlightMode, Setpoint
from drivers.sim.driver import SimDriver

GROUND_Z = -0.095  # local NED z of the body origin resting on its skids


#: follow_ball with a 20 s following step: the short closed loop most runtime tests fly
SHORT_FOLLOW = ["steps.1.follow_ball.duration_s=20"]


def fly_short(overrides, out=None, **kwargs):
    """A short follow_ball through :func:`autopilot.run.fly` on the lockstep clock: its summary
    and the tasks it left behind (there should be none)."""
    from autopilot.mission import load_mission
    from autopilot.run import fly

    plan = load_mission("follow_ball", [*SHORT_FOLLOW, *overrides])

    async def main():
        summary = await fly(plan, out, **kwargs)
        orphans = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        return summary, orphans

    return asyncio.run(main())


def ended_down(log) -> dict:
    """The flight's last telemetry, checked to be on the ground and disarmed."""
    last = log[ch.VEHICLE_STATE][-1]
    assert last["armed"] is False
    assert log[ch.GROUND_TRUTH][-1]["vehicle_position_ned_m"][2] > -0.3  # on the ground
    return last


def run(coro):
    return asyncio.run(coro)


@contextlib.asynccontextmanager
async def simulator(sim_config, **kwargs) -> AsyncIterator[SimDriver]:
    driver = SimDriver(sim_config, **kwargs)
    await driver.connect()
    try:
        yield driver
    finally:
        await driver.close()


async def armable(driver: SimDriver) -> None:
    await wait_for_state(driver, lambda s: s.health.armable, 10.0, "armable")


async def take_off(driver: SimDriver, altitude_m: float = 2.0) -> None:
    await armable(driver)
    await driver.arm()
    await driver.takeoff(altitude_m)
    await wait_for_state(driver, lambda s: s.mode is FlightMode.HOLD and s.in_air, 20.0,
                         "takeoff")


class Offboard:
    """A test's offboard "controller": streams ``self.setpoint`` (fresh each tick) at 20 Hz;
    set it to None to stop streaming."""

    def __init__(self, driver: SimDriver, rate_hz: float = 20.0) -> None:
        self.driver = driver
        self.setpoint: Setpoint | None = None
        self._task = asyncio.ensure_future(stream_setpoints(driver, lambda: self.setpoint,
                                                            rate_hz))

    async def start_holding_here(self) -> np.ndarray:
        state = self.driver.latest_state
        here = np.array(state.position_ned_m)
        self.setpoint = Setpoint.position(*here, yaw_rad=state.yaw_rad)
        await self.driver.clock.sleep(0.3)
        await self.driver.start_offboard()
        return here

    async def aclose(self) -> None:
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task


async def record_truth(driver: SimDriver, duration_s: float):
    """Ground-truth samples over the next ``duration_s`` seconds."""
    samples = []

    async def collect():
        async with contextlib.aclosing(driver.ground_truth(buffer=1024)) as stream:
            async for sample in stream:
                samples.append(sample)

    task = asyncio.ensure_future(collect())
    await driver.clock.sleep(duration_s)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    return samples


def searched(log, step: str) -> dict:
    """What the step's search did, from the flight log: how far from where the step began its
    setpoints went, and the highest they went (m above the take-off point)."""
    points = np.array([r["position_ned_m"] for r in log[ch.SETPOINTS]
                       if r.get("step") == step and r.get("phase") == "searching"])
    start = points[0]
    return {"out_m": float(np.max(np.hypot(*(points[:, :2] - start[:2]).T))),
            "up_m": float(-np.min(points[:, 2]))}
