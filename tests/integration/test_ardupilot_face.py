"""``autopilot sim --firmware ardupilot``'s face as ArduCopter SITL, to clients written for
ArduPilot: pymavlink's own ArduPilot conveniences over TCP (SERIAL0), unmodified — the
streams, parameters and the mission protocol with home at seq 0 — and the pymavlink driver
flying on it (real time, bounded by timeouts; docs/reference/ardupilot-mavlink.md)."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from pymavlink import mavutil

from autopilot.flight_ops import wait_for_state
from drivers.base import FlightMode, Setpoint
from drivers.mavlink.face_ardupilot import ArduPilotFace, serial0_port
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from ..conftest import sim_with
from .mavtools import INSTANCE, served

pytestmark = pytest.mark.serial  # real time

SERIAL0 = serial0_port(INSTANCE)


@pytest.fixture
def copter(sim_config):
    return sim_with(sim_config, firmware="ardupilot",
                    params={"RTL_ALT": 400, "RTL_LOIT_TIME": 0})


def _connect(texts: list[str]) -> mavutil.mavfile:
    """pymavlink on SERIAL0, as MAVProxy connects; every STATUSTEXT it reads goes to
    ``texts``."""
    m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{SERIAL0}", source_system=255,
                                   dialect="ardupilotmega")
    m.message_hooks.append(lambda _, msg: texts.append(msg.text)
                           if msg.get_type() == "STATUSTEXT" else None)
    assert m.wait_heartbeat(timeout=10) is not None
    return m


def _until(m, kind, predicate, timeout_s: float, texts: list[str]):
    """The first ``kind`` message that satisfies ``predicate``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        msg = m.recv_match(type=kind, blocking=True, timeout=0.5)
        if msg is not None and predicate(msg):
            return msg
    raise AssertionError(f"no {kind} as expected within {timeout_s:g} s (texts: {texts})")


def _ack(m, command: int, texts: list[str]) -> int:
    return _until(m, "COMMAND_ACK", lambda a: a.command == command, 5.0, texts).result


