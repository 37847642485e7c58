#!/usr/bin/env python3
"""MAVSDK's offboard_position_ned.py: arm, one position setpoint, start offboard, fly to
local positions (up, north, east, back down), stop offboard (MAVSDK 4)."""

import asyncio

from common import configuration, connect
from mavsdk.asyncio import Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync


async def run():
    async with Mavsdk(configuration()) as mavsdk:
        system = await connect(mavsdk)
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        offboard = OffboardAsync(system)

        print("Waiting for drone to have a global position estimate...")
        async for health in telemetry.subscribe_health():
            if health.is_global_position_ok and health.is_home_position_ok:
                print("-- Global position estimate OK")
                break

        print("-- Arming")
        await action.arm()

        print("-- Setting initial setpoint")
        await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, 0.0, 0.0))

        print("-- Starting offboard")
        try:
            await offboard.start()
        except OffboardError as error:
            print(f"Starting offboard mode failed with error code: {error}")
            print("-- Disarming")
            await action.disarm()
            raise SystemExit(1) from None

        print("-- Go 0m North, 0m East, -5m Down within local coordinate system")
        await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -5.0, 0.0))
        await asyncio.sleep(10)

        print("-- Go 5m North, 0m East, -5m Down within local coordinate system, turn to face East")
        await offboard.set_position_ned(PositionNedYaw(5.0, 0.0, -5.0, 90.0))
        await asyncio.sleep(10)

        print("-- Go 5m North, 10m East, -5m Down within local coordinate system")
        await offboard.set_position_ned(PositionNedYaw(5.0, 10.0, -5.0, 90.0))
        await asyncio.sleep(15)

        print("-- Go 0m North, 10m East, 0m Down within local coordinate system, "
              "turn to face South")
        await offboard.set_position_ned(PositionNedYaw(0.0, 10.0, 0.0, 180.0))
        await asyncio.sleep(10)

        print("-- Stopping offboard")
        try:
            await offboard.stop()
        except OffboardError as error:
            print(f"Stopping offboard mode failed with error code: {error}")
            raise SystemExit(1) from None


if __name__ == "__main__":
    asyncio.run(run())
