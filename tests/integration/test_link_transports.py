"""A companion computer's own links: a serial port (a Raspberry Pi or Jetson wired to the flight
controller's TELEM port) and TCP, for both drivers.

The serial port is a pseudo-terminal whose other end is bridged to the simulator's MAVLink face
over UDP, as a real flight controller's UART would carry the same bytes; the TCP server is a
bridge too. Real time, loopback, bounded by timeouts."""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty

import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import Setpoint
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from .mavtools import served

pytestmark = pytest.mark.serial  # MAVLink links on fixed ports

DRIVERS = [PymavlinkDriver, MavsdkDriver]
TCP_PORT = 15760


class _UdpSide(asyncio.DatagramProtocol):
    """The bridge's UDP end, facing the simulator's offboard port."""

    def __init__(self, deliver) -> None:
        self.deliver = deliver
        self.transport = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        self.deliver(data)


@contextlib.asynccontextmanager
async def _serial_bridge(face):
    """A pty: its slave is the "serial port" the driver opens, its master talks UDP to the
    simulator's offboard port (the face learns the bridge's address from its first datagram)."""
    loop = asyncio.get_running_loop()
    master, slave = os.openpty()
    tty.setraw(master)
    device = os.ttyname(slave)
    face_port = face.ports["offboard"][0]
    udp, _ = await loop.create_datagram_endpoint(
        lambda: _UdpSide(lambda data: os.write(master, data)), local_addr=("127.0.0.1", 0),
        remote_addr=("127.0.0.1", face_port))

    def from_driver() -> None:
        try:
            data = os.read(master, 4096)
        except OSError:
            return
        udp.sendto(data)

    loop.add_reader(master, from_driver)
    try:
        yield device
    finally:
        loop.remove_reader(master)
        udp.close()
        os.close(master)
        os.close(slave)


@contextlib.asynccontextmanager
async def _tcp_bridge(face):
    """A TCP server (as a WiFi telemetry bridge or ArduPilot SITL's 5760 offers) in front of
    the simulator's offboard UDP port."""
    loop = asyncio.get_running_loop()
    face_port = face.ports["offboard"][0]

    async def client(reader, writer) -> None:
        udp, _ = await loop.create_datagram_endpoint(
            lambda: _UdpSide(writer.write), local_addr=("127.0.0.1", 0),
            remote_addr=("127.0.0.1", face_port))
        try:
            while data := await reader.read(4096):
                udp.sendto(data)
        finally:
            udp.close()
            writer.close()

    server = await asyncio.start_server(client, "127.0.0.1", TCP_PORT)
    try:
        yield f"tcpout://127.0.0.1:{TCP_PORT}"
    finally:
        server.close()


async def _fly_briefly(driver, vehicle) -> None:
    """Connect, arm, stream a setpoint, disarm: commands and acks both ways."""
    await driver.connect(timeout_s=15.0)
    try:
        state = await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
        assert 0.0 <= driver.clock.now() - state.time_s < 0.5
        await driver.arm()
        await wait_for_state(vehicle, lambda s: s.armed, 5.0, "armed in the simulator")
        for _ in range(5):
            await driver.send_setpoint(Setpoint.velocity_ned(0.0, 0.0, 0.0))
            await asyncio.sleep(0.05)
        await driver.disarm()
        await wait_for_state(vehicle, lambda s: not s.armed, 5.0, "disarmed in the simulator")
    finally:
        await driver.close()


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_serial_port_to_the_flight_controller(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config) as (vehicle, face), _serial_bridge(face) as device:
            # the first bytes must come from the driver: a UART has no "peer" to learn
            driver = driver_class(f"serial://{device}:921600")
            await _fly_briefly(driver, vehicle)
            assert face.stats.setpoints >= 5

    asyncio.run(main())


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_tcp_to_a_vehicle_server(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config) as (vehicle, face), _tcp_bridge(face) as url:
            await _fly_briefly(driver_class(url), vehicle)
            assert face.stats.setpoints >= 5

    asyncio.run(main())
