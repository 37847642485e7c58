"""A PX4 SITL look-alike on MAVLink 2, in front of any :class:`~drivers.base.Vehicle`.

``autopilot sim`` puts it in front of the real-time simulator, so that real MAVLink clients
(MAVSDK, MAVProxy, QGroundControl) and our own MAVLink drivers fly the simulated vehicle as
they would fly PX4 SITL. What it copies from PX4 (see ``shared/reference/px4-mavlink-sitl.md``):

* ports: it binds UDP 14580+i (offboard API) and 18570+i (ground station), sends to
  127.0.0.1:14540+i and 127.0.0.1:14550 until someone writes to it, then replies to the
  sender's address from the same socket; no SO_REUSEADDR, so a stale simulator is an error;
* identity: sysid 1, compid 1, MAVLink 2, HEARTBEAT at 1 Hz as a PX4 quadrotor, PX4 custom
  modes, ``SAFETY_ARMED`` in ``base_mode`` when armed;
* commands answered with COMMAND_ACK (arm/disarm, takeoff to ``MIS_TAKEOFF_ALT`` when the
  altitude is NaN, land, DO_SET_MODE, flight termination, message intervals and requests;
  anything else UNSUPPORTED; a refused command DENIED);
* telemetry at PX4's onboard-link rates, SYS_STATUS health bits (with PREARM_CHECK),
  HOME_POSITION, BATTERY_STATUS, DISTANCE_SENSOR, STATUSTEXT for the vehicle's events;
* offboard: SET_POSITION_TARGET_LOCAL_NED (LOCAL_NED, BODY_NED) goes to the vehicle one by one,
  never re-sent: the vehicle's own setpoint-loss failsafe acts when a client stops;
* parameters (PARAM_REQUEST_LIST / _READ / PARAM_SET, REAL32) and empty mission, fence and rally
  lists, as QGroundControl asks for them on connect;
* TIMESYNC answered with the vehicle's boot time (the clock of every ``time_boot_ms``).

Malformed, unknown and foreign-targeted messages are ignored (counted in :attr:`stats`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import struct
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import ClassVar

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, FlightMode, Vehicle, VehicleError, VehicleState
from drivers.geometry import euler_from_quat
from drivers.mavlink import px4
from drivers.mavlink.common import cancel_all
from drivers.mavlink.link import pack

log = logging.getLogger(__name__)

SYSTEM_ID = 1
COMPONENT_ID = 1
#: PX4 SITL's default home (Zurich), for GLOBAL_POSITION_INT and HOME_POSITION.
DEFAULT_HOME = (47.397742, 8.545594, 488.0)
_EARTH_RADIUS_M = 6_378_137.0

# MAV_RESULT
ACCEPTED, DENIED = px4.MAV_RESULT_ACCEPTED, px4.MAV_RESULT_DENIED
UNSUPPORTED, FAILED = px4.MAV_RESULT_UNSUPPORTED, px4.MAV_RESULT_FAILED

# MAVLink message ids we produce on request or at a rate
_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_AUTOPILOT_VERSION = mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
_HOME_POSITION = mavlink.MAVLINK_MSG_ID_HOME_POSITION

#: Default stream rates (Hz): PX4's onboard link, limited by a 50 Hz telemetry source.
DEFAULT_RATES_HZ: dict[int, float] = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,
}


@dataclass
class FaceStats:
    received: int = 0
    bad_data: int = 0
    ignored: int = 0
    commands: int = 0
    setpoints: int = 0
    rejected_setpoints: int = 0


@dataclass
class Param:
    value: float
    #: Called with the new value when a client sets it (None: stored only).
    apply: Callable[[float], None] | None = None


class _Link(asyncio.DatagramProtocol):
    """One UDP port of the vehicle: sends to ``peer`` (the last sender, or the default)."""

    def __init__(self, name: str, face: MavlinkFace, default_peer: tuple[str, int]) -> None:
        self.name = name
        self.face = face
        self.peer = default_peer
        self.heard_from: tuple[str, int] | None = None
        self.transport: asyncio.DatagramTransport | None = None
        self.mav = mavlink.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self.mav.robust_parsing = True
        self._rx = mavlink.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self._rx.robust_parsing = True

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        self.peer = self.heard_from = addr
        try:
            messages = self._rx.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises on some corrupt frames even when robust
            self.face.stats.bad_data += 1
            log.debug("%s: unparsable datagram from %s: %s", self.name, addr, exc)
            return
        for msg in messages:
            self.face._receive(self, msg)

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable
        log.debug("%s: %s", self.name, exc)

    def send(self, msg) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        self.transport.sendto(pack(self.mav, msg), self.peer)


@dataclass
class _Streams:
    rates_hz: dict[int, float] = field(default_factory=lambda: dict(DEFAULT_RATES_HZ))
    next_s: dict[int, float] = field(default_factory=dict)

    def due(self, msg_id: int, now_s: float) -> bool:
        rate = self.rates_hz.get(msg_id, 0.0)
        if rate <= 0.0:
            return False
        due_s = self.next_s.get(msg_id, 0.0)
        if now_s + 1e-6 < due_s:
            return False
        period = 1.0 / rate
        # stay on the grid, but never try to catch up on missed sends
        self.next_s[msg_id] = max(due_s + period, now_s + 0.5 * period)
        return True


class MavlinkFace:
    """Serves ``vehicle`` on MAVLink as PX4 SITL instance ``instance`` does.

    ``events`` is an optional stream of ``(time_s, text)`` status messages to forward as
    STATUSTEXT. Start with :meth:`start`, stop with :meth:`close` (it does not command the
    vehicle).
    """

    def __init__(self, vehicle: Vehicle, *, instance: int = 0, host: str = "127.0.0.1",
                 gcs_port: int = 14550, home: tuple[float, float, float] = DEFAULT_HOME,
                 takeoff_altitude_m: float = 2.5,
                 events: AsyncIterator[tuple[float, str]] | None = None) -> None:
        self.vehicle = vehicle
        self.instance = instance
        self.host = host
        self.home = home
        self.stats = FaceStats()
        self.ports = {"offboard": (14580 + instance, (host, 14540 + instance)),
                      "gcs": (18570 + instance, (host, gcs_port))}
        self.links: dict[str, _Link] = {}
        self._streams = {name: _Streams() for name in self.ports}
        self._events = events
        self._tasks: list[asyncio.Task] = []
        self._state: VehicleState | None = None
        self._boot = time.monotonic()
        self.params: dict[str, Param] = {
            "MIS_TAKEOFF_ALT": Param(takeoff_altitude_m),
            "COM_OF_LOSS_T": Param(0.5),
            "COM_OBL_RC_ACT": Param(0.0),
            "NAV_DLL_ACT": Param(0.0),
            "MPC_XY_VEL_MAX": Param(12.0),
            "MPC_Z_VEL_MAX_UP": Param(3.0),
            "MPC_Z_VEL_MAX_DN": Param(1.5),
            "MAV_SYS_ID": Param(float(SYSTEM_ID)),
            "SYS_AUTOSTART": Param(10016.0),
        }

    # ------------------------------------------------------------------------------------
    # Life cycle
    # ------------------------------------------------------------------------------------

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        for name, (port, peer) in self.ports.items():
            link = _Link(name, self, peer)
            try:
                await loop.create_datagram_endpoint(lambda link=link: link,
                                                    local_addr=("0.0.0.0", port))
            except OSError as exc:
                await self.close()
                raise OSError(f"cannot bind UDP port {port} for the {name} link: {exc} "
                              "(is another simulator or PX4 SITL running?)") from exc
            self.links[name] = link
        self._tasks = [loop.create_task(self._heartbeats(), name="mavlink-heartbeat"),
                       loop.create_task(self._telemetry(), name="mavlink-telemetry")]
        if self._events is not None:
            self._tasks.append(loop.create_task(self._statustext(), name="mavlink-events"))

    async def close(self) -> None:
        await cancel_all(self._tasks)
        self._tasks = []
        for link in self.links.values():
            if link.transport is not None:
                link.transport.close()
        self.links = {}

    # ------------------------------------------------------------------------------------
    # Outgoing
    # ------------------------------------------------------------------------------------

    def _boot_ms(self, time_s: float | None = None) -> int:
        t = time.monotonic() - self._boot if time_s is None else time_s
        return max(0, int(t * 1000.0)) & 0xFFFFFFFF

    def _send_all(self, make) -> None:
        for link in self.links.values():
            link.send(make(link.mav))

    async def _heartbeats(self) -> None:
        while True:
            self._send_all(self._heartbeat)
            await asyncio.sleep(1.0)

    def _heartbeat(self, mav):
        s = self._state
        armed = s is not None and s.armed
        base = px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (px4.MAV_MODE_FLAG_SAFETY_ARMED
                                                        if armed else 0)
        custom = px4.px4_custom_mode(s.mode) if s is not None else 0
        status = (px4.MAV_STATE_CRITICAL if s is not None and s.failsafe else
                  px4.MAV_STATE_ACTIVE if armed else px4.MAV_STATE_STANDBY)
        return mav.heartbeat_encode(px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4, base, custom,
                                    status)

    async def _telemetry(self) -> None:
        async with contextlib.aclosing(self.vehicle.telemetry()) as samples:
            async for state in samples:
                self._state = state
                for name, link in self.links.items():
                    streams = self._streams[name]
                    for msg_id in streams.rates_hz:
                        if streams.due(msg_id, state.time_s):
                            try:
                                msg = self._message(msg_id, link.mav, state)
                            except (ValueError, OverflowError, struct.error):
                                # a value MAVLink cannot carry (NaN, out of range): skip this
                                # one message, never the stream
                                log.debug("cannot encode message %d", msg_id, exc_info=True)
                                continue
                            if msg is not None:
                                link.send(msg)

    async def _statustext(self) -> None:
        assert self._events is not None
        async with contextlib.aclosing(self._events) as events:
            async for _, text in events:
                self._send_all(lambda mav, text=text: mav.statustext_encode(
                    6, _statustext(text)))  # MAV_SEVERITY_INFO

    def _message(self, msg_id: int, mav, s: VehicleState | None):
        """Encode message ``msg_id`` from telemetry sample ``s`` (None if not possible)."""
        if msg_id == _AUTOPILOT_VERSION:
            return self._autopilot_version(mav)
        if s is None:
            return None
        t_ms = self._boot_ms(s.time_s)
        n, e, d = (float(v) for v in s.position_ned_m)
        vn, ve, vd = (float(v) for v in s.velocity_ned_m_s)
        p, q, r = (float(v) for v in s.angular_velocity_frd_rad_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return mav.attitude_quaternion_encode(t_ms, *(float(v) for v in s.attitude_q),
                                                  p, q, r)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            roll, pitch, yaw = euler_from_quat(s.attitude_q)
            return mav.attitude_encode(t_ms, roll, pitch, yaw, p, q, r)
        if msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return mav.local_position_ned_encode(t_ms, n, e, d, vn, ve, vd)
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            lat, lon, alt = self._global(n, e, d)
            hdg = round(math.degrees(s.yaw_rad) % 360.0 * 100.0) % 36000
            return mav.global_position_int_encode(
                t_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                round(-d * 1000), round(vn * 100), round(ve * 100),
                round(vd * 100), hdg)
        if msg_id == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return mav.extended_sys_state_encode(0, px4.LANDED_STATES[s.landed_state])
        if msg_id == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            return self._sys_status(mav, s)
        if msg_id == mavlink.MAVLINK_MSG_ID_BATTERY_STATUS:
            b = s.battery
            cells = [int(b.voltage_v * 1000)] + [65535] * 9
            return mav.battery_status_encode(0, 1, 1, 32767, cells, int(b.current_a * 100), -1,
                                             -1, round(b.remaining_fraction * 100))
        if msg_id == _HOME_POSITION:
            lat, lon, alt = self.home
            return mav.home_position_encode(int(lat * 1e7), int(lon * 1e7), int(alt * 1000),
                                            0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)
        if msg_id == mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR:
            dist = s.distance_to_ground_m
            cm = 65535 if not math.isfinite(dist) else round(dist * 100)
            # MAV_DISTANCE_SENSOR_LASER 0, orientation MAV_SENSOR_ROTATION_PITCH_270 (down) 25
            return mav.distance_sensor_encode(t_ms, 10, 4000, cm, 0, 0, 25, 0)
        return None

    def _global(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        lat0, lon0, alt0 = self.home
        lat = lat0 + math.degrees(n / _EARTH_RADIUS_M)
        lon = lon0 + math.degrees(e / (_EARTH_RADIUS_M * math.cos(math.radians(lat0))))
        return lat, lon, alt0 - d

    def _sys_status(self, mav, s: VehicleState):
        h = s.health
        present = (px4.SENSOR_GYRO | px4.SENSOR_ACCEL | px4.SENSOR_MAG | px4.SENSOR_ABS_PRESSURE
                   | px4.SENSOR_GPS | px4.SENSOR_MOTOR_OUTPUTS | px4.SENSOR_BATTERY
                   | px4.SENSOR_PREARM_CHECK)
        healthy = px4.SENSOR_GEOFENCE  # no fence, so never breached (MAVProxy reads this bit)
        for ok, bit in ((h.gyro_ok, px4.SENSOR_GYRO), (h.accel_ok, px4.SENSOR_ACCEL),
                        (h.mag_ok, px4.SENSOR_MAG), (True, px4.SENSOR_ABS_PRESSURE),
                        (h.local_position_ok, px4.SENSOR_GPS), (True, px4.SENSOR_MOTOR_OUTPUTS),
                        (h.battery_ok, px4.SENSOR_BATTERY), (h.armable, px4.SENSOR_PREARM_CHECK)):
            if ok:
                healthy |= bit
        b = s.battery
        return mav.sys_status_encode(present, present, healthy, 0, int(b.voltage_v * 1000),
                                     int(b.current_a * 100), round(b.remaining_fraction
                                                                       * 100),
                                     0, 0, 0, 0, 0, 0)

    def _autopilot_version(self, mav):
        caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # 1.15.0, FIRMWARE_VERSION_TYPE_OFFICIAL
        return mav.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                            0, 0, 0x5349_4D00 + self.instance)

    # ------------------------------------------------------------------------------------
    # Incoming
    # ------------------------------------------------------------------------------------

    def _receive(self, link: _Link, msg) -> None:
        self.stats.received += 1
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.stats.bad_data += 1
            return
        target = getattr(msg, "target_system", SYSTEM_ID)
        if target not in (0, SYSTEM_ID):
            self.stats.ignored += 1
            return
        handler = self._handlers.get(kind)
        if handler is None:
            self.stats.ignored += 1
            return
        try:
            handler(self, link, msg)
        except Exception:  # a message we cannot act on must never take the vehicle down
            self.stats.ignored += 1
            log.warning("ignoring %s from %s", kind, link.peer, exc_info=True)

    def _on_command(self, link: _Link, msg) -> None:
        self.stats.commands += 1
        if msg.get_type() == "COMMAND_INT":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
        else:
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                      msg.param7)
        task = asyncio.get_running_loop().create_task(self._command(link, msg, params))
        self._tasks.append(task)
        task.add_done_callback(lambda t: t in self._tasks and self._tasks.remove(t))

    async def _command(self, link: _Link, msg, params: tuple[float, ...]) -> None:
        command = msg.command
        try:
            result = await self._execute(link, command, params)
        except CommandDenied as exc:
            log.info("command %d denied: %s", command, exc.reason)
            link.send(link.mav.statustext_encode(4, _statustext(exc.reason)))
            result = DENIED
        except VehicleError as exc:
            log.warning("command %d failed: %s", command, exc)
            result = FAILED
        except Exception:  # a command we cannot read must still be answered
            log.warning("command %d failed", command, exc_info=True)
            result = FAILED
        link.send(link.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(),
                                              msg.get_srcComponent()))

    async def _execute(self, link: _Link, command: int, p: tuple[float, ...]) -> int:
        """Carry out a command. MAVSDK sends NaN for parameters it does not use: those read
        as 0 where a number is needed (the takeoff altitude keeps its NaN meaning)."""
        v = self.vehicle
        p = tuple(x if math.isfinite(x) or i == 6 else 0.0 for i, x in enumerate(p))
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] >= 0.5:
                await v.arm()
            else:
                await v.disarm(force=round(p[1]) == px4.FORCE_DISARM_MAGIC)
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            await v.takeoff(self._takeoff_altitude(p[6]))
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_LAND:
            await v.land()
            return ACCEPTED
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            return await self._set_mode(p)
        if command == mavlink.MAV_CMD_DO_FLIGHTTERMINATION:
            if p[0] >= 0.5:
                await v.disarm(force=True)
            return ACCEPTED
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(link, int(p[0]), p[1])
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            return self._send_requested(link, int(p[0]))
        if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return self._send_requested(link, _AUTOPILOT_VERSION)
        return UNSUPPORTED

    def _takeoff_altitude(self, amsl_m: float) -> float:
        """Takeoff height above home: PX4 reads param7 as AMSL; NaN means MIS_TAKEOFF_ALT."""
        if math.isfinite(amsl_m):
            above_home = amsl_m - self.home[2]
            if above_home > 0.0:
                return above_home
        return self.params["MIS_TAKEOFF_ALT"].value

    async def _set_mode(self, p: tuple[float, ...]) -> int:
        if not int(p[0]) & px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return UNSUPPORTED
        mode = px4.px4_mode_from_pair(int(p[1]), int(p[2]))
        v = self.vehicle
        if mode is FlightMode.HOLD:
            if self._state is not None and self._state.mode is FlightMode.OFFBOARD:
                await v.stop_offboard()
            else:
                await v.hold()
        elif mode is FlightMode.OFFBOARD:
            await v.start_offboard()
        elif mode is FlightMode.LAND:
            await v.land()
        elif mode is FlightMode.TAKEOFF:
            await v.takeoff(self.params["MIS_TAKEOFF_ALT"].value)
        else:
            return DENIED  # manual, position, mission and return modes are not simulated
        return ACCEPTED

    def _set_interval(self, link: _Link, msg_id: int, interval_us: float) -> int:
        streams = self._streams[link.name]
        if msg_id not in DEFAULT_RATES_HZ and msg_id != _HEARTBEAT:
            return UNSUPPORTED
        if msg_id == _HEARTBEAT:
            return ACCEPTED  # fixed at 1 Hz, as PX4
        if interval_us == 0:
            streams.rates_hz[msg_id] = DEFAULT_RATES_HZ[msg_id]
        elif interval_us < 0:
            streams.rates_hz[msg_id] = 0.0
        else:
            streams.rates_hz[msg_id] = 1e6 / interval_us
        streams.next_s.pop(msg_id, None)
        return ACCEPTED

    def _send_requested(self, link: _Link, msg_id: int) -> int:
        msg = self._message(msg_id, link.mav, self._state)
        if msg is None:
            return UNSUPPORTED
        link.send(msg)
        return ACCEPTED

    def _on_setpoint(self, link: _Link, msg) -> None:
        try:
            setpoint = px4.setpoint_from_mavlink(
                msg.coordinate_frame, msg.type_mask, (msg.x, msg.y, msg.z),
                (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate)
        except px4.SetpointNotSupported as exc:
            self.stats.rejected_setpoints += 1
            log.debug("setpoint ignored: %s", exc)
            return
        self.stats.setpoints += 1
        task = asyncio.get_running_loop().create_task(self.vehicle.send_setpoint(setpoint))
        task.add_done_callback(_log_failure)

    def _on_param_request_list(self, link: _Link, msg) -> None:
        for index, name in enumerate(self.params):
            self._send_param(link, name, index)

    def _on_param_request_read(self, link: _Link, msg) -> None:
        names = list(self.params)
        name = _param_name(msg.param_id)
        if msg.param_index >= 0:
            if msg.param_index >= len(names):
                return
            name = names[msg.param_index]
        if name in self.params:
            self._send_param(link, name, names.index(name))

    def _on_param_set(self, link: _Link, msg) -> None:
        name = _param_name(msg.param_id)
        param = self.params.get(name)
        if param is None or not math.isfinite(msg.param_value):
            return  # PX4 answers nothing for unknown parameters
        param.value = float(msg.param_value)
        if param.apply is not None:
            param.apply(param.value)
        self._send_param(link, name, list(self.params).index(name))

    def _send_param(self, link: _Link, name: str, index: int) -> None:
        link.send(link.mav.param_value_encode(name.encode(), self.params[name].value,
                                              mavlink.MAV_PARAM_TYPE_REAL32, len(self.params),
                                              index))

    def _on_mission_request_list(self, link: _Link, msg) -> None:
        link.send(link.mav.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                getattr(msg, "mission_type", 0)))

    def _on_timesync(self, link: _Link, msg) -> None:
        """MAVLink time synchronisation: answer a request (tc1 = 0) with our boot time."""
        if msg.tc1 == 0:
            now_ns = int(self.vehicle.clock.now() * 1e9)
            link.send(link.mav.timesync_encode(now_ns, msg.ts1))

    def _ignore(self, link: _Link, msg) -> None:
        pass

    _handlers: ClassVar[dict[str, Callable[[MavlinkFace, _Link, object], None]]] = {
        "COMMAND_LONG": _on_command,
        "COMMAND_INT": _on_command,
        "SET_POSITION_TARGET_LOCAL_NED": _on_setpoint,
        "PARAM_REQUEST_LIST": _on_param_request_list,
        "PARAM_REQUEST_READ": _on_param_request_read,
        "PARAM_SET": _on_param_set,
        "MISSION_REQUEST_LIST": _on_mission_request_list,
        "TIMESYNC": _on_timesync,
        "HEARTBEAT": _ignore,
    }


def _statustext(text: str) -> bytes:
    """STATUSTEXT's 50 characters, in ASCII (ground stations show other bytes as garbage)."""
    return text.replace("→", "->").encode("ascii", "replace")[:50]


def _param_name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode(errors="replace")
    return raw.rstrip("\x00")


def _log_failure(task: asyncio.Task) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.warning("setpoint not delivered: %s", task.exception())
