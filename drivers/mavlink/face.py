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
from collections.abc import AsyncIterator, Coroutine

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import VehicleState
from drivers.mavlink import px4
from drivers.mavlink.common import cancel_all
from drivers.mavlink.face_commands import CommandHandler
from drivers.mavlink.face_incoming import IncomingMessages
from drivers.mavlink.face_link import (
    FaceLink,
    FaceStats,
    FaceStreams,
)
from drivers.mavlink.face_mission import MissionServer
from drivers.mavlink.face_params import ParamServer
from drivers.mavlink.face_telemetry import DEFAULT_RATES_HZ, TelemetryEncoder, base_mode
from drivers.mavlink.signing import Signing
from drivers.sim.link_impairment import LinkImpairment

log = logging.getLogger(__name__)

#: MISSION_ITEM_REACHED is repeated this many times with the 1 Hz MISSION_CURRENT (as PX4)
_REACHED_REPEATS = 10

# MAV_RESULT
ACCEPTED, UNSUPPORTED = px4.MAV_RESULT_ACCEPTED, px4.MAV_RESULT_UNSUPPORTED

_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
#: PX4 SITL's offboard API port (instance N: + N), where a companion or MAVSDK listens
OFFBOARD_PORT = 14540


class MavlinkFace:
    """Serves ``vehicle`` (the simulator driver) on MAVLink as PX4 SITL instance ``instance``.

    ``events`` is an optional stream of ``(time_s, text)`` status messages to forward as
    STATUSTEXT. Start with :meth:`start`, stop with :meth:`close` (it does not command the
    vehicle).
    """

    #: the MAVLink dialect its links speak
    dialect = mavlink
    #: the parameter that holds its system id
    system_id_param = "MAV_SYS_ID"
    title = "PX4-compatible simulated vehicle"

    @staticmethod
    def companion_url(instance: int = 0) -> str:
        """Where a companion computer's driver connects to instance ``instance``."""
        return f"udpin://127.0.0.1:{OFFBOARD_PORT + instance}"

    def __init__(self, vehicle, *, instance: int = 0, host: str = "127.0.0.1",
                 gcs_port: int = 14550, peer_host: str | None = None,
                 events: AsyncIterator[tuple[float, str]] | None = None,
                 signing: Signing | None = None) -> None:
        self.vehicle = vehicle
        self.instance = instance
        #: MAV_SYS_ID (PX4 SITL gives instance i the id i + 1; read once, as PX4 at boot)
        self.system_id = int(vehicle.param(self.system_id_param))
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
        self.ports = {"offboard": (14580 + instance, (peer, OFFBOARD_PORT + instance)),
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
        self.params = ParamServer(vehicle, self._send, self.spawn, self.say)
        self.missions = MissionServer(vehicle, self._send, self.spawn, self.say)
        self._reached: list[list[int]] = []  # [seq, sends left]
        self._text_id = 0
        #: the simulator's link_loss fault, acting on the datagrams both ways
        self.impairment = LinkImpairment(vehicle, self.stats)
        #: what arrives: checked, counted and dispatched (:mod:`.face_incoming`)
        self.incoming = IncomingMessages(self)

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
        self.impairment.close()  # datagrams the impaired link still held back
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

    def say(self, link: FaceLink | None, text: str, severity: int = 6) -> None:
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

    def spawn(self, coro: Coroutine) -> asyncio.Task:
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
                for name, link in list(self.links.items()):
                    streams = self._streams[name]
                    for msg_id in list(streams.rates_hz):
                        if streams.due(msg_id, state.time_s):
                            msg = self.message(msg_id, link.mav)
                            if msg is not None:
                                link.send(msg)
                            if msg_id == mavlink.MAVLINK_MSG_ID_MISSION_CURRENT:
                                self._repeat_reached(link)

    @staticmethod
    def instance_params(instance: int) -> dict[str, float]:
        """Parameters SITL instance ``instance`` boots with: PX4's MAV_SYS_ID is i + 1."""
        return {"MAV_SYS_ID": instance + 1}

    @property
    def state(self) -> VehicleState | None:
        """The vehicle's newest telemetry sample (None before the first)."""
        return self._state

    def describe(self, host: str) -> str:
        """The line ``autopilot sim`` prints: where clients find the vehicle."""
        offboard, gcs = self.ports["offboard"], self.ports["gcs"]
        signed = "signed" if self.signing is not None else "unsigned"
        return (f"{self.title} (system {self.system_id}, component 1, MAVLink 2, {signed}): "
                f"offboard API on udp {host}:{offboard[0]} → {offboard[1][0]}:{offboard[1][1]} "
                f"(MAVSDK: udpin://0.0.0.0:{offboard[1][1]}), ground station on udp "
                f"{host}:{gcs[0]} → {gcs[1][0]}:{gcs[1][1]}; Ctrl-C to stop")

    def set_interval(self, link: FaceLink, msg_id: int, interval_us: float) -> int:
        """SET_MESSAGE_INTERVAL on ``link``: the MAV_RESULT."""
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

    def message(self, msg_id: int, mav):
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
                self.say(None, text, 6)  # MAV_SEVERITY_INFO

    async def _housekeeping(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            self.missions.tick()

def _statustext(text: str) -> bytes:
    """A status text in ASCII (ground stations show other bytes as garbage), at most four
    STATUSTEXT chunks long."""
    return text.replace("→", "->").replace("−", "-").encode("ascii", "replace")[:200]

