"""A PX4 SITL look-alike on MAVLink 2, in front of the simulated vehicle.

``autopilot sim`` puts it in front of the real-time simulator, so that real MAVLink clients
(MAVSDK, MAVProxy, QGroundControl) and our own MAVLink drivers fly the simulated vehicle as
they would fly PX4 SITL. What it copies from PX4 (see ``shared/reference/px4-mavlink-sitl.md``):

* ports: it binds UDP 14580+i (offboard API) and 18570+i (ground station) on ``host``
  (127.0.0.1 unless configured), sends to 14540+i and 14550 there until someone writes to it,
  then replies to the sender's address from the same socket; no SO_REUSEADDR, so a stale
  simulator is an error;
* identity: system id MAV_SYS_ID (1 + instance, as PX4 SITL), component 1, MAVLink 2,
  HEARTBEAT at 1 Hz as a PX4 quadrotor, PX4 custom modes with PX4's base-mode flags;
* commands (:mod:`~drivers.mavlink.face_commands`), telemetry at PX4's onboard-link rates
  (:mod:`~drivers.mavlink.face_telemetry`), parameters (:mod:`~drivers.mavlink.face_params`),
  the mission protocol with MISSION_CURRENT and MISSION_ITEM_REACHED
  (:mod:`~drivers.mavlink.face_mission`), STATUSTEXT for the vehicle's events;
* offboard: SET_POSITION_TARGET_LOCAL_NED (LOCAL_NED, BODY_NED) and _GLOBAL_INT go to the vehicle
  one by one, never re-sent: the vehicle's own setpoint-loss failsafe acts when a client stops;
* ground stations' heartbeats feed the vehicle's data-link loss failsafe (NAV_DLL_ACT);
* TIMESYNC answered with the vehicle's boot time (the clock of every ``time_boot_ms``);
* MAVLink 2 signing when given a key: unsigned or badly signed messages are then dropped
  (counted), and everything sent is signed.

Malformed, unknown and foreign-targeted messages are ignored (counted in :attr:`stats`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import struct
import time
from collections.abc import AsyncIterator, Callable, Coroutine
from typing import ClassVar

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, LandingTarget, VehicleError, VehicleState
from drivers.mavlink import px4
from drivers.mavlink.common import cancel_all
from drivers.mavlink.face_commands import CommandHandler, ModeNotAvailable
from drivers.mavlink.face_link import (
    COMPONENT_ID,
    FaceLink,
    FaceRequests,
    FaceStats,
    FaceStreams,
)
from drivers.mavlink.face_mission import MissionServer
from drivers.mavlink.face_params import ParamServer
from drivers.mavlink.face_telemetry import DEFAULT_RATES_HZ, TelemetryEncoder, base_mode
from drivers.mavlink.signing import Signing

log = logging.getLogger(__name__)

#: compids PX4 takes mission and parameter messages for besides its own (0: broadcast,
#: 190: MAV_COMP_ID_MISSIONPLANNER)
_OUR_COMPONENTS = (0, COMPONENT_ID, 190)
#: MISSION_ITEM_REACHED is repeated this many times with the 1 Hz MISSION_CURRENT (as PX4)
_REACHED_REPEATS = 10

# MAV_RESULT
ACCEPTED, DENIED = px4.MAV_RESULT_ACCEPTED, px4.MAV_RESULT_DENIED
UNSUPPORTED, FAILED = px4.MAV_RESULT_UNSUPPORTED, px4.MAV_RESULT_FAILED
TEMPORARILY_REJECTED = px4.MAV_RESULT_TEMPORARILY_REJECTED

_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_MAV_TYPE_GCS = mavlink.MAV_TYPE_GCS


class MavlinkFace:
    """Serves ``vehicle`` (the simulator driver) on MAVLink as PX4 SITL instance ``instance``.

    ``events`` is an optional stream of ``(time_s, text)`` status messages to forward as
    STATUSTEXT. Start with :meth:`start`, stop with :meth:`close` (it does not command the
    vehicle).
    """

    def __init__(self, vehicle, *, instance: int = 0, host: str = "127.0.0.1",
                 gcs_port: int = 14550, peer_host: str | None = None,
                 events: AsyncIterator[tuple[float, str]] | None = None,
                 signing: Signing | None = None) -> None:
        self.vehicle = vehicle
        self.instance = instance
        #: MAV_SYS_ID (PX4 SITL gives instance i the id i + 1; read once, as PX4 at boot)
        self.system_id = int(vehicle.param("MAV_SYS_ID"))
        #: a scenario's rover speaks as this system (sim.rover_link.system_id)
        self.rover_system_id = int(getattr(getattr(getattr(vehicle, "config", None),
                                                   "rover_link", None), "system_id", 0)
                                   or self.system_id + 1)
        self.host = host
        self.signing = signing
        #: signing's replay state, one for every port (a frame replayed to another port is
        #: still a replay)
        self.signed_streams: dict = {}
        self.stats = FaceStats()
        peer = peer_host or ("127.0.0.1" if host in ("0.0.0.0", "") else host)
        self.ports = {"offboard": (14580 + instance, (peer, 14540 + instance)),
                      "gcs": (18570 + instance, (peer, gcs_port))}
        self.links: dict[str, FaceLink] = {}
        self._streams = {name: FaceStreams() for name in self.ports}
        self._events = events
        self._tasks: list[asyncio.Task] = []
        self._state: VehicleState | None = None
        self._boot = time.monotonic()
        origin = vehicle.global_origin
        self.telemetry = TelemetryEncoder(vehicle, origin, self._boot_ms, instance)
        self.commands = CommandHandler(vehicle, origin, lambda: self._state)
        self.params = ParamServer(vehicle, self._send, self._spawn, self._say)
        self.missions = MissionServer(vehicle, self._send, self._spawn, self._say)
        self._reached: list[list[int]] = []  # [seq, sends left]
        self._text_id = 0
        self._delayed: list[asyncio.TimerHandle] = []  # datagrams held back (link_loss)

    # ------------------------------------------------------------------------------------
    # Link impairment (the simulator's link_loss fault: drivers/sim/faults.py)
    # ------------------------------------------------------------------------------------

    def link_fault(self):
        """The simulated vehicle's active ``link_loss`` fault (None: a clean link)."""
        try:
            sim = self.vehicle.simulator
        except Exception:  # not a simulator, or not connected
            return None
        faults = getattr(sim, "faults", None)
        if not faults or not faults.of("link_loss"):
            return None
        active = faults.active("link_loss", sim.fault_time_s())
        return active[0] if active else None

    def impaired(self, fault, deliver: Callable[[], None]) -> None:
        """One datagram across an impaired link: lost (``fraction``), delivered twice
        (``duplicate``), held back behind later ones (``reorder``: 20–150 ms) and late
        (``latency_s``)."""
        rng = self.vehicle.simulator.faults.link_rng
        if rng.random() < fault.fraction:
            self.stats.link_dropped += 1
            return
        delay = fault.latency_s
        if fault.reorder and rng.random() < fault.reorder:
            delay += float(rng.uniform(0.02, 0.15))
        copies = 2 if fault.duplicate and rng.random() < fault.duplicate else 1
        for _ in range(copies):
            if delay > 0.0:
                loop = asyncio.get_running_loop()
                if len(self._delayed) > 256:  # forget the ones delivered already
                    now = loop.time()
                    self._delayed = [h for h in self._delayed if h.when() > now]
                self._delayed.append(loop.call_later(delay, deliver))
            else:
                deliver()

    # ------------------------------------------------------------------------------------
    # Life cycle
    # ------------------------------------------------------------------------------------

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        with contextlib.suppress(Exception):  # a simulated vehicle: link_loss acts here only
            self.vehicle.simulator.link_faults_in_face = True
        for name, (port, peer) in self.ports.items():
            link = FaceLink(name, self, peer)
            try:
                await loop.create_datagram_endpoint(lambda link=link: link,
                                                    local_addr=(self.host, port))
            except OSError as exc:
                await self.close()
                raise OSError(f"cannot bind UDP {self.host}:{port} for the {name} link: "
                              f"{exc.strerror or exc} (is another simulator or PX4 SITL "
                              f"running? --instance N picks other ports)") from exc
            self.links[name] = link
        self._tasks = [loop.create_task(self._heartbeats(), name="mavlink-heartbeat"),
                       loop.create_task(self._telemetry(), name="mavlink-telemetry"),
                       loop.create_task(self._mission_events(), name="mavlink-mission"),
                       loop.create_task(self._housekeeping(), name="mavlink-housekeeping")]
        if self._events is not None:
            self._tasks.append(loop.create_task(self._statustext(), name="mavlink-events"))
        rover_link = getattr(getattr(self.vehicle, "config", None), "rover_link", None)
        if "rover" in getattr(self.vehicle, "sensors", ()) and \
                getattr(rover_link, "mavlink", False):
            self._tasks.append(loop.create_task(self._rover(), name="mavlink-rover"))

    async def close(self) -> None:
        await cancel_all(self._tasks)
        self._tasks = []
        for handle in self._delayed:  # datagrams the impaired link still held back
            handle.cancel()
        self._delayed = []
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

    @staticmethod
    def _send(link: FaceLink, msg) -> None:
        link.send(msg)

    def _send_all(self, make) -> None:
        for link in self.links.values():
            link.send(make(link.mav))

    def _say(self, link: FaceLink | None, text: str, severity: int = 6) -> None:
        """STATUSTEXT on ``link`` (all links if None); longer texts in 50-byte chunks with an
        id, as MAVLink 2 allows (the last chunk ends short, or with an empty one)."""
        data = _statustext(text)
        if len(data) <= 50:
            chunks, text_id = [data], 0
        else:
            self._text_id = self._text_id % 65535 + 1
            text_id = self._text_id
            chunks = [data[i:i + 50] for i in range(0, len(data), 50)]
            if len(chunks[-1]) == 50:
                chunks.append(b"")
        for seq, chunk in enumerate(chunks):
            def make(mav, chunk=chunk, seq=seq):
                return mav.statustext_encode(severity, chunk, text_id, seq)
            if link is None:
                self._send_all(make)
            else:
                link.send(make(link.mav))

    def _spawn(self, coro: Coroutine) -> asyncio.Task:
        """Run ``coro`` as a task the face owns (cancelled at close; failures logged)."""
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.append(task)
        task.add_done_callback(self._task_done)
        return task

    def _task_done(self, task: asyncio.Task) -> None:
        if task in self._tasks:
            self._tasks.remove(task)
        if not task.cancelled() and task.exception() is not None:
            log.warning("MAVLink face task failed: %s", task.exception())

    async def _heartbeats(self) -> None:
        while True:
            self._send_all(self._heartbeat)
            await asyncio.sleep(1.0)

    def _heartbeat(self, mav):
        s = self._state
        armed = s is not None and s.armed
        custom = px4.px4_custom_mode(s.mode) if s is not None else 0
        status = (px4.MAV_STATE_CRITICAL if s is not None and s.failsafe else
                  px4.MAV_STATE_ACTIVE if armed else px4.MAV_STATE_STANDBY)
        return mav.heartbeat_encode(px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4, base_mode(s),
                                    custom, status)

    async def _rover(self) -> None:
        """The scenario's rover as its own autopilot (a PX4 rover) would appear on a router's
        link: HEARTBEAT (MAV_TYPE_GROUND_ROVER) once a second and GLOBAL_POSITION_INT with
        each of its reports (its position, velocity and compass heading), from its system id,
        stamped with its capture time on the shared boot clock."""
        last_heartbeat = -math.inf
        async with contextlib.aclosing(self.vehicle.rover_states(buffer=16)) as reports:
            async for r in reports:
                now = time.monotonic()
                n, e, d = (float(v) for v in r.position_ned_m)
                vn, ve, vd = (float(v) for v in r.velocity_ned_m_s)
                lat, lon, alt = self.telemetry.origin.to_global(n, e, d)
                hdg = round(math.degrees(r.heading_rad) % 360.0 * 100.0) % 36000 \
                    if math.isfinite(r.heading_rad) else 65535
                for link in self.links.values():
                    mav = link.rover_mav
                    if now - last_heartbeat >= 1.0:
                        link.send(mav.heartbeat_encode(
                            mavlink.MAV_TYPE_GROUND_ROVER, px4.MAV_AUTOPILOT_PX4,
                            px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, px4.MAV_STATE_ACTIVE),
                            mav)
                    link.send(mav.global_position_int_encode(
                        self._boot_ms(r.time_s), round(lat * 1e7), round(lon * 1e7),
                        round(alt * 1000), round(-d * 1000), round(vn * 100), round(ve * 100),
                        round(vd * 100), hdg), mav)
                if now - last_heartbeat >= 1.0:
                    last_heartbeat = now

    async def _telemetry(self) -> None:
        async with contextlib.aclosing(self.vehicle.telemetry()) as samples:
            async for state in samples:
                self._state = state
                for name, link in self.links.items():
                    streams = self._streams[name]
                    for msg_id in streams.rates_hz:
                        if streams.due(msg_id, state.time_s):
                            msg = self._message(msg_id, link.mav)
                            if msg is not None:
                                link.send(msg)
                            if msg_id == mavlink.MAVLINK_MSG_ID_MISSION_CURRENT:
                                self._repeat_reached(link)

    def _message(self, msg_id: int, mav):
        try:
            return self.telemetry.encode(msg_id, mav, self._state)
        except (ValueError, OverflowError, struct.error):
            # a value MAVLink cannot carry (NaN, out of range): skip this one message
            log.debug("cannot encode message %d", msg_id, exc_info=True)
            return None

    async def _mission_events(self) -> None:
        """MISSION_CURRENT at once when the current item changes, MISSION_ITEM_REACHED when
        one is reached (repeated with the next few MISSION_CURRENTs, as PX4)."""
        async with contextlib.aclosing(self.vehicle.mission_events()) as events:
            async for event in events:
                if event.kind == "current":
                    self._send_all(self.telemetry.mission_current)
                elif event.kind == "reached":
                    self._send_all(lambda mav, seq=event.seq: mav.mission_item_reached_encode(
                        seq))
                    self._reached = [[event.seq, _REACHED_REPEATS]]
                elif event.kind == "finished":
                    self._send_all(self.telemetry.mission_current)

    def _repeat_reached(self, link: FaceLink) -> None:
        for entry in self._reached:
            if entry[1] > 0:
                link.send(link.mav.mission_item_reached_encode(entry[0]))
                if link is next(iter(self.links.values())):
                    entry[1] -= 1

    async def _statustext(self) -> None:
        assert self._events is not None
        async with contextlib.aclosing(self._events) as events:
            async for _, text in events:
                self._say(None, text, 6)  # MAV_SEVERITY_INFO

    async def _housekeeping(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            self.missions.tick()

    # ------------------------------------------------------------------------------------
    # Incoming
    # ------------------------------------------------------------------------------------

    def _receive(self, link: FaceLink, msg) -> None:
        self.stats.received += 1
        kind = msg.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(msg, "reason", "")).lower()
            if "signature" in reason or "unsigned" in reason:
                self.stats.bad_signature += 1
            else:
                self.stats.bad_data += 1
            return
        target = getattr(msg, "target_system", self.system_id)
        component = getattr(msg, "target_component", COMPONENT_ID)
        if target not in (0, self.system_id) or component not in _OUR_COMPONENTS:
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

    def _on_heartbeat(self, link: FaceLink, msg) -> None:
        if msg.type == _MAV_TYPE_GCS:
            self._spawn(self.vehicle.gcs_heartbeat())

    def _on_command(self, link: FaceLink, msg) -> None:
        self.stats.commands += 1
        frame = None
        if msg.get_type() == "COMMAND_INT":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x),
                      float(msg.y), msg.z)
            frame = msg.frame
        else:
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                      msg.param7)
        self._spawn(self._command(link, msg, params, frame))

    async def _command(self, link: FaceLink, msg, params: tuple[float, ...],
                       frame: int | None) -> None:
        command = msg.command
        try:
            result = await self.commands.execute(command, params, frame, FaceRequests(self, link))
        except ModeNotAvailable as exc:
            log.info("command %d: %s", command, exc.reason)
            self._say(link, exc.reason, 4)
            result = TEMPORARILY_REJECTED
        except CommandDenied as exc:
            log.info("command %d denied: %s", command, exc.reason)
            self._say(link, exc.reason, 4)
            result = DENIED
        except VehicleError as exc:
            log.warning("command %d failed: %s", command, exc)
            result = FAILED
        except Exception:  # a command we cannot read must still be answered
            log.warning("command %d failed", command, exc_info=True)
            result = FAILED
        link.send(link.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(),
                                              msg.get_srcComponent()))

    def _on_set_mode(self, link: FaceLink, msg) -> None:
        """SET_MODE (the message older clients send instead of DO_SET_MODE)."""
        main, sub = (msg.custom_mode >> 16) & 0xFF, (msg.custom_mode >> 24) & 0xFF

        async def change() -> None:
            try:
                await self.commands.set_mode(msg.base_mode, main, sub)
            except CommandDenied as exc:
                self._say(link, exc.reason, 4)

        self._spawn(change())

    def _set_interval(self, link: FaceLink, msg_id: int, interval_us: float) -> int:
        streams = self._streams[link.name]
        if msg_id == _HEARTBEAT:
            return ACCEPTED  # fixed at 1 Hz, as PX4
        if msg_id not in DEFAULT_RATES_HZ:
            return UNSUPPORTED
        if interval_us == 0:
            streams.rates_hz[msg_id] = DEFAULT_RATES_HZ[msg_id]
        elif interval_us < 0:
            streams.rates_hz[msg_id] = 0.0
        else:
            streams.rates_hz[msg_id] = 1e6 / interval_us
        streams.next_s.pop(msg_id, None)
        return ACCEPTED

    def _on_setpoint(self, link: FaceLink, msg) -> None:
        try:
            if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
                setpoint = self._global_setpoint(msg)
            else:
                setpoint = px4.setpoint_from_mavlink(
                    msg.coordinate_frame, msg.type_mask, (msg.x, msg.y, msg.z),
                    (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate,
                    (msg.afx, msg.afy, msg.afz))
        except px4.SetpointNotSupported as exc:
            self.stats.rejected_setpoints += 1
            log.debug("setpoint ignored: %s", exc)
            return
        self.stats.setpoints += 1
        self._spawn(self.vehicle.send_setpoint(setpoint))

    def _global_setpoint(self, msg):
        """SET_POSITION_TARGET_GLOBAL_INT as a local setpoint (position about the origin)."""
        origin = self.telemetry.origin
        n, e, _ = origin.to_ned(msg.lat_int / 1e7, msg.lon_int / 1e7, origin.alt_amsl_m)
        if msg.coordinate_frame in (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            home = self.vehicle.home()
            d = (float(home[3][2]) if home is not None else 0.0) - msg.alt
        elif msg.coordinate_frame in (mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL):
            d = origin.alt_amsl_m - msg.alt
        else:
            raise px4.SetpointNotSupported(f"coordinate frame {msg.coordinate_frame}")
        return px4.setpoint_from_mavlink(px4.MAV_FRAME_LOCAL_NED, msg.type_mask, (n, e, d),
                                         (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate,
                    (msg.afx, msg.afy, msg.afz))

    def _on_landing_target(self, link: FaceLink, msg) -> None:
        """LANDING_TARGET, as PX4's receiver takes it: a position in MAV_FRAME_LOCAL_NED is the
        target for precision landing (stamped on arrival); another frame is refused with a
        critical status text; angles only (IR-LOCK style, no ``position_valid``) need PX4's
        landing target estimator, which the simulator does not model: ignored."""
        if getattr(msg, "position_valid", 0) and msg.frame == px4.MAV_FRAME_LOCAL_NED:
            target = LandingTarget(self.vehicle.clock.now(), (msg.x, msg.y, msg.z),
                                   msg.target_num)
            self.stats.landing_targets += 1
            self._spawn(self.vehicle.send_landing_target(target))
        elif getattr(msg, "position_valid", 0):
            self._say(link, f"Landing target: coordinate frame {msg.frame} unsupported", 2)
        else:
            self.stats.ignored += 1

    def _on_timesync(self, link: FaceLink, msg) -> None:
        """MAVLink time synchronisation: answer a request (tc1 = 0) with our boot time."""
        if msg.tc1 == 0:
            now_ns = int(self.vehicle.clock.now() * 1e9)
            link.send(link.mav.timesync_encode(now_ns, msg.ts1))

    _handlers: ClassVar[dict[str, Callable[[MavlinkFace, FaceLink, object], None]]] = {
        "COMMAND_LONG": _on_command,
        "COMMAND_INT": _on_command,
        "SET_MODE": _on_set_mode,
        "SET_POSITION_TARGET_LOCAL_NED": _on_setpoint,
        "SET_POSITION_TARGET_GLOBAL_INT": _on_setpoint,
        "PARAM_REQUEST_LIST": lambda self, link, msg: self.params.on_request_list(link, msg),
        "PARAM_REQUEST_READ": lambda self, link, msg: self.params.on_request_read(link, msg),
        "PARAM_SET": lambda self, link, msg: self.params.on_set(link, msg),
        "MISSION_COUNT": lambda self, link, msg: self.missions.on_count(link, msg),
        "MISSION_ITEM": lambda self, link, msg: self.missions.on_item(link, msg),
        "MISSION_ITEM_INT": lambda self, link, msg: self.missions.on_item(link, msg),
        "MISSION_REQUEST_LIST": lambda self, link, msg: self.missions.on_request_list(link, msg),
        "MISSION_REQUEST": lambda self, link, msg: self.missions.on_request(link, msg),
        "MISSION_REQUEST_INT": lambda self, link, msg: self.missions.on_request(link, msg),
        "MISSION_ACK": lambda self, link, msg: self.missions.on_ack(link, msg),
        "MISSION_CLEAR_ALL": lambda self, link, msg: self.missions.on_clear_all(link, msg),
        "MISSION_SET_CURRENT": lambda self, link, msg: self.missions.on_set_current(link, msg),
        "TIMESYNC": _on_timesync,
        "LANDING_TARGET": _on_landing_target,
        "HEARTBEAT": _on_heartbeat,
    }


def _statustext(text: str) -> bytes:
    """A status text in ASCII (ground stations show other bytes as garbage), at most four
    STATUSTEXT chunks long."""
    return text.replace("→", "->").replace("−", "-").encode("ascii", "replace")[:200]

