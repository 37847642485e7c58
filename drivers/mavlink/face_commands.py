"""The commands of the simulator's MAVLink face (COMMAND_LONG / COMMAND_INT, SET_MODE), as PX4
answers them.

Each command becomes a call on the simulated vehicle; the answer is the MAV_RESULT PX4 would
give: ACCEPTED, DENIED when the vehicle refuses (with the reason as STATUSTEXT), TEMPORARILY_
REJECTED for a mode that cannot run now (PX4's answer to such a mode switch), UNSUPPORTED for
commands the simulator does not know. MAVSDK sends NaN for parameters it does not use: they
read as "not given".
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, FlightMode, VehicleState
from drivers.geo import GlobalOrigin
from drivers.mavlink import px4
from drivers.mission import GLOBAL_FRAMES, RELATIVE_ALT_FRAMES

ACCEPTED, TEMPORARILY_REJECTED = px4.MAV_RESULT_ACCEPTED, px4.MAV_RESULT_TEMPORARILY_REJECTED
DENIED, UNSUPPORTED = px4.MAV_RESULT_DENIED, px4.MAV_RESULT_UNSUPPORTED
NAN = float("nan")

#: Commands answered by sending a message (MAV_CMD → message id).
_MESSAGE_COMMANDS = {mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
                     mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                     mavlink.MAV_CMD_GET_HOME_POSITION: mavlink.MAVLINK_MSG_ID_HOME_POSITION}


class ModeNotAvailable(CommandDenied):
    """A mode switch the vehicle cannot make now (PX4 answers TEMPORARILY_REJECTED)."""


class CommandHandler:
    """Carries out commands on ``vehicle`` (the simulator driver). ``state()`` is the newest
    telemetry sample; ``origin`` places global coordinates; ``takeoff_altitude()`` is
    MIS_TAKEOFF_ALT."""

    def __init__(self, vehicle, origin: GlobalOrigin, state) -> None:
        self.vehicle = vehicle
        self.origin = origin
        self._state = state

    async def execute(self, command: int, p: tuple[float, ...], frame: int | None = None,
                      request=None) -> int:
        """Carry out ``command`` with params ``p`` (7 values; for COMMAND_INT, ``frame`` and
        x/y as degrees·1e7 in p[4], p[5]). ``request(msg_id)`` sends a message on the link."""
        v = self.vehicle
        given = [math.isfinite(x) for x in p]
        q = tuple(x if ok else 0.0 for x, ok in zip(p, given, strict=True))
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if q[0] >= 0.5:
                await v.arm()
            else:
                await v.disarm(force=round(q[1]) == px4.FORCE_DISARM_MAGIC)
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            await v.takeoff(self._takeoff_altitude(p[6]))
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_LAND:
            await v.land()
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return await self._mode(FlightMode.RETURN)
        if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
            return await self._mode(FlightMode.HOLD)
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            return await self.set_mode(int(q[0]), int(q[1]), int(q[2]))
        if command == mavlink.MAV_CMD_MISSION_START:
            if given[0] and q[0] > 0:
                await v.set_mission_current(int(q[0]))
            return await self._mode(FlightMode.MISSION)
        if command == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT:
            if not 0 <= int(q[0]) < v.mission_status.total:
                return DENIED
            await v.set_mission_current(int(q[0]))
            return ACCEPTED
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return await self._reposition(p, frame)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            await v.set_speed(q[1] if given[1] else -1.0)
            return ACCEPTED
        if command == mavlink.MAV_CMD_DO_FLIGHTTERMINATION:
            if q[0] >= 0.5:
                await v.disarm(force=True)
            return ACCEPTED
        if command == mavlink.MAV_CMD_IMAGE_START_CAPTURE:  # p2 interval s, p3 count (0: ∞)
            await v.start_photos(q[1], int(q[2]))
            return ACCEPTED
        if command == mavlink.MAV_CMD_IMAGE_STOP_CAPTURE:
            await v.stop_photos()
            return ACCEPTED
        if command == mavlink.MAV_CMD_DO_DIGICAM_CONTROL:
            if q[4] >= 0.5:  # param5: shoot
                await v.take_photo()
            return ACCEPTED
        if command == mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
            await v.set_trigger_distance(q[0], trigger_now=q[2] >= 0.5)
            return ACCEPTED
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL or command in _MESSAGE_COMMANDS \
                or command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            if request is None:
                return UNSUPPORTED
            if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                return request.set_interval(int(q[0]), p[1] if given[1] else 0.0)
            msg_id = _MESSAGE_COMMANDS.get(command, int(q[0]))
            return ACCEPTED if request.send_now(msg_id) else UNSUPPORTED
        return UNSUPPORTED

    async def set_mode(self, base_mode: int, main: int, sub: int) -> int:
        """DO_SET_MODE / SET_MODE with PX4's custom (main, sub) mode."""
        if not base_mode & px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return UNSUPPORTED
        mode = px4.px4_mode_from_pair(main, sub)
        if mode is None:
            return UNSUPPORTED
        return await self._mode(mode)

    async def _mode(self, mode: FlightMode) -> int:
        v = self.vehicle
        state: VehicleState | None = self._state()
        if mode is FlightMode.HOLD and state is not None and state.mode is FlightMode.OFFBOARD:
            await v.stop_offboard()
            return ACCEPTED
        if mode in (FlightMode.MANUAL, FlightMode.ALTCTL, FlightMode.POSCTL):
            raise ModeNotAvailable(f"set mode {mode.value}",
                                   "manual modes need a pilot (no RC in the simulation)")
        try:
            await v.set_mode(mode)
        except CommandDenied as exc:
            raise ModeNotAvailable(exc.command, exc.reason) from None
        return ACCEPTED

    def _takeoff_altitude(self, amsl_m: float) -> float | None:
        """Takeoff height above home: PX4 reads param7 as AMSL; NaN means MIS_TAKEOFF_ALT."""
        if math.isfinite(amsl_m):
            home = self.vehicle.home()
            home_amsl = home[2] if home is not None else self.origin.alt_amsl_m
            above_home = amsl_m - home_amsl
            if above_home > 0.0:
                return above_home
        return None

    async def _reposition(self, p: tuple[float, ...], frame: int | None) -> int:
        """DO_REPOSITION (MAVSDK's goto_location): fly to a global position in HOLD."""
        lat, lon, alt = p[4], p[5], p[6]
        if frame is not None:  # COMMAND_INT: degrees × 1e7
            lat, lon = lat / 1e7, lon / 1e7
            if frame not in GLOBAL_FRAMES:
                return UNSUPPORTED
        n = e = d = NAN
        if math.isfinite(lat) and math.isfinite(lon) and (lat, lon) != (0.0, 0.0):
            n, e, _ = self.origin.to_ned(lat, lon, self.origin.alt_amsl_m)
        if math.isfinite(alt):
            if frame in RELATIVE_ALT_FRAMES:
                home = self.vehicle.home()
                d = (float(home[3][2]) if home is not None else 0.0) - alt
            else:
                d = self.origin.alt_amsl_m - alt
        speed = p[0] if math.isfinite(p[0]) and p[0] > 0 else NAN
        yaw = p[3] if math.isfinite(p[3]) else NAN
        await self.vehicle.reposition((n, e, d), yaw, speed)
        return ACCEPTED
