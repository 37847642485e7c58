"""What every example does first: connect as a ground station and find the autopilot."""

import sys

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk


def url() -> str:
    return sys.argv[1] if len(sys.argv) > 1 else "udpin://0.0.0.0:14540"


async def connect(mavsdk: Mavsdk):
    await mavsdk.add_any_connection(url())
    print("Waiting for drone to connect...")
    system = await mavsdk.first_autopilot(timeout_s=15.0)
    if system is None:
        print("no autopilot found")
        sys.exit(1)
    print("-- Connected to drone!")
    return system


def configuration() -> Configuration:
    return Configuration.create_with_component_type(ComponentType.GROUND_STATION)
