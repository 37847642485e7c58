"""A :class:`~drivers.base.Vehicle` over plain MAVLink (pymavlink's message set), for PX4 and
ArduPilot Copter.

Everything runs on the event loop: one link (:mod:`drivers.mavlink.link`: UDP, TCP or a serial
port; locked onto the vehicle; signed with a key), messages parsed as they arrive, commands sent
as COMMAND_LONG and matched to their COMMAND_ACK (re-sent up to ``command_retries`` times, as
MAVSDK does). The first autopilot heard is the vehicle: messages from other systems on the link
are ignored (one log line), and TIMESYNC answers count only if they echo our own requests.
Telemetry is assembled from HEARTBEAT, attitude, LOCAL_POSITION_NED, EXTENDED_SYS_STATE,
SYS_STATUS, BATTERY_STATUS and DISTANCE_SENSOR; a
:class:`~drivers.base.VehicleState` is published on every LOCAL_POSITION_NED, stamped with its
capture time mapped from the vehicle's ``time_boot_ms`` onto the local monotonic clock.

Mode semantics by autopilot (from HEARTBEAT):

* PX4: DO_SET_MODE with PX4 custom main/sub modes; takeoff sets ``MIS_TAKEOFF_ALT`` and sends
  NAV_TAKEOFF with NaN altitude, as MAVSDK does; offboard is PX4 OFFBOARD.
* ArduPilot Copter: DO_SET_MODE with Copter mode numbers; takeoff switches to GUIDED and sends
  NAV_TAKEOFF with the relative altitude; offboard is GUIDED; hold is BRAKE (or LOITER).

Setpoints go out one SET_POSITION_TARGET_LOCAL_NED per :meth:`send_setpoint`, never re-sent:
if the caller stalls or dies, the stream stops and the vehicle's failsafe acts.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import deque

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import (
    Battery,
    CommandDenied,
    CommandTimeout,
    ConnectionLost,
    FlightMode,
    Health,
    LandingTarget,
    Setpoint,
    VehicleNotFound,
)
from drivers.mavlink import ardupilot, px4
from drivers.mavlink.common import MavlinkVehicle, cancel_all
from drivers.mavlink.link import MavlinkLink, TimesyncRequests, unheard
from drivers.mavlink.signing import Signing

log = logging.getLogger(__name__)

MAV_AUTOPILOT_INVALID = 8
#: MAV_COMP_ID_AUTOPILOT1: the flight controller (a gimbal or camera heartbeats too)
AUTOPILOT_COMPONENT = 1
#: Streams asked for on connect (message id → Hz).
class PymavlinkDriver(MavlinkVehicle):
    def __init__(self, url: str = "udpin://127.0.0.1:14540", *,
                 heartbeat_timeout_s: float = 3.0, command_timeout_s: float = 0.5,
                 command_retries: int = 3,
                 ardupilot_hold: ardupilot.CopterMode = ardupilot.CopterMode.BRAKE,
                 signing: Signing | None = None) -> None:
        super().__init__(ardupilot_hold)
        self.url = url
        self.signing = signing
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.command_timeout_s = command_timeout_s
        self.command_retries = command_retries
        self._link: MavlinkLink | None = None
        self._timesync_sent = TimesyncRequests()
        self._ignored_systems: set[tuple[int, int]] = set()
        self._target: tuple[int, int] | None = None  # (system, component) of the autopilot
        self.autopilot: int | None = None  # MAV_AUTOPILOT of the vehicle
        self._acks: dict[int, asyncio.Future] = {}
        self._params: dict[str, asyncio.Future] = {}
        self._statustext: deque[str] = deque(maxlen=8)
        self._heard = asyncio.Event()
        self._last_heartbeat_s = -math.inf
        self._tasks: list[asyncio.Task] = []
        self._closed_error: ConnectionLost | None = None

    # ------------------------------------------------------------------------------------
    # Vehicle interface
    # ------------------------------------------------------------------------------------

    async def connect(self, timeout_s: float = 10.0) -> None:
        if self._link is not None:
            return
        self._link = await MavlinkLink.open(self.url, self._receive, signing=self.signing)
        loop = asyncio.get_running_loop()
        self._tasks = [loop.create_task(self._heartbeats(), name="mavlink-gcs-heartbeat"),
                       loop.create_task(self._watchdog(), name="mavlink-watchdog"),
                       loop.create_task(self._timesync(), name="mavlink-timesync")]
        try:
            await asyncio.wait_for(self._heard.wait(), timeout_s)
        except TimeoutError:
            message = unheard(f"no autopilot heartbeat on {self.url} within {timeout_s:g} s",
                              self._link)
            await self.close()
            raise VehicleNotFound(message) from None
        except BaseException:
            await self.close()
            raise
        for msg_id, rate in self._stream_requests().items():
            self._send(self._command_long_msg(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                              msg_id, 1e6 / rate))
        # as a real link: connected once a telemetry sample has arrived
        async with contextlib.aclosing(self.telemetry()) as samples:
            try:
                await asyncio.wait_for(anext(samples), timeout_s)
            except (TimeoutError, StopAsyncIteration):
                await self.close()
                raise VehicleNotFound(f"no LOCAL_POSITION_NED from the vehicle on {self.url} "
                                     f"within {timeout_s:g} s") from None
            except BaseException:
                await self.close()
                raise

    async def arm(self) -> None:
        mode = self.firmware.arming_mode(self._custom_mode)
        if mode is not None:  # the vehicle arms only in some modes: into one first
            await self._set_mode(mode)
        await self._command("arm", mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    async def disarm(self, *, force: bool = False) -> None:
        await self._command("disarm", mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                            self.firmware.force_disarm_magic if force else 0)

    async def takeoff(self, altitude_m: float | None = None) -> None:
        await self.firmware.takeoff(self._command, self._set_mode, self.set_param, altitude_m)

    async def land(self) -> None:
        await self.firmware.land(self._command, self._set_mode)

    async def hold(self) -> None:
        await self._set_mode(FlightMode.HOLD)

    async def return_to_launch(self) -> None:
        await self._set_mode(FlightMode.RETURN)

    async def precision_land(self) -> None:
        await self.firmware.precision_land(self._command, self._set_mode, self.get_param)

    async def precision_landing_problem(self) -> str | None:
        return await self.firmware.precision_landing_problem(self.get_param)

    async def send_landing_target(self, target: LandingTarget) -> None:
        self._check_alive()
        report = self.firmware.landing_target(target, self.latest_state)
        if report is None:
            return  # (not yet expressible: no telemetry to place it against)
        self._send(self._link.mav.landing_target_encode(
            int(self._clock.now() * 1e6), target.target_num, report.frame,
            0.0, 0.0, report.distance_m, 0.0, 0.0, *report.position_m,
            [1.0, 0.0, 0.0, 0.0], 0, 1))

    async def start_offboard(self) -> None:
        await self._set_mode(FlightMode.OFFBOARD)

    async def stop_offboard(self) -> None:
        await self._set_mode(FlightMode.HOLD)

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        self._check_alive()
        frame, mask, pos, vel, yaw, rate, acc = px4.setpoint_to_mavlink(setpoint)
        system, component = self._require_target()
        self._send(self._link.mav.set_position_target_local_ned_encode(
            self._boot_ms(), system, component, frame, mask, *pos, *vel, *acc, yaw,
            rate))

    async def close(self) -> None:
        await cancel_all(self._tasks)
        self._tasks = []
        await self._close_cameras()
        if self._link is not None:
            self._link.close()
            self._link = None
            await asyncio.sleep(0)  # the transport lets go of its socket on the next turn
        self._end_telemetry(self._closed_error)

    # ------------------------------------------------------------------------------------
    # Extras
    # ------------------------------------------------------------------------------------


    async def set_param(self, name: str, value: float, timeout_s: float = 2.0) -> None:
        """PARAM_SET (REAL32) and wait for the vehicle's PARAM_VALUE echo."""
        system, component = self._require_target()
        loop = asyncio.get_running_loop()
        for _ in range(self.command_retries):
            future = self._params[name] = loop.create_future()
            self._send(self._link.mav.param_set_encode(system, component, name.encode(),
                                                       float(value),
                                                       mavlink.MAV_PARAM_TYPE_REAL32))
            try:
                echoed = await asyncio.wait_for(future, timeout_s / self.command_retries)
            except TimeoutError:
                continue
            if not math.isclose(echoed, value, rel_tol=1e-6, abs_tol=1e-6):
                raise CommandDenied(f"set {name}", f"vehicle kept {echoed}")
            return
        raise CommandTimeout(f"set {name}", timeout_s)

    async def get_param(self, name: str, timeout_s: float = 2.0) -> float:
        """PARAM_REQUEST_READ by name and the vehicle's PARAM_VALUE (KeyError if it never
        answers: no such parameter)."""
        system, component = self._require_target()
        loop = asyncio.get_running_loop()
        for _ in range(self.command_retries):
            future = self._params[name] = loop.create_future()
            self._send(self._link.mav.param_request_read_encode(system, component,
                                                                name.encode(), -1))
            try:
                return await asyncio.wait_for(future, timeout_s / self.command_retries)
            except TimeoutError:
                continue
        raise KeyError(f"{name}: the vehicle did not answer (no such parameter?)")

    # ------------------------------------------------------------------------------------
    # Internals: sending
    # ------------------------------------------------------------------------------------

    def _check_alive(self) -> None:
        if self._closed_error is not None:
            raise self._closed_error
        if self._link is None:
            raise ConnectionLost("not connected: call connect() first")

    def _require_target(self) -> tuple[int, int]:
        self._check_alive()
        if self._target is None:
            raise ConnectionLost("no autopilot heard yet")
        return self._target

    def _send(self, msg) -> None:
        if self._link is not None:
            self._link.send(msg)

    def _boot_ms(self) -> int:
        return int(self._clock.now() * 1000.0) & 0xFFFFFFFF

    def _command_long_msg(self, command: int, *params: float, confirmation: int = 0):
        system, component = self._target or (1, 1)
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        return self._link.mav.command_long_encode(system, component, command, confirmation, *p)

    async def _command(self, name: str, command: int, *params: float) -> None:
        self._require_target()
        loop = asyncio.get_running_loop()
        older = self._acks.get(command)
        if older is not None and not older.done():  # its answer could not be told apart
            older.set_exception(CommandDenied(name, "superseded by a newer command"))
        future = self._acks[command] = loop.create_future()
        try:
            for attempt in range(self.command_retries):
                self._send(self._command_long_msg(command, *params, confirmation=attempt))
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(asyncio.shield(future), self.command_timeout_s)
                    break
            if not future.done():
                raise CommandTimeout(name, self.command_timeout_s * self.command_retries)
            result = future.result()
            if result == mavlink.MAV_RESULT_IN_PROGRESS:  # wait for the final answer
                future = self._acks[command] = loop.create_future()
                try:
                    result = await asyncio.wait_for(future, 10.0 * self.command_timeout_s)
                except TimeoutError:
                    raise CommandTimeout(name, 10.0 * self.command_timeout_s) from None
            if result == mavlink.MAV_RESULT_ACCEPTED:
                return
            reason = px4.mav_result_name(result)
            if self._statustext:
                reason += f" ({self._statustext[-1]})"
            raise CommandDenied(name, reason)
        finally:
            if self._acks.get(command) is future:
                del self._acks[command]

    async def _set_mode(self, mode: FlightMode) -> None:
        await self._command(f"set mode {mode.value}", mavlink.MAV_CMD_DO_SET_MODE,
                            *self.firmware.mode_params(mode, self._armed))

    async def _heartbeats(self) -> None:
        """A companion computer's heartbeat at 1 Hz (MAV_TYPE_ONBOARD_CONTROLLER)."""
        while True:
            if self._link is not None:
                self._send(self._link.mav.heartbeat_encode(18, MAV_AUTOPILOT_INVALID, 0, 0, 4))
            await asyncio.sleep(1.0)

    async def _timesync(self) -> None:
        """TIMESYNC requests: ten a second for the first two seconds, then one a second."""
        count = 0
        while True:
            if self._link is not None and self._target is not None:
                now = self._clock.now()
                ts1 = int(now * 1e9)
                self._timesync_sent.sent(ts1, now)
                self._send(self._link.mav.timesync_encode(0, ts1))
            count += 1
            await asyncio.sleep(px4.timesync_period_s(count, self._boot.settling))

    async def _watchdog(self) -> None:
        """The link is lost when nothing from the vehicle (heartbeats, telemetry) arrives
        for ``heartbeat_timeout_s``: a lossy link that drops three heartbeats in a row (at
        30 % loss, every minute or so) but passes its telemetry is not lost."""
        while True:
            await asyncio.sleep(0.25)
            if self._heard.is_set() and \
                    self._clock.now() - self._last_heartbeat_s > self.heartbeat_timeout_s:
                self._closed_error = ConnectionLost(
                    f"nothing from the vehicle (no heartbeat, no telemetry) for "
                    f"{self.heartbeat_timeout_s:g} s")
                self._end_telemetry(self._closed_error)
                for future in (*self._acks.values(), *self._params.values()):
                    if not future.done():
                        future.set_exception(self._closed_error)
                return

    # ------------------------------------------------------------------------------------
    # Internals: receiving
    # ------------------------------------------------------------------------------------

    def _receive(self, msg, address) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        kind = msg.get_type()
        if self.rover_system_id is not None and src[0] == self.rover_system_id:
            self._on_rover(msg)  # the rover (never taken for the vehicle)
            return
        if kind == "HEARTBEAT":
            # (6 GCS, 18 onboard controller; 10-12 rover, boat, submarine: another vehicle on
            # the link, never the one this autopilot flies)
            if msg.autopilot == MAV_AUTOPILOT_INVALID or msg.type in (6, 10, 11, 12, 18) or \
                    (self._target is None and src[1] != AUTOPILOT_COMPONENT):
                return  # a ground station, companion computer, gimbal…: not the autopilot
            if self._target is None:
                self._target = src
                self.autopilot = msg.autopilot
                self._link.lock(address)
                log.info("vehicle: autopilot %s at system %d component %d", msg.autopilot,
                         *src)
            if src != self._target:
                self._ignore(src)
                return
            self._last_heartbeat_s = self._clock.now()
            self._armed = bool(msg.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED)
            self._custom_mode = msg.custom_mode
            self._mode = self.firmware.flight_mode(msg.custom_mode)
            self._failsafe = msg.system_status == px4.MAV_STATE_CRITICAL
            self._heard.set()
            return
        if src != self._target:
            if self._target is not None and kind not in _ANYONE:
                self._ignore(src)
            return
        self._last_heartbeat_s = self._clock.now()  # (anything from the vehicle will do)
        handler = _HANDLERS.get(kind)
        if handler is not None:
            handler(self, msg)

    def _ignore(self, src: tuple[int, int]) -> None:
        if src not in self._ignored_systems:
            self._ignored_systems.add(src)
            log.warning("ignoring MAVLink from system %d component %d: this link is locked "
                        "onto the vehicle at system %d component %d", *src, *self._target)

    def _on_ack(self, msg) -> None:
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        ours = (self._link.mav.srcSystem, self._link.mav.srcComponent) if self._link else None
        if (ours is not None and target[0] not in (0, ours[0])) or \
                (ours is not None and target[1] not in (0, ours[1])):
            return  # another client's answer on a shared link
        future = self._acks.get(msg.command)
        if future is not None and not future.done():
            future.set_result(msg.result)

    def _on_param(self, msg) -> None:
        name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) \
            else msg.param_id.decode(errors="replace").rstrip("\x00")
        future = self._params.get(name)
        if future is not None and not future.done():
            future.set_result(self.firmware.param_value(msg.param_value, msg.param_type))

    def _on_timesync(self, msg) -> None:
        if msg.tc1 == 0:
            return  # a request (PX4 sends its own); not ours to answer
        sent = self._timesync_sent.answer(msg.ts1)
        if sent is not None:  # an answer to one of our requests, not another client's
            self._boot.observe_sync(sent, msg.tc1 / 1e9, self._clock.now())

    def _on_statustext(self, msg) -> None:
        text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
        self._statustext.append(text.rstrip("\x00"))
        self._on_vehicle_text(msg)

    def _on_extended_sys_state(self, msg) -> None:
        self._landed = px4.landed_state(msg.landed_state)

    def _on_sys_status(self, msg) -> None:
        present, enabled, healthy = (msg.onboard_control_sensors_present,
                                     msg.onboard_control_sensors_enabled,
                                     msg.onboard_control_sensors_health)

        def ok(bit: int) -> bool:  # a sensor not present or not enabled does not block
            return not (present & enabled & bit) or bool(healthy & bit)

        self._health = Health(gyro_ok=ok(px4.SENSOR_GYRO), accel_ok=ok(px4.SENSOR_ACCEL),
                              mag_ok=ok(px4.SENSOR_MAG), local_position_ok=ok(px4.SENSOR_GPS),
                              battery_ok=ok(px4.SENSOR_BATTERY),
                              prearm_ok=ok(px4.SENSOR_PREARM_CHECK))
        remaining = msg.battery_remaining / 100.0 if msg.battery_remaining >= 0 else math.nan
        self._battery = Battery(msg.voltage_battery / 1000.0, msg.current_battery / 100.0,
                                remaining)

    def _on_distance_sensor(self, msg) -> None:
        if msg.orientation != 25:  # MAV_SENSOR_ROTATION_PITCH_270: facing down
            return
        cm = msg.current_distance
        in_range = msg.min_distance <= cm <= msg.max_distance
        self._range_m = cm / 100.0 if in_range else math.nan

    def _on_local_position(self, msg) -> None:
        self._publish_position(msg.time_boot_ms / 1000.0, (msg.x, msg.y, msg.z),
                               (msg.vx, msg.vy, msg.vz))


#: messages from other systems that are expected on a shared link and not worth a warning
_ANYONE = frozenset({"HEARTBEAT", "TIMESYNC", "RADIO_STATUS"})

_HANDLERS = {
    "COMMAND_ACK": PymavlinkDriver._on_ack,
    "PARAM_VALUE": PymavlinkDriver._on_param,
    "STATUSTEXT": PymavlinkDriver._on_statustext,
    "TIMESYNC": PymavlinkDriver._on_timesync,
    "ATTITUDE_QUATERNION": MavlinkVehicle._on_attitude,
    "ATTITUDE": MavlinkVehicle._on_attitude,
    "EKF_STATUS_REPORT": MavlinkVehicle._on_ekf_status,
    "EXTENDED_SYS_STATE": PymavlinkDriver._on_extended_sys_state,
    "SYS_STATUS": PymavlinkDriver._on_sys_status,
    "DISTANCE_SENSOR": PymavlinkDriver._on_distance_sensor,
    "LOCAL_POSITION_NED": PymavlinkDriver._on_local_position,
    "HOME_POSITION": PymavlinkDriver._on_home_position,
    "GPS_GLOBAL_ORIGIN": PymavlinkDriver._on_gps_global_origin,
}
