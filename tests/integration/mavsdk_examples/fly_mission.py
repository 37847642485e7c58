#!/usr/bin/env python3
"""MAVSDK's mission example (fly_mission): upload six waypoints with camera actions, arm,
start, pause at the second item for five seconds, continue, return to launch when the mission
is finished, wait for the disarm (MAVSDK 4)."""

import asyncio

from common import configuration, connect
from mavsdk.asyncio import Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

NAN = float("nan")
CAMERA = MissionItem.CameraAction


def make_item(lat, lon, speed_m_s, fly_through, camera_action):
    return MissionItem(
        latitude_deg=lat, longitude_deg=lon, relative_altitude_m=10, speed_m_s=speed_m_s,
        is_fly_through=fly_through, gimbal_pitch_deg=NAN, gimbal_yaw_deg=NAN,
        camera_action=camera_action, loiter_time_s=NAN, camera_photo_interval_s=1.0,
        acceptance_radius_m=NAN, yaw_deg=NAN, camera_photo_distance_m=NAN,
        vehicle_action=MissionItem.VehicleAction.NONE)


ITEMS = [
    make_item(47.398170327054473, 8.5456490218639658, 5, False, CAMERA.NONE),
    make_item(47.398241338125118, 8.5455360114574432, 2, True, CAMERA.TAKE_PHOTO),
    make_item(47.398139363821485, 8.5453846156597137, 5, True, CAMERA.START_VIDEO),
    make_item(47.398058617228855, 8.5454618036746979, 2, False, CAMERA.STOP_VIDEO),
    make_item(47.398100366082858, 8.5456969141960144, 5, False, CAMERA.START_PHOTO_INTERVAL),
    make_item(47.398001890458097, 8.5455576181411743, 5, False, CAMERA.STOP_PHOTO_INTERVAL),
]


async def run():
    async with Mavsdk(configuration()) as mavsdk:
        system = await connect(mavsdk)
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        mission = MissionAsync(system)

        print("-- Uploading mission")
        await mission.upload_mission(MissionPlan(ITEMS))
        print("-- Mission uploaded")
        downloaded = await mission.download_mission()
        print(f"-- Mission downloaded: {len(downloaded.mission_items)} items")

        print("Waiting for drone to have a global position estimate...")
        async for health in telemetry.subscribe_health():
            if health.is_global_position_ok and health.is_home_position_ok:
                print("-- Global position estimate OK")
                break

        print("-- Arming")
        await action.arm()

        print("-- Starting mission")
        await mission.start_mission()

        paused_once = False
        async for progress in mission.subscribe_mission_progress():
            print(f"Mission status update: {progress.current} / {progress.total}")
            if progress.current >= 2 and not paused_once:
                print("-- Pausing mission for 5 seconds")
                await mission.pause_mission()
                await asyncio.sleep(5)
                print("-- Resuming mission")
                await mission.start_mission()
                paused_once = True
            if progress.current == progress.total:
                break

        if not await mission.is_mission_finished():
            print("mission not finished")
            raise SystemExit(1)
        print("-- Mission finished")

        print("-- Commanding RTL")
        await action.return_to_launch()

        print("-- Waiting for the vehicle to land and disarm")
        async for armed in telemetry.subscribe_armed():
            if not armed:
                break
        print("-- Disarmed")


if __name__ == "__main__":
    asyncio.run(run())
