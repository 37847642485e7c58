"""A :class:`~drivers.base.Vehicle` for PX4 through MAVSDK 4 (``mavsdk.asyncio``).

MAVSDK's plugins do what they do well: ``action`` for arming, takeoff, land and hold (with
their retries and PX4 specifics), ``telemetry`` for attitude, modes, landed state, health,
battery and range. Two things go around them, through ``mavlink_direct``:

* setpoints: MAVSDK's ``offboard`` plugin re-sends the last setpoint at 20 Hz on its own
  thread for as long as the process lives, which would keep a stalled controller's stale
  intent alive. Here each :meth:`send_setpoint` is one SET_POSITION_TARGET_LOCAL_NED, and
  OFFBOARD is entered with DO_SET_MODE: if the caller stops, PX4's offboard-loss failsafe acts.
* time: telemetry samples are published on LOCAL_POSITION_NED, whose ``time_boot_ms`` is the
  sample's capture time on the vehicle, mapped onto our clock by TIMESYNC round trips (MAVSDK
  keeps its own time sync to itself).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import math

import numpy as np

from drivers.base import (
    Battery,
    CommandDenied,
    CommandTimeout,
    ConnectionLost,
    FlightMode,
    Health,
    LandedState,
    Setpoint,
)
from drivers.mavlink import px4
from drivers.mavlink.common import MavlinkVehicle, cancel_all

log = logging.getLogger(__name__)

_MODES = {"HOLD": FlightMode.HOLD, "TAKEOFF": FlightMode.TAKEOFF, "LAND": FlightMode.LAND,
          "OFFBOARD": FlightMode.OFFBOARD, "MISSION": FlightMode.MISSION,
          "RETURN_TO_LAUNCH": FlightMode.RETURN, "MANUAL": FlightMode.MANUAL,
          "ALTCTL": FlightMode.ALTCTL, "POSCTL": FlightMode.POSCTL,
          "STABILIZED": FlightMode.MANUAL, "ACRO": FlightMode.MANUAL}
_DENIED = {"COMMAND_DENIED", "COMMAND_DENIED_LANDED_STATE_UNKNOWN", "COMMAND_DENIED_NOT_LANDED",
           "UNSUPPORTED", "FAILED", "PARAMETER_ERROR", "INVALID_ARGUMENT", "BUSY"}
_LOST = {"NO_SYSTEM", "CONNECTION_ERROR"}


class MavsdkDriver(MavlinkVehicle):
    def __init__(self, url: str = "udpin://0.0.0.0:14540", *, discovery_timeout_s: float = 10.0,
                 telemetry_timeout_s: float = 3.0) -> None:
        super().__init__()
        self.url = url
        self.discovery_timeout_s = discovery_timeout_s
        self.telemetry_timeout_s = telemetry_timeout_s
        self._mavsdk = None
        self._system = None
        self._action = None
        self._telemetry_plugin = None
        self._direct = None
        self._tasks: list[asyncio.Task] = []
        self._error: ConnectionLost | None = None
        self._last_sample_s = -math.inf
        self._status_text: tuple[float, str] = (-math.inf, "")

    # ------------------------------------------------------------------------------------
    # Vehicle interface
    # ------------------------------------------------------------------------------------

    async def connect(self, timeout_s: float = 10.0) -> None:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        if self._mavsdk is not None:
            return
        config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        self._mavsdk = Mavsdk(config)
        await self._mavsdk.__aenter__()
        try:
            await self._mavsdk.add_any_connection(self.url)
            self._system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
            if self._system is None:
                raise ConnectionLost(f"no autopilot found on {self.url} within {timeout_s:g} s")
            self._action = ActionAsync(self._system)
            self._telemetry_plugin = TelemetryAsync(self._system)
            self._direct = MavlinkDirectAsync(self._system)
            loop = asyncio.get_running_loop()
            self._tasks = [loop.create_task(coro, name=f"mavsdk-{name}") for name, coro in (
                ("position", self._positions()), ("attitude", self._attitude()),
                ("rates", self._body_rates()), ("armed", self._armed_state()),
                ("mode", self._flight_mode()), ("landed", self._landed_state()),
                ("health", self._health_state()), ("battery", self._battery_state()),
                ("range", self._range()), ("timesync", self._timesync()),
                ("statustext", self._status_texts()),
                ("watchdog", self._watchdog()))]
            async with contextlib.aclosing(self.telemetry()) as samples:
                await asyncio.wait_for(anext(samples), timeout_s)
        except (TimeoutError, StopAsyncIteration):
            await self.close()
            raise ConnectionLost(f"no LOCAL_POSITION_NED from the vehicle on {self.url} "
                                 f"within {timeout_s:g} s") from None
        except BaseException:
            await self.close()
            raise

    async def arm(self) -> None:
        await self._act("arm", self._require_action().arm())

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

    async def start_offboard(self) -> None:
        main, sub = px4.PX4_MODES[FlightMode.OFFBOARD]
        base = px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (px4.MAV_MODE_FLAG_SAFETY_ARMED
                                                        if self._armed else 0)
        await self._command("start offboard", 176, base, main, sub)

    async def stop_offboard(self) -> None:
        await self.hold()

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkMessage

        self._check_alive()
        frame, mask, pos, vel, yaw, rate = px4.setpoint_to_mavlink(setpoint)
        fields = {"time_boot_ms": int(self._clock.now() * 1000) & 0xFFFFFFFF,
                  "target_system": 1, "target_component": 1, "coordinate_frame": frame,
                  "type_mask": mask, "x": pos[0], "y": pos[1], "z": pos[2], "vx": vel[0],
                  "vy": vel[1], "vz": vel[2], "afx": 0.0, "afy": 0.0, "afz": 0.0, "yaw": yaw,
                  "yaw_rate": rate}
        await self._direct.send_message(MavlinkMessage(
            message_name="SET_POSITION_TARGET_LOCAL_NED", target_system_id=1,
            target_component_id=1, fields_json=json.dumps(fields)))

    async def close(self) -> None:
        await cancel_all(self._tasks)
        self._tasks = []
        await self._close_cameras()
        if self._mavsdk is not None:
            mavsdk, self._mavsdk = self._mavsdk, None
            with contextlib.suppress(Exception):
                await mavsdk.__aexit__(None, None, None)
        self._end_telemetry(self._error)

    # ------------------------------------------------------------------------------------
    # Commands
    # ------------------------------------------------------------------------------------

    def _check_alive(self) -> None:
        if self._error is not None:
            raise self._error
        if self._system is None:
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
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        fields = {"target_system": 1, "target_component": 1, "command": command,
                  "confirmation": 0, **{f"param{i + 1}": p[i] for i in range(7)}}
        try:
            ack = await self._direct.send_command(MavlinkMessage(
                message_name="COMMAND_LONG", target_system_id=1, target_component_id=1,
                fields_json=json.dumps(fields)))
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

    async def _positions(self) -> None:
        async for msg in self._direct.subscribe_message("LOCAL_POSITION_NED"):
            f = json.loads(msg.fields_json)
            self._last_sample_s = self._clock.now()
            self._publish_position(f["time_boot_ms"] / 1000.0, (f["x"], f["y"], f["z"]),
                                   (f["vx"], f["vy"], f["vz"]))

    async def _timesync(self) -> None:
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkMessage

        async def answers() -> None:
            async for msg in self._direct.subscribe_message("TIMESYNC"):
                f = json.loads(msg.fields_json)
                if f.get("tc1"):
                    self._boot.observe_sync(f["ts1"] / 1e9, f["tc1"] / 1e9, self._clock.now())

        listener = asyncio.get_running_loop().create_task(answers())
        try:
            for count in itertools.count():
                fields = {"tc1": 0, "ts1": int(self._clock.now() * 1e9), "target_system": 1,
                          "target_component": 1}
                await self._direct.send_message(MavlinkMessage(
                    message_name="TIMESYNC", target_system_id=1, target_component_id=1,
                    fields_json=json.dumps(fields)))
                await asyncio.sleep(px4.timesync_period_s(count))
        finally:
            listener.cancel()

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

    async def _attitude(self) -> None:
        async for q in self._telemetry_plugin.subscribe_attitude_quaternion():
            self._q = np.array([q.w, q.x, q.y, q.z])

    async def _body_rates(self) -> None:
        async for w in self._telemetry_plugin.subscribe_attitude_angular_velocity_body():
            self._rates = np.array([w.roll_rad_s, w.pitch_rad_s, w.yaw_rad_s])

    async def _armed_state(self) -> None:
        async for armed in self._telemetry_plugin.subscribe_armed():
            self._armed = bool(armed)

    async def _flight_mode(self) -> None:
        async for mode in self._telemetry_plugin.subscribe_flight_mode():
            self._mode = _MODES.get(mode.name, FlightMode.UNKNOWN)

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
