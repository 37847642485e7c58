"""The simulator's MAVLink face, end to end with real MAVLink clients on loopback.

These run the simulator in real time (a MAVLink client cannot be put on a lockstep clock), so
they are bounded by generous timeouts rather than timed: a slow machine takes longer, it does
not fail, as long as it keeps up with real time.
"""

from __future__ import annotations

import asyncio
import math
import socket
import struct

import pytest
from pymavlink.dialects.v20 import common as mavlink

from drivers.base import FlightMode
from drivers.mavlink import px4

from .mavtools import INSTANCE, served

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time


async def _first(gen, predicate, what: str, timeout_s: float = 30.0):
    async with asyncio.timeout(timeout_s):
        async for value in gen:
            if predicate(value):
                return value
    raise AssertionError(f"stream ended before {what}")


@pytest.mark.long  # (MAVSDK's own examples fly the same calls in CI: test_mavsdk_examples)
def test_mavsdk_flies_the_simulator_connect_arm_takeoff_offboard_land_disarm(no_camera_config):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    async def main():
        async with served(no_camera_config) as (vehicle, face):
            cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
            async with Mavsdk(cfg) as mav:
                await mav.add_any_connection(f"udpin://0.0.0.0:{14540 + INSTANCE}")
                system = await mav.first_autopilot(timeout_s=15.0)
                assert system is not None, "MAVSDK did not discover the simulated autopilot"
                tel, action = TelemetryAsync(system), ActionAsync(system)
                offboard = OffboardAsync(system)
                await _first(tel.subscribe_health_all_ok(), bool, "healthy")
                await action.set_takeoff_altitude(3.0)
                assert vehicle.param("MIS_TAKEOFF_ALT") == pytest.approx(3.0)
                await action.arm()
                await action.takeoff()
                pv = await _first(tel.subscribe_position_velocity_ned(),
                                  lambda p: -p.position.down_m > 2.7, "climbing to 3 m")
                await _first(tel.subscribe_flight_mode(), lambda m: m.name == "HOLD",
                             "HOLD after takeoff")
                north0 = pv.position.north_m
                await offboard.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
                # PX4 wants the setpoint stream alive before OFFBOARD (MAVSDK streams at 20 Hz)
                await asyncio.sleep(0.5)
                await offboard.start()
                await _first(tel.subscribe_flight_mode(), lambda m: m.name == "OFFBOARD",
                             "OFFBOARD", timeout_s=5.0)
                await _first(tel.subscribe_position_velocity_ned(),
                             lambda p: p.position.north_m > north0 + 1.5, "flying north")
                await offboard.stop()
                await action.land()
                await _first(tel.subscribe_armed(), lambda armed: not armed,
                             "landed and disarmed", timeout_s=60.0)
            assert vehicle.latest_state.altitude_m < 0.3
            assert face.stats.setpoints > 0

    asyncio.run(main())


