"""The simulated ArduCopter in process (``driver: sim`` with ``sim.firmware: ardupilot``): the
simulator's own driver, asking the ArduCopter firmware (:mod:`drivers.sim.flight.arducopter`)
what a MAVLink driver asks an ArduCopter — through the same firmware profile
(:class:`~drivers.mavlink.firmware.ArduCopterProfile`): a takeoff is GUIDED then NAV_TAKEOFF,
a landing the LAND mode (a precision landing only with PLND_ENABLED and PLND_TYPE 1), a
hold BRAKE. The MAVLink itself is not exercised here: ``autopilot sim --firmware ardupilot``
serves the same vehicle as ArduCopter SITL to the MAVLink drivers and to any ground station.
"""

from __future__ import annotations

from drivers.base import FlightMode
from drivers.mavlink.firmware import MAV_CMD_NAV_LAND, MAV_CMD_NAV_TAKEOFF, ArduCopterProfile
from drivers.sim.driver import SimDriver


class SimArduCopterDriver(SimDriver):
    """:class:`SimDriver` on the ArduCopter firmware, its commands as the profile sends them."""

    profile = ArduCopterProfile()

    async def _mav_command(self, name: str, command: int, *params: float) -> None:
        """A COMMAND_LONG the profile sends, carried out as the MAVLink face would."""
        if command == MAV_CMD_NAV_TAKEOFF:
            await self._command("takeoff", params[6])
        elif command == MAV_CMD_NAV_LAND:
            await self._command("land")
        else:
            raise ValueError(f"{name}: command {command} is not one the profile sends")

    async def _no_param(self, name: str, value: float) -> None:
        raise ValueError(f"the ArduCopter profile sets no parameter ({name})")

    async def takeoff(self, altitude_m: float | None = None) -> None:
        await self.profile.takeoff(self._mav_command, self.set_mode, self._no_param, altitude_m)

    async def land(self) -> None:
        await self.profile.land(self._mav_command, self.set_mode)

    async def hold(self) -> None:
        await self.set_mode(FlightMode.HOLD)

    async def precision_land(self) -> None:
        await self.profile.precision_land(self._mav_command, self.set_mode, self.get_param)

    async def precision_landing_problem(self) -> str | None:
        return await self.profile.precision_landing_problem(self.get_param)
