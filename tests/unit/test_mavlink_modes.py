"""Mode semantics of the pymavlink driver: PX4 and ArduPilot Copter, on a fake link."""

from __future__ import annotations

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, CommandTimeout, FlightMode
from drivers.mavlink import ardupilot
from drivers.mavlink.firmware import MAV_AUTOPILOT_ARDUPILOTMEGA
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

PX4 = 12


@pytest.mark.parametrize(("number", "mode"), [
    (4, FlightMode.OFFBOARD), (5, FlightMode.HOLD), (17, FlightMode.HOLD),
    (9, FlightMode.LAND), (6, FlightMode.RETURN), (3, FlightMode.MISSION),
    (0, FlightMode.MANUAL), (2, FlightMode.ALTCTL), (16, FlightMode.POSCTL),
    (99, FlightMode.UNKNOWN),
])
def test_ardupilot_copter_modes_read_as_our_modes(number, mode):
    assert ardupilot.flight_mode(number) is mode


def test_ardupilot_hold_is_brake_or_loiter_and_offboard_is_guided():
    assert ardupilot.copter_mode(FlightMode.HOLD) is ardupilot.CopterMode.BRAKE
    assert ardupilot.copter_mode(FlightMode.HOLD, ardupilot.CopterMode.LOITER) \
        is ardupilot.CopterMode.LOITER
    assert ardupilot.copter_mode(FlightMode.OFFBOARD) is ardupilot.CopterMode.GUIDED
    assert ardupilot.copter_mode(FlightMode.TAKEOFF) is ardupilot.CopterMode.GUIDED
    with pytest.raises(ValueError, match="BRAKE or LOITER"):
        ardupilot.copter_mode(FlightMode.HOLD, ardupilot.CopterMode.LAND)


class FakeLink:
    """Captures what the driver sends; answers COMMAND_LONGs as a vehicle would."""

    def __init__(self, driver: PymavlinkDriver, result: int | None = 0) -> None:
        self.driver = driver
        self.mav = mavlink.MAVLink(None, srcSystem=245, srcComponent=191)
        self.vehicle = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.result = result
        self.sent = []

    def send(self, msg) -> bool:
        self.sent.append(msg)
        if msg.get_type() == "COMMAND_LONG" and self.result is not None:
            ack = self.vehicle.command_ack_encode(msg.command, self.result)
            ack.pack(self.vehicle)  # sets the header (source ids)
            asyncio.get_running_loop().call_soon(self.driver._receive, ack, ("127.0.0.1", 14580))
        return True

    def close(self) -> None:
        pass

    def commands(self):
        return [(m.command, m.param1, m.param2, m.param3, m.param7) for m in self.sent
                if m.get_type() == "COMMAND_LONG"]


def _driver(autopilot: int, result: int | None = 0, **kwargs) -> tuple[PymavlinkDriver,
                                                                        FakeLink]:
    driver = PymavlinkDriver(command_timeout_s=0.05, **kwargs)
    driver.autopilot = autopilot
    driver._target = (1, 1)
    link = driver._link = FakeLink(driver, result)
    return driver, link


def test_px4_modes_are_custom_main_sub_pairs():
    async def main():
        driver, link = _driver(PX4)
        await driver.start_offboard()
        await driver.hold()
        await driver.land()
        got = link.commands()
        assert got[:2] == [(176, 1, 6, 0, 0), (176, 1, 4, 3, 0)]
        assert got[2][0] == 21
        assert all(math.isnan(v) for v in got[2][1:])  # NAV_LAND here, as MAVSDK sends it

    asyncio.run(main())


