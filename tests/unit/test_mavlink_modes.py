"""Mode semantics of the pymavlink driver: PX4 and ArduPilot Copter, on a fake link."""

from __future__ import annotations

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, CommandTimeout, FlightMode
from drivers.mavlink import ardupilot
from drivers.mavlink.pymavlink_driver import MAV_AUTOPILOT_ARDUPILOTMEGA, PymavlinkDriver

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
