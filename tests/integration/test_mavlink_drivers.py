"""The MAVLink drivers (pymavlink, MAVSDK) flying the simulator through its MAVLink face
(real time, loopback, bounded by timeouts)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import textwrap

import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, FlightMode, Setpoint
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from .mavtools import CLIENT_URL, collected, served
from .sim_process import die_with_parent

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time


async def _fly_offboard(driver) -> None:
    await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
    await driver.arm()
    await driver.takeoff(3.0)
    await wait_for_state(driver, lambda s: s.in_air and s.mode is FlightMode.HOLD
                         and s.altitude_m > 2.7, 30.0, "takeoff to 3 m")


@pytest.mark.parametrize("driver_class", [
    PymavlinkDriver,
    # (MAVSDK's own examples and the link tests fly the MAVSDK driver in CI)
    pytest.param(MavsdkDriver, marks=pytest.mark.long)])
def test_driver_flies_the_simulator_end_to_end(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config) as (vehicle, _face):
            driver = driver_class(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            # STATUSTEXT, put back together (the console's events)
            reading = collected(driver.events())
            events = await reading.__aenter__()
            try:
                state = driver.latest_state
                assert state.mode is FlightMode.HOLD or state.mode is FlightMode.UNKNOWN
                # capture times are mapped onto our clock: recent, never in the future
                assert 0.0 <= driver.clock.now() - state.time_s < 0.5
                await _fly_offboard(driver)
                with pytest.raises(CommandDenied, match="COM_OF_LOSS_T"):
                    await driver.start_offboard()  # flying, no setpoint: refused (with why)
                assert vehicle.param("MIS_TAKEOFF_ALT") == pytest.approx(3.0)
                start = driver.latest_state.position_ned_m.copy()
                for _ in range(10):
                    await driver.send_setpoint(Setpoint.velocity_ned(1.0, 0.0, 0.0, yaw_rad=0.0))
                    await asyncio.sleep(0.05)
                await driver.start_offboard()

                async def stream():
                    while True:
                        await driver.send_setpoint(Setpoint.velocity_ned(1.0, 0.0, 0.0,
                                                                         yaw_rad=0.0))
                        await asyncio.sleep(0.05)

                streamer = asyncio.get_running_loop().create_task(stream())
                try:
                    await wait_for_state(driver, lambda s: s.mode is FlightMode.OFFBOARD and
                                         s.position_ned_m[0] > start[0] + 1.5, 10.0,
                                         "flying north in OFFBOARD")
                finally:
                    streamer.cancel()
                await driver.stop_offboard()
                await wait_for_state(driver, lambda s: s.mode is FlightMode.HOLD, 3.0, "HOLD")
                await driver.land()
                await wait_for_state(driver, lambda s: not s.armed, 60.0, "landed, disarmed")
                assert vehicle.latest_state.altitude_m < 0.3
                texts = [text for _time_s, text in events]
                assert any("offboard" in t.lower() for t in texts), texts
                assert any("COM_OF_LOSS_T" in t for t in texts), texts  # the refusal's reason
            finally:
                await reading.__aexit__(None, None, None)
                await driver.close()

    asyncio.run(main())


_KILLED_CLIENT = textwrap.dedent("""
    import asyncio, sys
    from autopilot.flight_ops import wait_for_state
    from drivers.base import FlightMode, Setpoint
    from drivers.mavlink.pymavlink_driver import PymavlinkDriver

    async def main():
        driver = PymavlinkDriver(sys.argv[1])
        await driver.connect()
        await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
        await driver.arm()
        await driver.takeoff(2.5)
        await wait_for_state(driver, lambda s: s.in_air and s.mode is FlightMode.HOLD, 30.0,
                             "takeoff")
        sp = Setpoint.velocity_ned(0.5, 0.0, 0.0, yaw_rad=0.0)
        for _ in range(10):
            await driver.send_setpoint(sp)
            await asyncio.sleep(0.05)
        await driver.start_offboard()
        print("OFFBOARD", flush=True)
        while True:  # the controller streams until it is killed
            await driver.send_setpoint(sp)
            await asyncio.sleep(0.05)

    asyncio.run(main())
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_killing_the_client_mid_offboard_lands_after_com_of_loss_t(no_camera_config):
    """SIGKILL takes the client with everything it had: no library keeps re-sending its last
    setpoint, so the vehicle's offboard-loss failsafe acts (COM_OBL_RC_ACT 4: land)."""
    async def main():
        async with served(no_camera_config) as (vehicle, _face):
            await vehicle.set_param("COM_OBL_RC_ACT", 4)
            loss_s = vehicle.param("COM_OF_LOSS_T")
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-c", _KILLED_CLIENT, CLIENT_URL, stdout=subprocess.PIPE,
                env={**os.environ, "PYTHONUNBUFFERED": "1"}, preexec_fn=die_with_parent)
            try:
                line = await asyncio.wait_for(proc.stdout.readline(), 60.0)
                assert line.strip() == b"OFFBOARD"
                await wait_for_state(vehicle, lambda s: s.mode is FlightMode.OFFBOARD, 2.0,
                                     "OFFBOARD")
                await asyncio.sleep(1.0)
                proc.kill()
                killed_at = vehicle.clock.now()
                landing = await wait_for_state(vehicle, lambda s: s.mode is FlightMode.LAND,
                                               loss_s + 2.0, "LAND after the kill")
                assert landing.failsafe
                assert landing.time_s - killed_at <= loss_s + 0.3
                await wait_for_state(vehicle, lambda s: not s.armed, 60.0, "landed, disarmed")
            finally:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()

    asyncio.run(main())