def test_ardupilot_modes_are_copter_mode_numbers_and_takeoff_goes_through_guided():
    async def main():
        driver, link = _driver(MAV_AUTOPILOT_ARDUPILOTMEGA,
                               ardupilot_hold=ardupilot.CopterMode.LOITER)
        await driver.start_offboard()
        await driver.hold()
        await driver.land()
        await driver.takeoff(4.0)
        got = link.commands()
        assert got[:3] == [(176, 1, 4, 0, 0), (176, 1, 5, 0, 0), (176, 1, 9, 0, 0)]
        assert got[3] == (176, 1, 4, 0, 0)  # GUIDED first
        assert got[4][0] == 22
        assert got[4][4] == 4.0  # relative takeoff altitude in param7

    asyncio.run(main())


def test_refused_and_unanswered_commands_raise_typed_errors():
    async def main():
        driver, _ = _driver(PX4, result=2)
        with pytest.raises(CommandDenied, match="arm denied: denied"):
            await driver.arm()
        driver, link = _driver(PX4, result=None)
        with pytest.raises(CommandTimeout):
            await driver.arm()
        assert len(link.commands()) == driver.command_retries  # re-sent, then gave up

    asyncio.run(main())


def _state_at(position, yaw_rad):
    import numpy as np

    from drivers.base import Battery, Health, LandedState, VehicleState

    q = (math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2))
    return VehicleState(time_s=1.0, position_ned_m=np.array(position),
                        velocity_ned_m_s=np.zeros(3), attitude_q=np.array(q),
                        angular_velocity_frd_rad_s=np.zeros(3), armed=True,
                        mode=FlightMode.LAND, landed_state=LandedState.IN_AIR,
                        distance_to_ground_m=-position[2], battery=Battery(16.0, 1.0, 0.9),
                        health=Health())


def test_each_firmware_gets_the_landing_target_in_the_frame_it_takes():
    import numpy as np

    from drivers.base import LandingTarget

    async def main():
        target = LandingTarget(time_s=1.0, position_ned_m=np.array([3.0, 1.0, 0.0]))
        sent = {}
        for autopilot in (PX4, MAV_AUTOPILOT_ARDUPILOTMEGA):
            driver, link = _driver(autopilot)
            driver.latest_state = _state_at((1.0, 1.0, -4.0), math.pi / 2)  # facing east
            await driver.send_landing_target(target)
            (msg,) = [m for m in link.sent if m.get_type() == "LANDING_TARGET"]
            sent[autopilot] = msg
        px4_msg, ap = sent[PX4], sent[MAV_AUTOPILOT_ARDUPILOTMEGA]
        assert px4_msg.frame == 1  # LOCAL_NED, the target where it is
        assert (px4_msg.x, px4_msg.y, px4_msg.z) == (3.0, 1.0, 0.0)
        # ArduPilot: LOCAL_FRD from the vehicle (2 m north of it, 4 m below: facing east,
        # that is 2 m to its left), with the distance it needs without a rangefinder
        assert ap.frame == 20
        assert (ap.x, ap.y, ap.z) == pytest.approx((0.0, -2.0, 4.0), abs=1e-6)
        assert ap.distance == pytest.approx(math.hypot(2.0, 4.0))
        assert ap.position_valid == 1

    asyncio.run(main())


