"""The AR.Drone driver's outer loop flying the simulated AR.Drone in process (lockstep): a
velocity setpoint is flown up to the speed the drone's tilt limit holds against its drag, and
the drone's configuration keys written at connect (``link.ardrone_config``) move that limit."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from autopilot.config import load_config
from drivers.base import Setpoint
from drivers.sim.ardrone_driver import SimArdroneDriver


async def _cruise(speed_m_s: float, drone_config=None, seed: int = 3) -> tuple[float, object]:
    """The true ground speed north after 12 s of a velocity setpoint north (the integral
    takes seconds to supply the drag), and the limits the driver read."""
    config = load_config(None, ["sim.firmware=ardrone", "sim.profile=ideal"])
    driver = SimArdroneDriver(config.sim, seed=seed, drone_config=drone_config)
    try:
        await driver.connect()
        await driver.takeoff()
        clock = driver.clock
        setpoint = Setpoint.velocity_ned(speed_m_s, 0.0, 0.0)
        await driver.send_setpoint(setpoint)
        await driver.start_offboard()
        speeds = []
        start = clock.now()
        while clock.now() - start < 14.0:
            await driver.send_setpoint(setpoint)
            await clock.sleep(1 / 30)
            if clock.now() - start > 12.0:
                truth = await driver.runner.call(driver.simulator.ground_truth)
                speeds.append(truth.vehicle.velocity_ned_m_s[0])
        await driver.land()
        return float(np.mean(speeds)), driver.limits
    finally:
        await driver.close()


def test_a_fast_velocity_is_flown_up_to_the_tilts_limit():
    """Indoor defaults (12°): 2.5 m/s flown (the limit is 80 % of the 3.6 m/s the tilt holds);
    10 m/s asked: the limit."""
    speed, limits = asyncio.run(_cruise(2.5))
    assert speed == pytest.approx(2.5, rel=0.05)
    top, _ = asyncio.run(_cruise(10.0))
    assert top == pytest.approx(0.8 * limits.terminal_speed_m_s(), rel=0.08)


def test_the_outdoor_profile_written_at_connect_flies_faster():
    speed, limits = asyncio.run(_cruise(4.0, {"control:outdoor": True}))
    assert limits.euler_angle_max_rad == pytest.approx(np.radians(20.0), rel=1e-4)
    assert limits.control_vz_max_m_s == pytest.approx(1.0)
    assert speed == pytest.approx(4.0, rel=0.06)
