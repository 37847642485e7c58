"""An ArduCopter SITL look-alike on MAVLink 2, in front of the simulated ArduCopter
(``autopilot sim --firmware ardupilot``), read from ArduPilot's source
(``docs/reference/ardupilot-mavlink.md``):

* ports as ``sim_vehicle.py`` leaves them: TCP 5760 (SERIAL0: MAVProxy's or a ground
  station's), 5762 and 5763 (SERIAL1, 2), +10 per instance; and UDP from the vehicle to 14550
  (+10 per instance), where ``sim_vehicle.py``'s MAVProxy sends what it hears: clients bind
  that port (``udpin:0.0.0.0:14550``) and the vehicle replies to whoever writes to it;
* identity: SYSID_THISMAV, component 1, the ardupilotmega dialect; HEARTBEAT as an ArduCopter
  quad: autopilot ARDUPILOTMEGA, custom mode the Copter mode number, base mode 81 (+8 while
  the position controller flies, +128 armed), STANDBY on the ground, ACTIVE in the air,
  CRITICAL in a failsafe;
* streams as ArduCopter serves them: nothing but HEARTBEAT until asked — REQUEST_DATA_STREAM
  by group (EXTENDED_STATUS, POSITION, EXTRA1–3; ALL), SET_MESSAGE_INTERVAL per message (it
  wins over the group's rate), SRn_* as each TCP port's defaults (0, as Copter); the UDP link
  starts with every group at 4 Hz, as ``sim_vehicle.py``'s MAVProxy asks for them;
* commands, GUIDED targets and LANDING_TARGET as ArduCopter takes them
  (:mod:`~drivers.mavlink.face_ardupilot_commands`); parameters and missions as ArduPilot
  speaks them (:mod:`~drivers.mavlink.face_ardupilot_protocols`: floats, home at seq 0);
* ground stations' heartbeats feed the GCS failsafe only from SYSID_MYGCS (255: MAVProxy's).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from drivers.base import LandingTarget, VehicleState
from drivers.mavlink import px4
from drivers.mavlink.face import MavlinkFace
from drivers.mavlink.face_ardupilot_commands import (
    BODY_FRD,
    LOCAL_FRD,
    ArduCommands,
    global_setpoint,
    guided_setpoint,
    landing_target_ned,
)
from drivers.mavlink.face_ardupilot_protocols import (
    ArduIncoming,
    ArduMissionServer,
    ArduParamServer,
    ArduTelemetry,
)
from drivers.mavlink.face_link import FaceLink, FaceStreamLink, FaceStreams

log = logging.getLogger(__name__)

M = mavlink
AUTO, GUIDED = 3, 4  # Copter mode numbers
#: REQUEST_DATA_STREAM's groups (MAV_DATA_STREAM id → SRn_ name, the messages the simulator
#: sends in it); RAW_SENSORS and RC_CHANNELS carry nothing the simulator has
STREAM_GROUPS: dict[int, tuple[str, tuple[int, ...]]] = {
    M.MAV_DATA_STREAM_RAW_SENSORS: ("RAW_SENS", ()),
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("EXT_STAT", (
        M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_MISSION_CURRENT,
        M.MAVLINK_MSG_ID_GPS_RAW_INT)),
    M.MAV_DATA_STREAM_RC_CHANNELS: ("RC_CHAN", ()),
    M.MAV_DATA_STREAM_RAW_CONTROLLER: ("RAW_CTRL", ()),
    M.MAV_DATA_STREAM_POSITION: ("POSITION", (
        M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED)),
    M.MAV_DATA_STREAM_EXTRA1: ("EXTRA1", (M.MAVLINK_MSG_ID_ATTITUDE,)),
    M.MAV_DATA_STREAM_EXTRA2: ("EXTRA2", (M.MAVLINK_MSG_ID_VFR_HUD,)),
    M.MAV_DATA_STREAM_EXTRA3: ("EXTRA3", (
        M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_DISTANCE_SENSOR,
        M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, M.MAVLINK_MSG_ID_ALTITUDE)),
}
#: what SET_MESSAGE_INTERVAL and REQUEST_MESSAGE may ask for beyond the groups
_OTHER_MESSAGES = (M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                   M.MAVLINK_MSG_ID_HOME_POSITION, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
KNOWN_MESSAGES = frozenset({m for _, ids in STREAM_GROUPS.values() for m in ids}
                           | set(_OTHER_MESSAGES))
#: the rate sim_vehicle.py's MAVProxy asks every group for (its ``streamrate``)
MAVPROXY_STREAM_HZ = 4.0
#: HEARTBEAT base mode: custom mode, stabilize and manual input always (ArduCopter)
_BASE_MODE = (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
              | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED)


def serial0_port(instance: int = 0) -> int:
    """ArduCopter SITL's SERIAL0 TCP port for instance ``instance`` (5760, + 10 per instance)."""
    return 5760 + 10 * instance


