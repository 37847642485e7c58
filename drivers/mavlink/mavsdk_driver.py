"""A :class:`~drivers.base.Vehicle` for PX4 through MAVSDK 4 (``mavsdk.asyncio``).

MAVSDK's plugins do what they do well: ``action`` for arming, takeoff, land and hold (with
their retries and PX4 specifics), ``telemetry`` for modes, landed state, health, battery and
range. MAVSDK talks to the vehicle through this project's own link
(:class:`~drivers.mavlink.link.MavlinkLink`, over MAVSDK's ``raw://`` connection), so that both
drivers share one implementation of what MAVSDK 4 does not offer: locking onto the first
vehicle (other systems and senders on the link are dropped before MAVSDK sees them), MAVLink 2
signing (MAVSDK has none: frames it sends are signed on their way out), and UDP, TCP and serial
links with clear errors. Around the plugins:

* setpoints: MAVSDK's ``offboard`` plugin re-sends the last setpoint at 20 Hz on its own
  thread for as long as the process lives, which would keep a stalled controller's stale
  intent alive. Here each :meth:`send_setpoint` is one SET_POSITION_TARGET_LOCAL_NED, encoded
  and sent on the event loop through the shared link (signed there when signing is on), and
  OFFBOARD is entered with DO_SET_MODE: if the caller stops, PX4's offboard-loss failsafe
  acts. Other messages MAVSDK has no call for (LANDING_TARGET) go through ``mavlink_direct``,
  on one thread of its own so that they keep their order.
* MAVSDK's view: the high-rate streams the driver reads itself (position and attitude, at
  PX4's 30–50 Hz each) reach MAVSDK thinned to :data:`MAVSDK_STREAM_HZ`; MAVSDK still sees every
  message kind (its health and telemetry stay as they are), but not 200 messages a second, each
  a call into it and a wake of its thread, taken from the event loop's CPU (the part that a busy
  machine shares out, see docs/reliability.md).
* time: position and attitude are read from the link as they arrive, each stamped with its own
  ``time_boot_ms`` mapped onto our clock by TIMESYNC round trips of our own (answers to MAVSDK's
  or anyone else's requests are not taken for ours).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import math
import threading
from concurrent.futures import ThreadPoolExecutor

from drivers.base import (
    Battery,
    CommandDenied,
    CommandTimeout,
    ConnectionLost,
    FlightMode,
    Health,
    LandedState,
    LandingTarget,
    Setpoint,
    VehicleNotFound,
)
from drivers.mavlink import ardupilot, px4
from drivers.mavlink.common import MavlinkVehicle, cancel_all
from drivers.mavlink.link import MavlinkLink, TimesyncRequests, unheard
from drivers.mavlink.signing import Signing, refresh
from drivers.rate import RateSampler

log = logging.getLogger(__name__)

_LOST = {"NO_SYSTEM", "CONNECTION_ERROR"}
#: never taken for the vehicle: MAV_TYPE_GCS, ONBOARD_CONTROLLER, and another vehicle on the
#: link (GROUND_ROVER, SURFACE_BOAT, SUBMARINE: a rover landing's rover)
_GCS_OR_COMPANION = (6, 18, 10, 11, 12)
_MAV_AUTOPILOT_INVALID = 8
#: MAV_COMP_ID_AUTOPILOT1: the flight controller (as MAVSDK, we take no other component for it:
#: a gimbal or camera with its own heartbeat is not the vehicle)
_AUTOPILOT_COMPONENT = 1
#: the streams read by the driver itself (never through MAVSDK's telemetry), and the rate at
#: which MAVSDK still sees each of them
MAVSDK_THINNED = frozenset({"ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED",
                            "GLOBAL_POSITION_INT"})
MAVSDK_STREAM_HZ = 4.0


class StreamThinner:
    """Passes at most ``rate_hz`` messages of each of ``kinds`` (every other kind passes)."""

    def __init__(self, kinds: frozenset[str], rate_hz: float) -> None:
        self.kinds = kinds
        self._samplers = {kind: RateSampler(rate_hz) for kind in kinds}
        self.held_back = 0

    def passes(self, kind: str, now_s: float) -> bool:
        sampler = self._samplers.get(kind)
        if sampler is None or sampler.take(now_s):
            return True
        self.held_back += 1
        return False


class MavsdkDriver(MavlinkVehicle):
    def __init__(self, url: str = "udpin://127.0.0.1:14540", *,
                 discovery_timeout_s: float = 10.0, telemetry_timeout_s: float = 3.0,
                 signing: Signing | None = None,
                 ardupilot_hold: ardupilot.CopterMode = ardupilot.CopterMode.BRAKE) -> None:
        super().__init__(ardupilot_hold)
        self.url = url
        self.discovery_timeout_s = discovery_timeout_s
        self.telemetry_timeout_s = telemetry_timeout_s
        self.signing = signing
        self._mavsdk = None
        self._system = None
        self._target: tuple[int, int] | None = None
        self._action = None
        self._telemetry_plugin = None
        self._direct = None
        self._param = None
        self._link: MavlinkLink | None = None
        self._raw_handle = None
        self._resigner = None
        self._tasks: list[asyncio.Task] = []
        self._error: ConnectionLost | None = None
        self._last_sample_s = -math.inf
        self._status_text: tuple[float, str] = (-math.inf, "")
        self._ignored: set[tuple[int, int]] = set()
        self._timesync_sent = TimesyncRequests()
        self._to_mavsdk = StreamThinner(MAVSDK_THINNED, MAVSDK_STREAM_HZ)
        self._sender = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mavsdk-send")

    # ------------------------------------------------------------------------------------
    # Vehicle interface
    # ------------------------------------------------------------------------------------

    async def connect(self, timeout_s: float = 10.0) -> None:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        if self._mavsdk is not None:
            return
        loop = asyncio.get_running_loop()
        try:
            self._link = await MavlinkLink.open(self.url, self._from_vehicle,
                                                signing=self.signing)
            config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
            self._mavsdk = Mavsdk(config)
            await self._mavsdk.__aenter__()
            result = await self._mavsdk.add_any_connection("raw://")
            if getattr(result, "name", "SUCCESS") != "SUCCESS":
                raise ConnectionLost(f"MAVSDK refused its raw connection: {result}")
            core = self._mavsdk._mavsdk  # the native Mavsdk: raw bytes in and out
            if self.signing is not None:
                self._resigner = _Resigner(self.signing)
            self._raw_handle = core.subscribe_raw_bytes_to_be_sent(
                lambda data: loop.call_soon_threadsafe(self._to_vehicle, bytes(data)))
            self._system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
            if self._system is None:
                raise VehicleNotFound(unheard(f"no autopilot heartbeat on {self.url} within "
                                              f"{timeout_s:g} s", self._link))
            self._action = ActionAsync(self._system)
            self._telemetry_plugin = TelemetryAsync(self._system)
            self._direct = MavlinkDirectAsync(self._system)
            self._param = ParamAsync(self._system)
            self._request_streams()
            self._tasks = [loop.create_task(coro, name=f"mavsdk-{name}") for name, coro in (
                ("armed", self._armed_state()), ("landed", self._landed_state()),
                ("health", self._health_state()),
                ("battery", self._battery_state()), ("range", self._range()),
                ("timesync", self._timesync()), ("statustext", self._status_texts()),
                ("watchdog", self._watchdog()))]
            async with contextlib.aclosing(self.telemetry()) as samples:
                await asyncio.wait_for(anext(samples), timeout_s)
        except (TimeoutError, StopAsyncIteration):
            await self.close()
            raise VehicleNotFound(f"no LOCAL_POSITION_NED from the vehicle on {self.url} "
                                 f"within {timeout_s:g} s") from None
        except BaseException:
            await self.close()
            raise

    async def arm(self) -> None:
        action = self._require_action()
        mode = self.firmware.arming_mode(self._custom_mode)
        if mode is None:
            await self._act("arm", action.arm())
            return
        # the vehicle arms only in some modes: into one first, and arm with our own command
        # (MAVSDK's action, its mode not yet updated, would ask for a hold ArduCopter refuses)
        await self._set_mode("arm", mode)
        await self._command("arm", 400, 1)

    async def disarm(self, *, force: bool = False) -> None:
        action = self._require_action()
        await self._act("disarm", action.kill() if force else action.disarm())

    async def takeoff(self, altitude_m: float | None = None) -> None:
        action = self._require_action()
        if altitude_m is not None:
            await self._act("set takeoff altitude", action.set_takeoff_altitude(altitude_m))
        await self._act("takeoff", action.takeoff())

    async def land(self) -> None:
        await self._act("land", self._require_action().land())

    async def hold(self) -> None:
        await self._act("hold", self._require_action().hold())

    async def return_to_launch(self) -> None:
        await self._act("return to launch", self._require_action().return_to_launch())

    async def precision_land(self) -> None:
        """The firmware's precision landing (PX4's AUTO.PRECLAND, ArduCopter's LAND with PLND;
        MAVSDK's action has no call for it: DO_SET_MODE)."""
        async def set_mode(mode: FlightMode) -> None:
            await self._set_mode("precision land", mode)

        await self.firmware.precision_land(self._command, set_mode, self.get_param)

    async def precision_landing_problem(self) -> str | None:
        return await self.firmware.precision_landing_problem(self.get_param)

    async def get_param(self, name: str) -> float:
        """A parameter's value through MAVSDK's param plugin (KeyError if the vehicle has no
        such parameter or does not answer)."""
        if self._param is None:
            raise ConnectionLost("not connected")
        return await read_param(self._param, name)

    async def send_landing_target(self, target: LandingTarget) -> None:
        report = self.firmware.landing_target(target, self.latest_state)
        if report is None:
            return  # (not yet expressible: no telemetry to place it against)
        x, y, z = report.position_m
        fields = {"time_usec": int(self._clock.now() * 1e6), "target_num": target.target_num,
                  "frame": report.frame, "angle_x": 0.0, "angle_y": 0.0,
                  "distance": report.distance_m, "size_x": 0.0, "size_y": 0.0,
                  "x": x, "y": y, "z": z,
                  "q": [1.0, 0.0, 0.0, 0.0], "type": 0, "position_valid": 1}
        await self._send_message("LANDING_TARGET", fields)

    async def start_offboard(self) -> None:
        await self._set_mode("start offboard", FlightMode.OFFBOARD)

    async def _set_mode(self, name: str, mode: FlightMode) -> None:
        """DO_SET_MODE with the firmware's custom mode (for modes MAVSDK's action has no call
        for)."""
        await self._command(name, 176, *self.firmware.mode_params(mode, self._armed))

    def _request_streams(self) -> None:
        """SET_MESSAGE_INTERVAL for the telemetry the driver reads (ArduCopter streams none
        unasked on a fresh port; MAVSDK asks only for what its calls name)."""
        link, target = self._link, self._target
        if link is None or target is None:
            return
        system, component = target
        for msg_id, rate in self._stream_requests().items():
            link.send(link.mav.command_long_encode(system, component, 511, 0, msg_id,
                                                   1e6 / rate, 0, 0, 0, 0, 0))

    async def stop_offboard(self) -> None:
        await self.hold()

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        self._check_alive()
        system, component = self._target
        frame, mask, pos, vel, yaw, rate, acc = px4.setpoint_to_mavlink(setpoint)
        link = self._link
        if link is None:
            raise ConnectionLost("the link to the vehicle is closed")
        # encoded and sent here, on the link MAVSDK also talks through (as our TIMESYNC is):
        # through mavlink_direct each setpoint went to a sender thread, through MAVSDK's
        # JSON encoder and back to this loop as raw bytes — two thread hand-overs per
        # setpoint, which on a busy CPU made control ticks late
        link.send(link.mav.set_position_target_local_ned_encode(
            int(self._clock.now() * 1000) & 0xFFFFFFFF, system, component, frame, mask,
            *pos, *vel, *acc, yaw, rate))

    async def _send_message(self, name: str, fields: dict) -> None:
        """One message through MAVSDK's mavlink_direct, in order on the sender thread."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkMessage

        self._check_alive()
        system, component = self._target
        message = MavlinkMessage(message_name=name, target_system_id=system,
                                 target_component_id=component, fields_json=json.dumps(fields))
        cancelled = threading.Event()
        plugin = self._direct._plugin

        def send() -> None:
            if not cancelled.is_set():  # the caller gave up on this setpoint: drop it
                plugin.send_message(message)

        try:
            await asyncio.get_running_loop().run_in_executor(self._sender, send)
        except asyncio.CancelledError:
            cancelled.set()
            raise

    async def close(self) -> None:
        await cancel_all(self._tasks)
        self._tasks = []
        await self._close_cameras()
        # no send may still be running on MAVSDK's objects when they are destroyed
        await asyncio.to_thread(self._sender.shutdown, True, cancel_futures=True)
        if self._mavsdk is not None:
            mavsdk, self._mavsdk = self._mavsdk, None
            with contextlib.suppress(Exception):
                if self._raw_handle is not None:
                    mavsdk._mavsdk.unsubscribe_raw_bytes_to_be_sent(self._raw_handle)
            self._raw_handle = None
            with contextlib.suppress(Exception):
                await mavsdk.__aexit__(None, None, None)
        if self._link is not None:
            self._link.close()
            self._link = None
            await asyncio.sleep(0)  # the transport lets go of its socket on the next turn
        self._end_telemetry(self._error)

    # ------------------------------------------------------------------------------------
    # The link: MAVSDK's frames out, the vehicle's in
    # ------------------------------------------------------------------------------------

    def _to_vehicle(self, frame: bytes) -> None:
        link = self._link
        if link is None:
            return
        if self._resigner is None:
            link.send_frame(frame)
            return
        for signed in self._resigner.sign(frame):
            link.send_frame(signed)

    def _from_vehicle(self, msg, address) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        kind = msg.get_type()
        if self.rover_system_id is not None and src[0] == self.rover_system_id:
            self._on_rover(msg)  # the rover: read here, never shown to MAVSDK
            return
        if kind == "HEARTBEAT" and self._target is None and src[1] == _AUTOPILOT_COMPONENT and \
                msg.autopilot != _MAV_AUTOPILOT_INVALID and msg.type not in _GCS_OR_COMPANION:
            self._target = src
            self.autopilot = msg.autopilot
            self._link.lock(address)
            log.info("vehicle: autopilot %s at system %d component %d", msg.autopilot, *src)
        if self._target is None or src[0] != self._target[0]:
            if self._target is not None and src not in self._ignored and \
                    kind not in ("HEARTBEAT", "RADIO_STATUS"):
                self._ignored.add(src)
                log.warning("ignoring MAVLink from system %d component %d: this link is locked "
                            "onto the vehicle at system %d component %d", *src, *self._target)
            return
        if kind == "LOCAL_POSITION_NED" and src == self._target:
            self._last_sample_s = self._clock.now()
            self._publish_position(msg.time_boot_ms / 1000.0, (msg.x, msg.y, msg.z),
                                   (msg.vx, msg.vy, msg.vz))
        elif kind in ("ATTITUDE_QUATERNION", "ATTITUDE") and src == self._target:
            self._on_attitude(msg)
        elif kind == "HEARTBEAT" and src == self._target:
            # the mode off the custom mode, as the firmware numbers it (MAVSDK's flight modes
            # have no precision land, and fold ArduCopter's BRAKE and LOITER)
            self._custom_mode = msg.custom_mode
            self._mode = self.firmware.flight_mode(msg.custom_mode)
        elif kind == "EKF_STATUS_REPORT" and src == self._target:
            self._on_ekf_status(msg)
        elif kind == "HOME_POSITION" and src == self._target:
            self._on_home_position(msg)
        elif kind == "STATUSTEXT" and src == self._target:
            self._on_vehicle_text(msg)
        elif kind == "GPS_GLOBAL_ORIGIN" and src == self._target:
            self._on_gps_global_origin(msg)
        elif kind == "TIMESYNC" and msg.tc1 != 0:
            sent = self._timesync_sent.answer(msg.ts1)
            if sent is not None:
                self._boot.observe_sync(sent, msg.tc1 / 1e9, self._clock.now())
        mavsdk = self._mavsdk
        if mavsdk is not None and self._to_mavsdk.passes(kind, self._clock.now()):
            mavsdk._mavsdk.pass_received_raw_bytes(bytes(msg.get_msgbuf()))

    # ------------------------------------------------------------------------------------
    # Commands
    # ------------------------------------------------------------------------------------

    def _check_alive(self) -> None:
        if self._error is not None:
            raise self._error
        if self._system is None or self._target is None:
            raise ConnectionLost("not connected: call connect() first")

    def _require_action(self):
        self._check_alive()
        return self._action

    async def _act(self, name: str, call) -> None:
        from mavsdk.asyncio import MavsdkError

        try:
            await call
        except MavsdkError as exc:
            result = getattr(getattr(exc, "result", None), "name", "UNKNOWN")
            if result == "TIMEOUT":
                raise CommandTimeout(name, 2.0) from exc
            if result in _LOST:
                raise ConnectionLost(f"{name}: {result.lower()}") from exc
            raise CommandDenied(name, self._reason(result.lower().replace("_", " "))) from exc

    def _reason(self, result: str) -> str:
        """A refusal's result, with the vehicle's latest status text if it just came."""
        at, text = self._status_text
        return f"{result} ({text})" if self._clock.now() - at < 1.0 else result

    async def _command(self, name: str, command: int, *params: float) -> None:
        from mavsdk.asyncio import MavsdkError
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkMessage

        self._check_alive()
        system, component = self._target
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        fields = {"target_system": system, "target_component": component, "command": command,
                  "confirmation": 0, **{f"param{i + 1}": p[i] for i in range(7)}}
        try:
            ack = await self._direct.send_command(MavlinkMessage(
                message_name="COMMAND_LONG", target_system_id=system,
                target_component_id=component, fields_json=json.dumps(fields)))
        except MavsdkError as exc:
            raise CommandTimeout(name, 2.0) from exc
        result = json.loads(ack.fields_json or "{}").get("result")
        if result is None:
            raise CommandTimeout(name, 2.0)
        if result != 0:
            await asyncio.sleep(0.05)  # the vehicle's reason may trail its answer
            raise CommandDenied(name, self._reason(px4.mav_result_name(result)))

    # ------------------------------------------------------------------------------------
    # Telemetry
    # ------------------------------------------------------------------------------------

    async def _timesync(self) -> None:
        """Our own TIMESYNC requests (their answers are matched in :meth:`_from_vehicle`)."""
        for count in itertools.count():
            link = self._link
            if link is not None:
                now = self._clock.now()
                ts1 = int(now * 1e9)
                self._timesync_sent.sent(ts1, now)
                link.send(link.mav.timesync_encode(0, ts1))
            await asyncio.sleep(px4.timesync_period_s(count, self._boot.settling))

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.25)
            if self.latest_state is not None and \
                    self._clock.now() - self._last_sample_s > self.telemetry_timeout_s:
                self._error = ConnectionLost(
                    f"no telemetry from the vehicle for {self.telemetry_timeout_s:g} s")
                self._end_telemetry(self._error)
                return

    async def _status_texts(self) -> None:
        async for status in self._telemetry_plugin.subscribe_status_text():
            self._status_text = (self._clock.now(), status.text)

    async def _armed_state(self) -> None:
        async for armed in self._telemetry_plugin.subscribe_armed():
            self._armed = bool(armed)

    async def _landed_state(self) -> None:
        async for landed in self._telemetry_plugin.subscribe_landed_state():
            self._landed = LandedState[landed.name] if landed.name in LandedState.__members__ \
                else LandedState.UNKNOWN

    async def _health_state(self) -> None:
        async for h in self._telemetry_plugin.subscribe_health():
            self._health = Health(gyro_ok=h.is_gyrometer_calibration_ok,
                                  accel_ok=h.is_accelerometer_calibration_ok,
                                  mag_ok=h.is_magnetometer_calibration_ok,
                                  local_position_ok=h.is_local_position_ok,
                                  prearm_ok=h.is_armable)

    async def _battery_state(self) -> None:
        async for b in self._telemetry_plugin.subscribe_battery():
            remaining = b.remaining_percent / 100.0 if math.isfinite(b.remaining_percent) \
                else math.nan
            self._battery = Battery(b.voltage_v, b.current_battery_a, remaining)

    async def _range(self) -> None:
        async for d in self._telemetry_plugin.subscribe_distance_sensor():
            ok = d.minimum_distance_m <= d.current_distance_m <= d.maximum_distance_m
            self._range_m = d.current_distance_m if ok else math.nan


class _Resigner:
    """Signs the frames another MAVLink stack (MAVSDK) sends: each frame is decoded and encoded
    again with the same sender, sequence number and payload, and a signature."""

    def __init__(self, signing: Signing) -> None:
        from pymavlink.dialects.v20 import common as mavlink

        self._rx = mavlink.MAVLink(None)
        self._rx.robust_parsing = True
        self._tx = mavlink.MAVLink(None)
        signing.apply(self._tx, mavlink.MAVLink(None))

    def sign(self, data: bytes) -> list[bytes]:
        out = []
        for msg in self._rx.parse_buffer(data) or []:
            if msg.get_type() == "BAD_DATA":
                continue
            tx = self._tx
            tx.srcSystem, tx.srcComponent = msg.get_srcSystem(), msg.get_srcComponent()
            tx.seq = msg.get_seq()
            refresh(tx)
            out.append(msg.pack(tx))
        return out


async def read_param(plugin, name: str) -> float:
    """``name``'s value through MAVSDK's param plugin in the vehicle's own type: as an integer
    first (as most that a companion reads are), then as a float; KeyError naming MAVSDK's
    result if neither is answered."""
    from mavsdk.plugins.param import ParamError, ParamResult

    wrong = {ParamResult.WRONG_TYPE, ParamResult.TYPE_MISMATCH}
    try:
        try:
            return float(await plugin.get_param_int(name))
        except ParamError as exc:
            if exc.result not in wrong:
                raise
        return float(await plugin.get_param_float(name))
    except ParamError as exc:
        raise KeyError(f"{name}: {exc.result.name.lower().replace('_', ' ')}") from None
