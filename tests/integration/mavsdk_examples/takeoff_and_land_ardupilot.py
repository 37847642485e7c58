#!/usr/bin/env python3
"""MAVSDK's takeoff_and_land.py for an ArduCopter: the published example with the one line an
ArduPilot user adds. ArduCopter sends HOME_POSITION only when home is set or moves (and on
request), never as a stream: MAVSDK's health already holds the home it asked for, but
``subscribe_home()`` waits for the next message, which never comes before arming. Asking for
it as a stream (SET_MESSAGE_INTERVAL, which ArduCopter honours) is the fix (MAVSDK 4)."""

import asyncio

from common import configuration, connect
from mavsdk.asyncio import Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync


async def run():
    async with Mavsdk(configuration()) as mavsdk:
        system = await connect(mavsdk)
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        status_text_task = asyncio.ensure_future(print_status_text(telemetry))

        print("Waiting for drone to have a global position estimate...")
        async for health in telemetry.subscribe_health():
            if health.is_global_position_ok and health.is_home_position_ok:
                print("-- Global position estimate OK")
                break

        await telemetry.set_rate_home(1.0)  # (the added line: ArduCopter does not stream home)
        print("Fetching amsl altitude at home location....")
        async for terrain_info in telemetry.subscribe_home():
            absolute_altitude = terrain_info.absolute_altitude_m
            break
        print(f"-- Home at {absolute_altitude:.1f} m AMSL")
        print(f"-- Takeoff altitude: {await action.get_takeoff_altitude():.1f} m")
        print(f"-- Return-to-launch altitude: {await action.get_return_to_launch_altitude():.1f} m")

        print("-- Arming")
        await action.arm()

        print("-- Taking off")
        await action.takeoff()

        await asyncio.sleep(10)

        print("-- Landing")
        await action.land()

        status_text_task.cancel()


async def print_status_text(telemetry):
    try:
        async for status_text in telemetry.subscribe_status_text():
            print(f"Status: {status_text.type}: {status_text.text}")
    except asyncio.CancelledError:
        return


if __name__ == "__main__":
    asyncio.run(run())