class ArduPilotFace(MavlinkFace):
    """Serves ``vehicle`` (the simulator driver on the ArduCopter firmware) as ArduCopter SITL
    instance ``instance``."""

    dialect = mavlink
    system_id_param = "SYSID_THISMAV"
    title = "ArduCopter SITL-compatible simulated vehicle"

    def __init__(self, vehicle, *, instance: int = 0, host: str = "127.0.0.1",
                 gcs_port: int = 14550, peer_host: str | None = None, events=None,
                 signing=None) -> None:
        super().__init__(vehicle, instance=instance, host=host, gcs_port=gcs_port,
                         peer_host=peer_host, events=events, signing=signing)
        peer = peer_host or ("127.0.0.1" if host in ("0.0.0.0", "") else host)
        base = serial0_port(instance)
        #: SERIALn → its TCP port
        self.serial_ports = {0: base, 1: base + 2, 2: base + 3}
        #: the UDP link: from an ephemeral port to the ground station's 14550
        self.ports = {"udp": (0, (peer, gcs_port + 10 * instance))}
        self._streams = {"udp": self._group_streams(MAVPROXY_STREAM_HZ)}
        self._servers: list[asyncio.base_events.Server] = []
        self._connections = 0
        origin = vehicle.global_origin
        self.telemetry = ArduTelemetry(vehicle, origin, self._boot_ms, instance)
        self.commands = ArduCommands(vehicle, origin, lambda: self._state)
        self.params = ArduParamServer(vehicle, self._send, self.spawn, self.say)
        self.missions = ArduMissionServer(vehicle, self._send, self.spawn, self.say)
        self.incoming = ArduIncoming(self)
        self._home: tuple | None = None
        self._plnd_frame_said = False

    @staticmethod
    def companion_url(instance: int = 0) -> str:
        """SERIAL0, where ``sim_vehicle.py``'s MAVProxy (or a companion) connects."""
        return f"tcpout://127.0.0.1:{serial0_port(instance)}"

    @staticmethod
    def instance_params(instance: int) -> dict[str, float]:
        return {}  # sim_vehicle.py -I N keeps SYSID_THISMAV 1 (unless --sysid)

    # -- life cycle ------------------------------------------------------------------------

    async def start(self) -> None:
        await super().start()
        loop = asyncio.get_running_loop()
        for n, port in self.serial_ports.items():
            try:
                server = await loop.create_server(lambda n=n: self._accept(n), self.host, port)
            except OSError as exc:
                await self.close()
                raise OSError(f"cannot listen on TCP {self.host}:{port} (SERIAL{n}): "
                              f"{exc.strerror or exc} (is ArduCopter SITL or another simulator "
                              "running? --instance N picks other ports)") from exc
            self._servers.append(server)

    async def close(self) -> None:
        for server in self._servers:
            server.close()
        self._servers = []
        await super().close()

    def _accept(self, serial: int) -> FaceStreamLink:
        self._connections += 1
        name = f"SERIAL{serial}#{self._connections}"
        link = FaceStreamLink(name, self, on_close=self._closed)
        self._streams[name] = self._group_streams(
            None, {group: float(self.vehicle.param(f"SR{serial}_{key}"))
                   for group, (key, _) in STREAM_GROUPS.items()})
        self.links[name] = link
        log.info("%s: connection", name)
        return link

    def _closed(self, link: FaceLink) -> None:
        self.links.pop(link.name, None)
        self._streams.pop(link.name, None)

    def describe(self, host: str) -> str:
        tcp = ", ".join(f"{p} (SERIAL{n})" for n, p in self.serial_ports.items())
        udp = self.ports["udp"][1]
        signed = "signed" if self.signing is not None else "unsigned"
        return (f"{self.title} (system {self.system_id}, component 1, MAVLink 2, {signed}): "
                f"tcp {host}:{tcp} (MAVProxy: --master tcp:{host}:{self.serial_ports[0]}); "
                f"udp out to {udp[0]}:{udp[1]} (pymavlink: udpin:0.0.0.0:{udp[1]}, MAVSDK: "
                f"udpin://0.0.0.0:{udp[1]}); Ctrl-C to stop")

    # -- streams ---------------------------------------------------------------------------

    @staticmethod
    def _group_streams(all_hz: float | None, groups: dict[int, float] | None = None
                       ) -> FaceStreams:
        streams = FaceStreams(rates_hz={})
        for group, (_, ids) in STREAM_GROUPS.items():
            rate = all_hz if all_hz is not None else (groups or {}).get(group, 0.0)
            for msg_id in ids:
                streams.rates_hz[msg_id] = rate
        return streams

    def request_data_stream(self, link: FaceLink, stream_id: int, rate_hz: int,
                            start_stop: int) -> None:
        """REQUEST_DATA_STREAM: a group (or ALL but PARAMS) at ``rate_hz``, or stopped."""
        if start_stop not in (0, 1):
            return
        streams = self._streams.get(link.name)
        if streams is None:
            return
        rate = float(rate_hz) if start_stop == 1 else 0.0
        groups = list(STREAM_GROUPS) if stream_id == M.MAV_DATA_STREAM_ALL else [stream_id]
        for group in groups:
            for msg_id in STREAM_GROUPS.get(group, ("", ()))[1]:
                if msg_id not in streams.overridden:
                    streams.rates_hz[msg_id] = rate
                    streams.next_s.pop(msg_id, None)

    def set_interval(self, link: FaceLink, msg_id: int, interval_us: float) -> int:
        """SET_MESSAGE_INTERVAL (0: back to the group's rate, −1: stop; at most 1 kHz)."""
        streams = self._streams.get(link.name)
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            return 0
        if msg_id not in KNOWN_MESSAGES or streams is None:
            self.say(link, f"No ap_message for mavlink id ({msg_id})", 6)
            return px4.MAV_RESULT_DENIED
        if interval_us == 0:
            streams.overridden.discard(msg_id)
            streams.rates_hz[msg_id] = 0.0
        else:
            streams.overridden.add(msg_id)
            streams.rates_hz[msg_id] = 0.0 if interval_us < 0 else \
                1e6 / min(max(interval_us, 1000.0), 60e6)
        streams.next_s.pop(msg_id, None)
        return px4.MAV_RESULT_ACCEPTED

    # -- outgoing --------------------------------------------------------------------------

    def _heartbeat(self, mav):
        s: VehicleState | None = self._state
        flight = self.vehicle.simulator.flight
        base = _BASE_MODE
        if s is not None and s.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
            if flight.position_controlled:
                base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        status = (M.MAV_STATE_CRITICAL if s is not None and s.failsafe else
                  M.MAV_STATE_STANDBY if s is None or not s.in_air else M.MAV_STATE_ACTIVE)
        return mav.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base,
                                    flight.custom_mode, status)

    async def _mission_events(self) -> None:
        """MISSION_CURRENT when the item changes, MISSION_ITEM_REACHED and ArduCopter's
        "Mission: N …" / "Reached command #N" texts, in ArduPilot's numbering (home is 0)."""
        async with contextlib.aclosing(self.vehicle.mission_events()) as events:
            async for event in events:
                if event.kind == "current":
                    self._send_all(self.telemetry.mission_current)
                    if self.vehicle.simulator.flight.custom_mode == AUTO:
                        self.say(None, f"Mission: {event.seq + 1} "
                                 f"{self.missions.command_name(event.seq)}", 6)
                elif event.kind == "reached":
                    self._send_all(lambda mav, seq=event.seq + 1:
                                   mav.mission_item_reached_encode(seq))
                    self.say(None, f"Reached command #{event.seq + 1}", 6)
                elif event.kind == "finished":
                    self._send_all(self.telemetry.mission_current)

    async def _housekeeping(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            self.missions.tick()
            home = self.vehicle.home()
            key = None if home is None else tuple(round(float(v), 3) for v in home[3])
            if key != self._home:  # ArduPilot sends HOME_POSITION when home is set or moves
                self._home = key
                if home is not None:
                    self._send_all(self.telemetry.home_position)

    # -- what the incoming handlers call ---------------------------------------------------

    def gcs_system_id(self) -> int:
        return int(self.vehicle.param("SYSID_MYGCS"))

    def guided_target(self, msg) -> None:
        """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT: a GUIDED target."""
        s = self._state
        if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
            home = self.vehicle.home()
            sp = global_setpoint(msg, self.telemetry.origin,
                                 float(home[3][2]) if home is not None else 0.0, s)
        else:
            sp = guided_setpoint(msg.coordinate_frame, msg.type_mask, (msg.x, msg.y, msg.z),
                                 (msg.vx, msg.vy, msg.vz), (msg.afx, msg.afy, msg.afz),
                                 msg.yaw, msg.yaw_rate, s)
        self.stats.setpoints += 1
        self.spawn(self.vehicle.send_setpoint(sp))

    def landing_target(self, link: FaceLink, msg) -> None:
        if msg.frame not in (BODY_FRD, LOCAL_FRD):
            if not self._plnd_frame_said:
                self._plnd_frame_said = True
                self.say(link, "Plnd: Frame not supported", 6)
            self.stats.ignored += 1
            return
        s = self._state
        ned = landing_target_ned(msg, s) if s is not None else None
        if ned is None:
            self.stats.ignored += 1
            return
        self.stats.landing_targets += 1
        target = LandingTarget(self.vehicle.clock.now(), tuple(float(v) for v in ned),
                               msg.target_num)
        self.spawn(self.vehicle.send_landing_target(target))

    def in_guided(self) -> bool:
        return self.vehicle.simulator.flight.custom_mode == GUIDED
