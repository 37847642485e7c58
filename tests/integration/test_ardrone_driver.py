"""The AR.Drone 2.0 driver (drivers/ardrone/driver.py) against the simulated AR.Drone
(autopilot/ardrone_server.py) on loopback, in real time: connect, take off to its ~1 m, fly a
velocity north on the driver's own outer loop and hold, a frame from each camera (the video
channel switched), land."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time

import numpy as np
import pytest

from autopilot.ardrone_server import serve
from autopilot.config import load_config
from drivers.ardrone import navdata as nav
from drivers.ardrone.driver import ArdroneDriver
from drivers.ardrone.navdata import ControlState, Demo, State
from drivers.ardrone.urls import ArdronePorts
from drivers.base import CommandDenied, FlightMode, LandedState, Setpoint, VehicleNotFound

pytestmark = pytest.mark.serial  # real time, on fixed ports

PORTS = ArdronePorts().offset(100)  # clear of the other AR.Drone tests' (200, 300)
#: generous: a busy machine slows the simulated drone (its clock is held back with it)
READY_S = 120.0
STEP_S = 20.0


async def _until(driver: ArdroneDriver, done, timeout_s: float, what: str):
    """The first telemetry sample for which ``done`` holds."""
    async def wait():
        async with contextlib.aclosing(driver.telemetry()) as states:
            async for state in states:
                if done(state):
                    return state
        raise AssertionError(f"telemetry ended before {what}")

    try:
        return await asyncio.wait_for(wait(), timeout_s)
    except TimeoutError:
        raise AssertionError(f"not {what} within {timeout_s:g} s: "
                             f"{driver.latest_state}") from None


async def _frame(driver: ArdroneDriver, camera: str, timeout_s: float):
    async def first():
        async with contextlib.aclosing(driver.frames(camera)) as frames:
            async for frame in frames:
                return frame
        raise AssertionError(f"{camera}: the frames ended")

    return await asyncio.wait_for(first(), timeout_s)


async def _truth(server) -> np.ndarray:
    runner, sim = server.vehicle.runner, server.vehicle.simulator
    return (await runner.call(sim.ground_truth)).vehicle.position_ned_m.copy()


def _send_from(host: str, port: int, data: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((host, 0))
        sock.sendto(data, ("127.0.0.1", port))


async def _flight(timings: dict[str, float]) -> None:
    stop, ready = asyncio.Event(), asyncio.Event()
    servers = []

    def on_ready(server) -> None:
        servers.append(server)
        ready.set()

    start = time.monotonic()
    serving = asyncio.ensure_future(serve(load_config(None, ["sim.firmware=ardrone"]), None,
                                          ports=PORTS, stop=stop, on_ready=on_ready,
                                          log=lambda line: None))
    driver = ArdroneDriver("ardrone://127.0.0.1", ports=PORTS)
    try:
        await asyncio.wait_for(ready.wait(), READY_S)
        (server,) = servers
        timings["server"] = time.monotonic() - start
        mark = time.monotonic()
        await driver.connect(STEP_S)
        timings["connect"] = time.monotonic() - mark
        state = driver.latest_state
        assert state.landed_state is LandedState.ON_GROUND
        assert not state.armed
        assert state.health.armable
        assert driver.limits.euler_angle_max_rad == pytest.approx(0.20944, abs=1e-4)

        # navdata from elsewhere is ignored, a damaged packet dropped
        (_, port) = driver.link.navdata_address
        packet = nav.build(int(State.FLY | State.NAVDATA_DEMO), 10**6,
                           Demo(ControlState.FLYING << 16, 5, 0, 0, 0, 9000, 0, 0, 0))
        _send_from("127.0.0.2", port, packet)
        _send_from("127.0.0.1", port, packet[:-1] + bytes([packet[-1] ^ 0xFF]))
        await asyncio.sleep(0.3)
        assert driver.link.foreign_datagrams == 1
        assert driver.link.bad_packets == 1
        assert driver.latest_state.altitude_m < 0.2  # neither was taken

        mark = time.monotonic()
        await driver.arm()
        await driver.takeoff()
        hovering = await _until(driver, lambda s: s.in_air and s.mode is FlightMode.HOLD and
                                s.landed_state is LandedState.IN_AIR, STEP_S, "hovering")
        timings["takeoff"] = time.monotonic() - mark
        assert 0.7 < hovering.altitude_m < 1.3
        assert hovering.armed

        # 0.5 m/s north for 3 s on the driver's outer loop, then the drone's own hover
        await server.vehicle.clock.sleep(1.0)
        truth0, dead0 = await _truth(server), driver.latest_state.position_ned_m.copy()
        north = Setpoint.velocity_ned(0.5, 0.0, 0.0)
        await driver.send_setpoint(north)
        await driver.start_offboard()
        modes, speeds = set(), []
        sim_clock = server.vehicle.clock  # (the drone's world: held back on a busy machine)
        end = sim_clock.now() + 3.0
        while sim_clock.now() < end:
            await driver.send_setpoint(north)
            modes.add(driver.latest_state.mode)
            speeds.append(float(driver.latest_state.velocity_ned_m_s[0]))
            await asyncio.sleep(1 / 30)
        assert FlightMode.OFFBOARD in modes
        assert max(speeds) > 0.35
        await driver.hold()
        await sim_clock.sleep(2.5)
        held = driver.latest_state
        assert held.mode is FlightMode.HOLD
        assert np.linalg.norm(held.velocity_ned_m_s[:2]) < 0.25
        truth1, dead1 = await _truth(server), held.position_ned_m.copy()
        true_move, dead_move = truth1 - truth0, dead1 - dead0
        assert 0.9 < true_move[0] < 3.0, true_move
        assert abs(true_move[1]) < 0.5, true_move
        assert 0.9 < dead_move[0] < 3.0, dead_move
        assert abs(dead_move[1]) < 0.5, dead_move
        assert np.linalg.norm((dead_move - true_move)[:2]) < 0.5
        assert driver.drift_m > 0.04 * 1.0
        timings["flown"] = time.monotonic() - mark

        # one camera at a time: a frame from the front, then (the channel switched) the bottom
        mark = time.monotonic()
        front = await _frame(driver, "front", STEP_S)
        assert front.image.shape == (360, 640, 3)
        assert front.camera.name == "front"
        down = await _frame(driver, "down", STEP_S)
        assert down.image.shape == (240, 320, 3)
        assert down.camera.name == "down"
        assert driver.video_camera == "down"
        assert server.face.video_camera == "down"
        now = driver.clock.now()
        for frame in (front, down):
            assert now - 5.0 < frame.time_s < now
        assert down.time_s > front.time_s
        timings["frames"] = time.monotonic() - mark

        mark = time.monotonic()
        await driver.land()
        landed = await _until(driver, lambda s: not s.armed and not s.in_air, STEP_S, "landed")
        timings["land"] = time.monotonic() - mark
        assert landed.landed_state is LandedState.ON_GROUND
        assert landed.altitude_m < 0.2

        # a takeoff to a height: the drone's own ~1 m, then the driver's climb (TAKEOFF), HOLD
        mark = time.monotonic()
        await driver.takeoff(1.6)
        climbing = await _until(driver, lambda s: s.mode is FlightMode.TAKEOFF and
                                s.altitude_m > 1.1, STEP_S, "climbing past 1.1 m")
        assert climbing.in_air
        there = await _until(driver, lambda s: s.mode is FlightMode.HOLD and s.in_air,
                             STEP_S, "holding after the climb")
        assert there.altitude_m == pytest.approx(1.6, abs=0.15)
        timings["takeoff to 1.6 m"] = time.monotonic() - mark

        # disarm in the air: refused, unless forced (the emergency cut); then reset
        with pytest.raises(CommandDenied):
            await driver.disarm()
        await driver.disarm(force=True)
        fallen = await _until(driver, lambda s: not s.in_air and s.altitude_m < 0.2, STEP_S,
                              "fallen")
        assert not fallen.health.armable
        with pytest.raises(CommandDenied, match="emergency"):
            await driver.arm()
        await driver.reset_emergency()
        await _until(driver, lambda s: s.health.armable, STEP_S, "armable again")
    finally:
        await driver.close()
        stop.set()
        await asyncio.wait_for(serving, 60.0)


def test_the_driver_flies_the_simulated_ardrone() -> None:
    timings: dict[str, float] = {}
    asyncio.run(_flight(timings))
    print("timings (s):", {k: round(v, 2) for k, v in timings.items()})


def test_no_drone_is_vehicle_not_found_with_its_address() -> None:
    async def main():
        driver = ArdroneDriver("ardrone://127.0.0.1", ports=ArdronePorts().offset(110))
        with pytest.raises(VehicleNotFound, match=r"127\.0\.0\.1"):
            await driver.connect(1.0)
        with pytest.raises(VehicleNotFound):  # (and it may be tried again)
            await driver.connect(0.5)
        await driver.close()

    asyncio.run(main())
