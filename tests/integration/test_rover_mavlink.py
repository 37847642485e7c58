"""The rover as a second MAVLink system: the simulator's face speaks for the scenario's rover
(system 2, a ground rover's HEARTBEAT and GLOBAL_POSITION_INT) on the vehicle's own port, as a
router relays both; the pymavlink driver told the rover's system id turns its reports into
RoverState in the drone's local frame, and never takes the rover for the vehicle."""

import asyncio
import contextlib
import math

import numpy as np
import pytest

from autopilot.mission import load_mission
from autopilot.scenario import build_world
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from .mavtools import CLIENT_URL, served

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time


def test_the_rovers_reports_reach_the_driver_as_a_second_system():
    plan = load_mission("land_on_rover", ["scenario.rover.path=straight"])
    sim_cfg, objects = build_world(plan.mission.scenario, plan.config.sim, plan.config)
    cams = {k: v.model_copy(update={"enabled": False}) for k, v in sim_cfg.cameras.items()}
    link = sim_cfg.rover_link.model_copy(update={"mavlink": True})
    sim_cfg = sim_cfg.model_copy(update={"cameras": cams, "rover_link": link})

    async def main():
        async with served(sim_cfg, scenario=objects) as (vehicle, face):
            assert face.rover_system_id == 2
            # a driver not told about the rover: takes the vehicle, ignores the rover
            plain = PymavlinkDriver(CLIENT_URL)
            await plain.connect(timeout_s=10.0)
            try:
                assert plain._target[0] == face.system_id
                assert plain.sensors == frozenset()
            finally:
                await plain.close()
            driver = PymavlinkDriver(CLIENT_URL)
            driver.rover_system_id = 2
            await driver.connect(timeout_s=10.0)
            try:
                assert driver.sensors == frozenset({"rover"})
                assert driver._target[0] == face.system_id  # the vehicle, not the rover
                got = []
                async with contextlib.aclosing(driver.rover_states()) as reports:
                    async with asyncio.timeout(20.0):
                        async for report in reports:
                            got.append((report, vehicle.simulator.ground_truth()))
                            if len(got) >= 10:
                                break
                for report, truth in got:
                    assert report.system_id == 2
                    rover = truth.bodies["rover"]
                    # its GNSS wanders (σ 0.8 m) and it is seen a moment later
                    assert np.hypot(*(report.position_ned_m[:2] - rover.position_ned_m[:2])) \
                        < 4.0
                    assert math.isfinite(report.heading_rad)
                    assert report.time_s <= driver.clock.now()
                # the vehicle's own telemetry is untouched by the rover's messages
                state = driver.latest_state
                assert state is not None
                assert abs(state.position_ned_m[0]) < 1.0
            finally:
                await driver.close()

    asyncio.run(main())


def test_the_mavsdk_driver_reads_the_rover_too_and_never_shows_it_to_mavsdk():
    from drivers.mavlink.mavsdk_driver import MavsdkDriver

    plan = load_mission("land_on_rover")
    sim_cfg, objects = build_world(plan.mission.scenario, plan.config.sim, plan.config)
    cams = {k: v.model_copy(update={"enabled": False}) for k, v in sim_cfg.cameras.items()}
    link = sim_cfg.rover_link.model_copy(update={"mavlink": True})
    sim_cfg = sim_cfg.model_copy(update={"cameras": cams, "rover_link": link})

    async def main():
        async with served(sim_cfg, scenario=objects) as (_vehicle, face):
            driver = MavsdkDriver(CLIENT_URL)
            driver.rover_system_id = 2
            await driver.connect(timeout_s=15.0)
            try:
                assert driver._target[0] == face.system_id
                async with contextlib.aclosing(driver.rover_states()) as reports:
                    async with asyncio.timeout(20.0):
                        report = await anext(reports)
                assert report.system_id == 2
                assert math.isfinite(report.heading_rad)
            finally:
                await driver.close()

    asyncio.run(main())