class _Client:
    """A bare pymavlink client on a UDP socket (for what MAVSDK does not let us send)."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.rx = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.rx.robust_parsing = True
        self.addr = ("127.0.0.1", 14580 + INSTANCE)
        # a ground station's heartbeat: the vehicle replies to whoever wrote to it
        self.send(self.mav.heartbeat_encode(6, 8, 0, 0, 0))

    def send(self, msg_or_bytes) -> None:
        data = msg_or_bytes if isinstance(msg_or_bytes, bytes) else msg_or_bytes.pack(self.mav)
        self.sock.sendto(data, self.addr)

    async def receive(self, kind: str, predicate=lambda m: True, timeout_s: float = 10.0):
        loop = asyncio.get_running_loop()
        async with asyncio.timeout(timeout_s):
            while True:
                data = await loop.sock_recv(self.sock, 4096)
                for msg in self.rx.parse_buffer(data) or []:
                    if msg.get_type() == kind and predicate(msg):
                        return msg

    async def command(self, command: int, *params: float) -> int:
        p = [*params, *[0.0] * (7 - len(params))]
        self.send(self.mav.command_long_encode(1, 1, command, 0, *p))
        ack = await self.receive("COMMAND_ACK", lambda m: m.command == command)
        return ack.result

    def close(self) -> None:
        self.sock.close()


def test_garbage_and_unknown_messages_are_ignored_and_commands_answered(no_camera_config):
    async def main():
        async with served(no_camera_config) as (vehicle, face):
            client = _Client()
            try:
                client.send(b"\xfd\x09\x00\x00\x00garbage that is not mavlink")
                client.send(b"\xfe\x05\x00\x01\x01\x00\x01\x02\x03\x04\x05\x00\x00")  # bad CRC
                client.send(client.mav.debug_encode(0, 1, 2.0))  # valid, but not for a vehicle
                client.send(client.mav.command_long_encode(42, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
                # still alive, and answering: unknown command → UNSUPPORTED
                assert await client.command(31999) == 3
                # DO_SET_MODE to a mode the simulator cannot fly (POSCTL needs a pilot)
                assert await client.command(176, 1, 3, 0) == 1  # TEMPORARILY_REJECTED
                # a request for AUTOPILOT_VERSION is answered with the message and an ACK
                assert await client.command(512, 148) == 0
                assert face.stats.bad_data >= 1
                assert face.stats.ignored >= 2
                assert vehicle.latest_state.armed is False  # the foreign-targeted arm ignored
            finally:
                client.close()

    asyncio.run(main())


def test_arming_refused_while_unhealthy_is_denied_with_a_reason(no_camera_config):
    async def main():
        async with served(no_camera_config) as (vehicle, _face):
            client = _Client()
            try:
                hb = await client.receive("HEARTBEAT")
                assert (hb.type, hb.autopilot) == (px4.MAV_TYPE_QUADROTOR,
                                                   px4.MAV_AUTOPILOT_PX4)
                await _wait_armable(client)
                await vehicle.inject_failure("gyro")
                status = await client.receive(
                    "SYS_STATUS", lambda m: not m.onboard_control_sensors_health & px4.SENSOR_GYRO)
                assert not status.onboard_control_sensors_health & px4.SENSOR_PREARM_CHECK
                assert await client.command(400, 1) == 2
                await vehicle.inject_failure("gyro", False)
                await _wait_armable(client)
                assert await client.command(400, 1) == 0
                hb = await client.receive(
                    "HEARTBEAT", lambda m: m.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED)
                assert px4.px4_flight_mode(hb.custom_mode) is FlightMode.HOLD
                # MAVSDK sends NaN for the parameters it does not use
                assert await client.command(400, 0, math.nan) == 0
                # every message carries the next sequence number
                first = await client.receive("ATTITUDE")
                second = await client.receive("ATTITUDE")
                assert second.get_seq() != first.get_seq()
            finally:
                client.close()

    asyncio.run(main())


async def _wait_armable(client: _Client) -> None:
    await client.receive("SYS_STATUS", lambda m: m.onboard_control_sensors_health
                         & px4.SENSOR_PREARM_CHECK, timeout_s=30.0)


def test_setpoints_stop_and_the_vehicle_lands_per_com_obl_rc_act(no_camera_config):
    """The face never re-sends a setpoint: when the client goes silent, PX4's offboard loss
    failsafe acts after COM_OF_LOSS_T, as COM_OBL_RC_ACT says (4: land)."""
    async def main():
        async with served(no_camera_config) as (_vehicle, _face):
            client = _Client()
            try:
                await _wait_armable(client)
                # an INT32 parameter travels bytewise, as PX4 sends it
                client.send(client.mav.param_set_encode(
                    1, 1, b"COM_OBL_RC_ACT", struct.unpack("<f", struct.pack("<i", 4))[0],
                    mavlink.MAV_PARAM_TYPE_INT32))
                echo = await client.receive("PARAM_VALUE",
                                            lambda m: m.param_id == "COM_OBL_RC_ACT")
                assert struct.unpack("<i", struct.pack("<f", echo.param_value))[0] == 4
                assert await client.command(400, 1) == 0
                assert await client.command(22, *[math.nan] * 7) == 0
                await client.receive("EXTENDED_SYS_STATE", lambda m: m.landed_state == 2,
                                     timeout_s=30.0)
                await client.receive("HEARTBEAT",
                                     lambda m: px4.px4_flight_mode(m.custom_mode)
                                     is FlightMode.HOLD, timeout_s=30.0)
                frame, mask, pos, vel, yaw, rate, _acc = px4.setpoint_to_mavlink(
                    px4.setpoint_from_mavlink(1, 0xDC7, (0, 0, 0), (0.5, 0, 0), 0, 0))
                for _ in range(15):
                    client.send(client.mav.set_position_target_local_ned_encode(
                        0, 1, 1, frame, mask, *pos, *vel, 0, 0, 0, yaw, rate))
                    await asyncio.sleep(0.05)
                assert await client.command(176, 129, 6, 0) == 0
                await client.receive("HEARTBEAT", lambda m: px4.px4_flight_mode(m.custom_mode)
                                     is FlightMode.OFFBOARD, timeout_s=2.0)
                # silence: LAND once the newest setpoint is older than COM_OF_LOSS_T
                await client.receive("HEARTBEAT", lambda m: px4.px4_flight_mode(m.custom_mode)
                                     is FlightMode.LAND, timeout_s=3.0)
            finally:
                client.close()

    asyncio.run(main())