def test_force_disarm_and_profiles_by_autopilot():
    from drivers.mavlink.firmware import ArduCopterProfile, Px4Profile, firmware_profile

    assert type(firmware_profile(PX4)) is Px4Profile
    assert type(firmware_profile(None)) is Px4Profile  # (before any heartbeat; or generic)
    ap = firmware_profile(MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert isinstance(ap, ArduCopterProfile)
    assert (ap.force_arm_magic, ap.force_disarm_magic) == (2989, 21196)
    assert ap.attitude_from_euler
    assert not Px4Profile.attitude_from_euler

    async def main():
        driver, link = _driver(MAV_AUTOPILOT_ARDUPILOTMEGA)
        await driver.disarm(force=True)
        assert link.commands()[-1][:3] == (400, 0, 21196)

    asyncio.run(main())


def test_parameters_read_as_each_firmware_sends_them():
    import struct

    from drivers.mavlink.firmware import firmware_profile

    bits = struct.unpack("<f", struct.pack("<i", 3))[0]  # PX4: an INT32's bits in the float
    assert firmware_profile(PX4).param_value(bits, mavlink.MAV_PARAM_TYPE_INT32) == 3.0
    assert firmware_profile(PX4).param_value(0.5, mavlink.MAV_PARAM_TYPE_REAL32) == 0.5
    ap = firmware_profile(MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert ap.param_value(3.0, mavlink.MAV_PARAM_TYPE_INT8) == 3.0  # ArduPilot: a float cast


def test_arducopter_companion_parameters_are_judged_by_what_they_do():
    from drivers.mavlink.firmware import firmware_profile

    checks = {c.name: c for c in firmware_profile(MAV_AUTOPILOT_ARDUPILOTMEGA).companion_params()}
    assert set(checks) >= {"GUID_TIMEOUT", "FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "SYSID_MYGCS"}
    assert checks["GUID_TIMEOUT"].judge(3.0)[0] == "PASS"
    assert checks["GUID_TIMEOUT"].judge(5.0)[0] == "WARN"
    status, text = checks["FS_GCS_ENABLE"].judge(0.0)  # ArduCopter's default: no action
    assert status == "WARN"
    assert "GUID_TIMEOUT" in text
    assert checks["FS_GCS_ENABLE"].judge(5.0) == ("PASS", "ground station loss: Land")


def test_a_parameter_is_read_by_name():
    async def main():
        driver, link = _driver(MAV_AUTOPILOT_ARDUPILOTMEGA)
        original = link.send

        def send(msg):
            original(msg)
            if msg.get_type() == "PARAM_REQUEST_READ":
                answer = link.vehicle.param_value_encode(b"GUID_TIMEOUT", 3.0,
                                                         mavlink.MAV_PARAM_TYPE_REAL32, 900, 65535)
                answer.pack(link.vehicle)
                asyncio.get_running_loop().call_soon(driver._receive, answer,
                                                     ("127.0.0.1", 5760))
            return True

        link.send = send
        assert await driver.get_param("GUID_TIMEOUT") == 3.0
        with pytest.raises(KeyError, match="NOPE"):
            await driver.get_param("NOPE", timeout_s=0.06)  # never answered

    asyncio.run(main())


def test_arducopter_profile_arms_out_of_the_modes_arducopter_refuses():
    from drivers.mavlink.firmware import ArduCopterProfile, Px4Profile
    from drivers.sim.flight.arducopter_modes import MODES

    profile = ArduCopterProfile()
    c = ardupilot.CopterMode
    for mode in (c.LAND, c.RTL, c.BRAKE, c.AUTO, c.CIRCLE, c.SMART_RTL):
        assert profile.arming_mode(int(mode)) is FlightMode.OFFBOARD  # GUIDED first
    for mode in (c.STABILIZE, c.GUIDED, c.LOITER):
        assert profile.arming_mode(int(mode)) is None
    assert profile.arming_mode(None) is None  # no heartbeat yet: as it is
    assert Px4Profile().arming_mode(4) is None
    # the driver's knowledge and the simulated ArduCopter's agree
    assert {m for m, spec in MODES.items() if spec.gcs_arm} == \
        {m for m in ardupilot.GCS_ARMABLE if m in MODES}


def test_ekf_flags_judged_as_a_companion_flying_on_position_needs_them():
    good = 0x33F  # attitude, velocities, relative and absolute positions, above ground
    assert ardupilot.ekf_judgement(good)[0] == "PASS"
    status, text = ardupilot.ekf_judgement(0x401)  # attitude only, uninitialized
    assert status == "FAIL"
    assert "horizontal position (absolute)" in text
    assert "uninitialized" in text
    assert ardupilot.ekf_judgement(good | 0x80)[0] == "WARN"  # constant position mode
    assert ardupilot.ekf_judgement(good & ~0x10)[0] == "FAIL"  # no absolute position