def test_pymavlink_arducopter_conveniences_fly_it(copter):
    async def main():
        async with served(copter, face_class=ArduPilotFace):
            await asyncio.to_thread(_fly)

    def _fly():
        texts: list[str] = []
        m = _connect(texts)
        assert m.sysid_state[m.target_system].mav_autopilot == \
            mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert m.flightmode == "STABILIZE"
        assert "GUIDED" in m.mode_mapping()
        # Copter's SRn rates are 0: only HEARTBEAT until asked
        assert m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=1.5) is None
        m.mav.request_data_stream_send(m.target_system, m.target_component,
                                       mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
        _until(m, "GLOBAL_POSITION_INT", lambda g: True, 5.0, texts)
        # arming where ArduCopter does not allow it
        m.mav.command_long_send(m.target_system, m.target_component, 176, 0, 1, 6, 0, 0, 0,
                                0, 0)  # RTL: a mode a disarmed copter may enter
        assert _ack(m, 176, texts) == 0
        m.arducopter_arm()
        assert _ack(m, 400, texts) == 4  # FAILED
        _until(m, "HEARTBEAT", lambda h: True, 2.0, texts)
        assert any("Arm: RTL mode not armable" in t for t in texts)
        m.set_mode("GUIDED")
        assert _ack(m, 176, texts) == 0
        _until(m, "HEARTBEAT", lambda h: h.custom_mode == 4, 3.0, texts)
        _until(m, "SYS_STATUS", lambda s: s.onboard_control_sensors_health & 0x10000000, 20.0,
               texts)  # armable (the prearm bit)
        m.arducopter_arm()
        m.motors_armed_wait()
        assert m.motors_armed()
        m.mav.command_long_send(m.target_system, m.target_component, 22, 0, 0, 0, 0, 0, 0, 0,
                                3.0)
        assert _ack(m, 22, texts) == 0
        _until(m, "GLOBAL_POSITION_INT", lambda g: g.relative_alt > 2700, 20.0, texts)
        m.mav.set_position_target_local_ned_send(0, m.target_system, m.target_component, 1,
                                                 0x0DF8, 6.0, 3.0, -3.0, 0, 0, 0, 0, 0, 0, 0,
                                                 0)
        _until(m, "LOCAL_POSITION_NED", lambda p: math.hypot(p.x - 6.0, p.y - 3.0) < 0.4,
               20.0, texts)
        m.param_set_send("WPNAV_SPEED", 300.0)
        value = _until(m, "PARAM_VALUE", lambda v: v.param_id == "WPNAV_SPEED", 5.0, texts)
        assert value.param_value == 300.0
        assert value.param_type == mavutil.mavlink.MAV_PARAM_TYPE_REAL32
        m.set_mode_rtl()
        assert _ack(m, 20, texts) == 0
        m.motors_disarmed_wait()
        where = _until(m, "LOCAL_POSITION_NED", lambda p: True, 3.0, texts)
        assert math.hypot(where.x, where.y) < 1.5  # home (GNSS-grade navigation)
        assert "Arming motors" in texts
        assert "Disarming motors" in texts
        m.close()

    asyncio.run(main())


def test_parameters_and_missions_as_arducopter_speaks_them(copter):
    async def main():
        async with served(copter, face_class=ArduPilotFace) as (vehicle, _):
            await asyncio.to_thread(_talk, vehicle)

    def _talk(vehicle):
        texts: list[str] = []
        m = _connect(texts)
        m.mav.param_request_list_send(m.target_system, m.target_component)
        first = _until(m, "PARAM_VALUE", lambda v: True, 5.0, texts)
        assert texts[:2] == ["ArduCopter V4.5.7 (simulated)", "QUAD/X"]  # the banner
        assert first.param_count == len(vehicle.param_specs())
        m.mav.param_request_read_send(m.target_system, m.target_component, b"RTL_ALT", -1)
        rtl = _until(m, "PARAM_VALUE", lambda v: v.param_id == "RTL_ALT", 5.0, texts)
        assert rtl.param_value == 400.0  # cm, a float (not bytewise)
        assert rtl.param_type == mavutil.mavlink.MAV_PARAM_TYPE_INT32
        # upload: home at 0, a takeoff, a waypoint, DO_JUMP back to the waypoint (seq 2)
        origin = vehicle.global_origin
        lat, lon, _ = origin.to_global(10.0, 0.0, 0.0)
        items = [(0, 16, 0, origin.lat_deg, origin.lon_deg, 0.0, 0.0),
                 (3, 22, 0, 0.0, 0.0, 5.0, 0.0), (3, 16, 0, lat, lon, 5.0, 0.0),
                 (3, 177, 2, 0.0, 0.0, 0.0, 1.0)]
        m.waypoint_count_send(len(items))
        for _ in items:
            req = _until(m, "MISSION_REQUEST", lambda r: True, 5.0, texts)  # not _INT
            frame, command, p1, x, y, z, p2 = items[req.seq]
            m.mav.mission_item_send(m.target_system, m.target_component, req.seq, frame,
                                    command, 0, 1, p1, p2, 0, 0, x, y, z)
        ack = _until(m, "MISSION_ACK", lambda a: True, 5.0, texts)
        assert ack.type == 0
        stored = vehicle.mission_items()
        assert [i.command for i in stored] == [22, 16, 177]  # home is not flown
        assert stored[2].param1 == 1  # the jump's target, in the flown numbering
        m.waypoint_request_list_send()
        count = _until(m, "MISSION_COUNT", lambda c: True, 5.0, texts)
        assert count.count == 4
        m.waypoint_request_send(0)
        home = _until(m, "MISSION_ITEM", lambda i: i.seq == 0, 5.0, texts)
        assert home.command == 16
        assert home.frame == 0
        m.waypoint_request_send(3)
        jump = _until(m, "MISSION_ITEM", lambda i: i.seq == 3, 5.0, texts)
        assert jump.param1 == 2.0
        _until(m, "HEARTBEAT", lambda h: True, 2.0, texts)
        assert "Flight plan received" in texts
        m.close()

    asyncio.run(main())


# (MAVSDK flies an ArduCopter in CI through test_ardupilot_goals_console; here with --run-long)
@pytest.mark.parametrize("driver_class", [
    PymavlinkDriver,
    pytest.param(MavsdkDriver, id="MavsdkDriver", marks=pytest.mark.long)])
def test_both_drivers_fly_an_arducopter_from_its_firmware_profile(copter, driver_class):
    """Each driver on SERIAL0 (no stream unasked: the driver asks), the firmware known from the
    heartbeat: GUIDED takeoff, velocity targets in GUIDED, BRAKE, LAND to a disarm, and arming
    again out of LAND (not armable there: GUIDED first)."""
    async def main():
        async with served(copter, face_class=ArduPilotFace) as (vehicle, _):
            driver = driver_class(f"tcpout://127.0.0.1:{SERIAL0}")
            await driver.connect(timeout_s=10.0)
            try:
                assert driver.firmware.name == "ardupilot"
                assert driver.latest_state.mode is FlightMode.MANUAL  # STABILIZE at boot
                for flight in range(2):
                    await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
                    await driver.arm()
                    await driver.takeoff(3.0)
                    await wait_for_state(driver, lambda s: s.in_air and s.altitude_m > 2.7,
                                         30.0, f"takeoff to 3 m ({flight})")
                    assert vehicle.simulator.flight.custom_mode == 4  # GUIDED
                    start = driver.latest_state.position_ned_m.copy()
                    await driver.start_offboard()
                    for _ in range(40):
                        await driver.send_setpoint(Setpoint.velocity_ned(1.0, 0.0, 0.0,
                                                                         yaw_rad=0.0))
                        await asyncio.sleep(0.05)
                    await wait_for_state(driver, lambda s, x=start[0]: s.position_ned_m[0] > x + 1,
                                         5.0, "north in GUIDED")
                    await driver.hold()
                    await wait_for_state(driver, lambda s: s.mode is FlightMode.HOLD, 3.0,
                                         "BRAKE")
                    assert vehicle.simulator.flight.custom_mode == 17
                    await driver.land()
                    await wait_for_state(driver, lambda s: not s.armed, 60.0, "landed")
                    # it stays in LAND, where ArduCopter does not arm
                    assert vehicle.simulator.flight.custom_mode == 9
                    assert vehicle.latest_state.altitude_m < 0.3
                # the attitude is ArduCopter's Euler angles, read
                yaw_error = driver.latest_state.yaw_rad - vehicle.latest_state.yaw_rad
                assert abs(math.remainder(yaw_error, math.tau)) < 0.05
            finally:
                await driver.close()

    asyncio.run(main())
