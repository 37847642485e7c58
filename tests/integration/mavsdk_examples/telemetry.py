#!/usr/bin/env python3
"""MAVSDK's telemetry.py: battery, GPS, in-air and position, printed as they come (MAVSDK 4).

The published example prints forever; this one stops once each stream has given five samples.
"""

import asyncio

from common import configuration, connect
from mavsdk.asyncio import Mavsdk
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

SAMPLES = 5


async def run():
    async with Mavsdk(configuration()) as mavsdk:
        system = await connect(mavsdk)
        telemetry = TelemetryAsync(system)
        await asyncio.wait_for(asyncio.gather(
            print_battery(telemetry), print_gps_info(telemetry), print_in_air(telemetry),
            print_position(telemetry)), 30.0)


async def print_battery(telemetry):
    n = 0
    async for battery in telemetry.subscribe_battery():
        print(f"Battery: {battery.remaining_percent}")
        n += 1
        if n == SAMPLES:
            return


async def print_gps_info(telemetry):
    n = 0
    async for gps_info in telemetry.subscribe_gps_info():
        print(f"GPS info: {gps_info}")
        n += 1
        if n == SAMPLES:
            return


async def print_in_air(telemetry):
    n = 0
    async for in_air in telemetry.subscribe_in_air():
        print(f"In air: {in_air}")
        n += 1
        if n == SAMPLES:
            return


async def print_position(telemetry):
    n = 0
    async for position in telemetry.subscribe_position():
        print(position)
        n += 1
        if n == SAMPLES:
            return


if __name__ == "__main__":
    asyncio.run(run())
