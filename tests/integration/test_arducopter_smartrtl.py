"""The simulated ArduCopter's SMART_RTL and battery failsafe, through the simulator's own
driver on the lockstep clock: SMART_RTL retraces the path flown (the corner, not the
diagonal) to 2 m above where it armed, then lands and disarms; it is refused before any path;
the GCS failsafe's "SmartRTL or RTL" flies it; the battery monitor's low voltage
(BATT_LOW_VOLT for BATT_LOW_TIMER) takes BATT_FS_LOW_ACT in ArduPilot's words, and the pre-arm
check refuses a pack already below it."""

import asyncio
import contextlib

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, Setpoint
from drivers.mavlink.ardupilot import CopterMode
from tests.conftest import sim_with

from .mavtools import collected
from .simtools import GROUND_Z, armable, run, simulator

GUIDED, SMART_RTL, RTL = int(CopterMode.GUIDED), int(CopterMode.SMART_RTL), int(CopterMode.RTL)


@pytest.fixture
def copter(sim_config):
    return sim_with(sim_config, firmware="ardupilot")


async def _takeoff(drv, altitude_m: float = 3.0) -> None:
    await drv.firmware_command("set_copter_mode", GUIDED)
    await drv.arm()
    await drv.takeoff(altitude_m)
    await wait_for_state(drv, lambda s: -s.position_ned_m[2] > altitude_m - 0.2, 20.0,
                         "takeoff")


async def _goto(drv, north_m: float, east_m: float, altitude_m: float = 3.0) -> None:
    await drv.send_setpoint(Setpoint(position_ned_m=[north_m, east_m, -altitude_m]))
    await wait_for_state(drv, lambda s: np.hypot(s.position_ned_m[0] - north_m,
                                                 s.position_ned_m[1] - east_m) < 0.5,
                         40.0, f"at {north_m}, {east_m}")


def test_smart_rtl_retraces_the_path_flown_and_lands_home(copter):
    async def main():
        async with simulator(copter) as drv:
            await armable(drv)
            with pytest.raises(CommandDenied, match="SMARTRTL failed: init failed"):
                await drv.firmware_command("set_copter_mode", SMART_RTL)  # no path yet
            await _takeoff(drv, 6.0)
            await _goto(drv, 20.0, 0.0, 6.0)
            await _goto(drv, 20.0, 20.0, 6.0)
            await drv.firmware_command("set_copter_mode", SMART_RTL)
            seen = []
            await wait_for_state(drv, lambda s: seen.append(s) or not s.armed, 120.0,
                                 "SMART_RTL lands and disarms")
            xy = np.array([s.position_ned_m[:2] for s in seen])
            # home by the corner it went out by, never across the diagonal (RTL's way)
            assert np.min(np.linalg.norm(xy - [20.0, 0.0], axis=1)) < 2.5
            assert np.min(np.linalg.norm(xy - [10.0, 10.0], axis=1)) > 5.0
            # back over home at the top of its climb (the path's point there), then down the
            # climb to its last point, 2 m above where it armed, and lands
            near_home = [s for s in seen if np.hypot(*s.position_ned_m[:2]) < 1.0]
            assert -near_home[0].position_ned_m[2] == pytest.approx(6.0, abs=0.7)
            # (LAND from where the descent ends, still moving: within a metre)
            assert np.hypot(*seen[-1].position_ned_m[:2]) < 1.0
            assert seen[-1].position_ned_m[2] > GROUND_Z - 0.2
            assert drv.simulator.flight.custom_mode == SMART_RTL  # stays, disarmed

    run(main())


def test_a_gcs_failsafe_smartrtl_or_rtl_flies_smart_rtl(copter):
    async def main():
        async with simulator(copter) as drv, collected(drv.events(buffer=256)) as said:
            await drv.set_param("FS_GCS_ENABLE", 3)  # SmartRTL or RTL
            await armable(drv)
            flight = drv.simulator.flight

            async def ground_station():
                while True:
                    flight.gcs_heartbeat()
                    await drv.clock.sleep(0.5)

            heartbeats = asyncio.ensure_future(ground_station())
            await _takeoff(drv)
            await _goto(drv, 15.0, 0.0)
            await _goto(drv, 15.0, 15.0)
            heartbeats.cancel()  # the ground station falls silent: FS_GCS_TIMEOUT (5 s)
            with contextlib.suppress(asyncio.CancelledError):
                await heartbeats
            state = await wait_for_state(drv, lambda s: flight.custom_mode == SMART_RTL,
                                         20.0, "the GCS failsafe's SMART_RTL")
            assert state.armed
            seen = []
            await wait_for_state(drv, lambda s: seen.append(s) or not s.armed, 120.0, "home")
            xy = np.array([s.position_ned_m[:2] for s in seen])
            assert np.min(np.linalg.norm(xy - [15.0, 0.0], axis=1)) < 2.5
            assert not any("SmartRTL Unavailable" in text for _, text in said)

    run(main())


def test_low_battery_voltage_takes_batt_fs_low_act_and_refuses_arming(copter):
    async def main():
        async with simulator(copter) as drv, collected(drv.events(buffer=256)) as said:
            await armable(drv)
            # the pack at rest: 16.8 V (4S full); below a threshold above it, no arming
            await drv.set_param("BATT_LOW_VOLT", 17.0)
            await drv.firmware_command("set_copter_mode", GUIDED)
            with pytest.raises(CommandDenied, match="PreArm: Battery 1 low voltage failsafe"):
                await drv.arm()
            # under load the voltage sags below 16.7 V: low after BATT_LOW_TIMER (2 s)
            await drv.set_param("BATT_LOW_VOLT", 16.7)
            await drv.set_param("BATT_LOW_TIMER", 2)
            await drv.set_param("BATT_FS_LOW_ACT", 2)  # RTL
            await _takeoff(drv)
            await drv.send_setpoint(Setpoint(position_ned_m=[8.0, 0.0, -3.0]))
            flight = drv.simulator.flight
            await wait_for_state(drv, lambda s: flight.custom_mode == RTL, 30.0,
                                 "the battery failsafe's RTL")
            texts = [text for _, text in said]
            assert any(t.startswith("Battery 1 is low ") and "mAh" in t for t in texts)
            assert "Battery Failsafe" in texts
            assert drv.latest_state.failsafe
            seen = []
            await wait_for_state(drv, lambda s: seen.append(s) or not s.armed, 90.0, "RTL")
            np.testing.assert_allclose(seen[-1].position_ned_m[:2], [0.0, 0.0], atol=0.6)

    run(main())
