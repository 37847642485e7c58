"""PX4's precision landing (AUTO.PRECLAND) in the simulator, driven over MAVLink as a companion
computer drives PX4: LANDING_TARGET in MAV_FRAME_LOCAL_NED streamed through the MAVSDK and
pymavlink drivers, the mode switched with DO_SET_MODE (real time, loopback). The simulator
follows PX4's precland.cpp: approach, descend over the target, and without a target climb to
PLD_SRCH_ALT, search for PLD_SRCH_TOUT, fall back to a normal landing."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import FlightMode, LandingTarget
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from .mavtools import CLIENT_URL, served

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time


async def _up(driver, altitude_m: float) -> np.ndarray:
    await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
    await driver.arm()
    await driver.takeoff(altitude_m)
    await wait_for_state(driver, lambda s: s.in_air and s.mode is FlightMode.HOLD
                         and s.altitude_m > altitude_m - 0.3, 30.0, "takeoff")
    return driver.latest_state.position_ned_m.copy()


def test_precision_landing_on_the_reported_target_through_mavsdk(no_camera_config):
    target = (2.0, -1.5, 0.0)
    config = no_camera_config.model_copy(update={"params": {"MPC_LAND_SPEED": 1.2}})

    async def main():
        async with served(config) as (vehicle, face):
            driver = MavsdkDriver(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            try:
                await _up(driver, 3.0)

                async def stream():  # the companion's pad estimate, 10 a second
                    while True:
                        await driver.send_landing_target(LandingTarget(driver.clock.now(),
                                                                       target))
                        await asyncio.sleep(0.1)

                streamer = asyncio.get_running_loop().create_task(stream())
                try:
                    await asyncio.sleep(0.3)
                    await driver.precision_land()
                    await wait_for_state(driver, lambda s: s.mode is FlightMode.PRECLAND, 3.0,
                                         "PRECLAND shown through MAVSDK")
                    await wait_for_state(driver, lambda s: not s.armed, 60.0,
                                         "landed on the target, disarmed")
                finally:
                    streamer.cancel()
                rest = vehicle.latest_state.position_ned_m
                assert np.hypot(rest[0] - target[0], rest[1] - target[1]) < 0.1
                assert face.stats.landing_targets > 50
            finally:
                await driver.close()

    asyncio.run(main())


@pytest.mark.long  # (the precision landing above covers the mode in CI)
def test_no_target_climbs_to_search_then_falls_back_to_a_normal_landing(no_camera_config):
    # (a quicker descent than PX4's default, for the test's time)
    config = no_camera_config.model_copy(update={"params": {
        "PLD_SRCH_ALT": 4.0, "PLD_SRCH_TOUT": 2.0, "MPC_LAND_SPEED": 1.5}})

    async def main():
        async with served(config) as (vehicle, _face):
            driver = PymavlinkDriver(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            try:
                start = await _up(driver, 2.5)
                await driver.precision_land()
                top = 0.0

                def watch(s):
                    nonlocal top
                    top = max(top, s.altitude_m)
                    return not s.armed

                await wait_for_state(driver, watch, 60.0, "fallback landing, disarmed")
                # PX4: 2 s at the start point, climb to PLD_SRCH_ALT, 2 s search, land there
                assert top == pytest.approx(4.0, abs=0.4)
                rest = vehicle.latest_state.position_ned_m
                assert np.hypot(*(rest[:2] - start[:2])) < 0.5
                print(list(driver._statustext))
                assert "Falling back to normal land." in driver._statustext
            finally:
                await driver.close()

    asyncio.run(main())


def test_a_target_in_another_frame_is_refused_with_a_status_text(no_camera_config):
    async def main():
        async with served(no_camera_config) as (_vehicle, face):
            driver = PymavlinkDriver(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            try:
                link = driver._link
                link.send(link.mav.landing_target_encode(0, 0, 12, 0, 0, 0, 0, 0, 1.0, 2.0,
                                                         0.0, [1, 0, 0, 0], 0, 1))
                await asyncio.sleep(0.5)
                assert face.stats.landing_targets == 0
                assert "Landing target: coordinate frame 12 unsupported" in driver._statustext
            finally:
                await driver.close()

    asyncio.run(main())
