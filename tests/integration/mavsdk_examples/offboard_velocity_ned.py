#!/usr/bin/env python3
"""MAVSDK's offboard_velocity_ned.py: arm on the ground, one setpoint, start offboard, fly
velocity legs, stop offboard (MAVSDK 4)."""

import asyncio

from common import configuration, connect
from mavsdk.asyncio import Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError, VelocityNedYaw
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
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))

        print("-- Starting offboard")
        try:
            await offboard.start()
        except OffboardError as error:
            print(f"Starting offboard mode failed with error code: {error}")
            print("-- Disarming")
            await action.disarm()
            raise SystemExit(1) from None

        print("-- Go up 2 m/s")
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, -2.0, 0.0))
        await asyncio.sleep(4)

        print("-- Go North 2 m/s, turn to face East")
        await offboard.set_velocity_ned(VelocityNedYaw(2.0, 0.0, 0.0, 90.0))
        await asyncio.sleep(4)

        print("-- Go South 2 m/s, turn to face West")
        await offboard.set_velocity_ned(VelocityNedYaw(-2.0, 0.0, 0.0, 270.0))
        await asyncio.sleep(4)

        print("-- Go West 2 m/s, turn to face East")
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, -2.0, 0.0, 90.0))
        await asyncio.sleep(4)

        print("-- Go East 2 m/s")
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 2.0, 0.0, 90.0))
        await asyncio.sleep(4)

        print("-- Turn to face South")
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 180.0))
        await asyncio.sleep(2)

        print("-- Go down 1 m/s, turn to face North")
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 1.0, 0.0))
        await asyncio.sleep(4)

        print("-- Stopping offboard")
        try:
            await offboard.stop()
        except OffboardError as error:
            print(f"Stopping offboard mode failed with error code: {error}")
            raise SystemExit(1) from None


if __name__ == "__main__":
    asyncio.run(run())
