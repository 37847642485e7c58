"""The ArduCopter face's protocols (:mod:`drivers.mavlink.face_ardupilot`), where ArduPilot
speaks them otherwise than PX4 (``docs/reference/ardupilot-mavlink.md`` §4, §5, §9):

* **parameters** (``GCS_Param.cpp``): every value cast to float (no bytewise integers), the
  type INT8 / INT16 / INT32 / REAL32 of ArduPilot's table; PARAM_REQUEST_LIST first sends the
  banner ("ArduCopter V4.5.7 (…)", "QUAD/X"); a PARAM_SET is taken whatever type it says, and
  an unknown name gets no answer;
* **missions** (``AP_Mission``): item 0 is home — the vehicle counts it, sends it back as a
  NAV_WAYPOINT in GLOBAL at home's AMSL altitude, and ignores what is uploaded there; the
  flown items are 1…n (DO_JUMP targets and MISSION_CURRENT in that numbering); items are
  returned in the non-INT frames, in MISSION_ITEM_INT too; an accepted upload says "Flight
  plan received"; MISSION_ITEM(_INT) with ``current`` 2 in GUIDED is a "guided waypoint"
  (MAVProxy's ``guided``), 3 an altitude change;
* **telemetry**: EKF_STATUS_REPORT, AUTOPILOT_VERSION as ArduCopter 4.5.7's, MISSION_CURRENT's
  seq counting home;
* **what arrives**: SET_MODE with the Copter number (no ACK, as 4.5), COMMAND_* refusals as
  FAILED with the reason as STATUSTEXT, REQUEST_DATA_STREAM, heartbeats from SYSID_MYGCS
  only.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import TYPE_CHECKING, ClassVar

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from drivers.base import CommandDenied, Setpoint, VehicleError
from drivers.mavlink import px4
from drivers.mavlink.face_ardupilot_commands import FAILED, CommandFailed
from drivers.mavlink.face_incoming import IncomingMessages
from drivers.mavlink.face_link import FaceRequests
from drivers.mavlink.face_mission import MissionServer, item_from_message
from drivers.mavlink.face_params import ParamServer, param_name
from drivers.mavlink.face_telemetry import TelemetryEncoder
from drivers.mission import MISSION_ACCEPTED, MISSION_ERROR, Frame, MissionItem, MissionType
from drivers.sim.flight.params import ParamType

if TYPE_CHECKING:
    from drivers.mavlink.face_ardupilot import ArduPilotFace
    from drivers.mavlink.face_link import FaceLink

log = logging.getLogger(__name__)

M = mavlink
VERSION = (4, 5, 7)
BANNER = (f"ArduCopter V{'.'.join(map(str, VERSION))} (simulated)", "QUAD/X")
_TYPES = {ParamType.INT8: M.MAV_PARAM_TYPE_INT8, ParamType.INT16: M.MAV_PARAM_TYPE_INT16,
          ParamType.INT32: M.MAV_PARAM_TYPE_INT32, ParamType.FLOAT: M.MAV_PARAM_TYPE_REAL32}
MAV_CMD_DO_JUMP = 177
_INT_TO_FLOAT_FRAME = {Frame.GLOBAL_INT: Frame.GLOBAL,
                       Frame.GLOBAL_RELATIVE_ALT_INT: Frame.GLOBAL_RELATIVE_ALT,
                       Frame.GLOBAL_TERRAIN_ALT_INT: Frame.GLOBAL_TERRAIN_ALT}
_GLOBAL = (Frame.GLOBAL, Frame.GLOBAL_RELATIVE_ALT, Frame.GLOBAL_TERRAIN_ALT)
#: ``cmd.type()`` names for "Mission: N …"
_COMMAND_NAMES = {16: "WP", 17: "LoitUnlim", 18: "LoitTurns", 19: "LoitTime", 20: "RTL",
                  21: "Land", 22: "Takeoff", 82: "SplineWP", 93: "NavDelay", 112: "CondDelay",
                  115: "CondYaw", 177: "Jump", 178: "ChangeSpeed", 203: "DigiCamCtrl",
                  206: "SetCamTrigDst", 2000: "ImageStartCapture", 2001: "ImageStopCapture"}


class ArduTelemetry(TelemetryEncoder):
    def encode(self, msg_id: int, mav, s):
        if msg_id == M.MAVLINK_MSG_ID_EKF_STATUS_REPORT:
            if s is None:
                return None
            ok = s.health.local_position_ok
            # attitude, velocities, relative and absolute horizontal position, absolute
            # vertical, predicted positions; UNINITIALIZED until the position is good
            flags = 0x33F | 0x300 if ok else 0x400 | 0x1
            return mav.ekf_status_report_encode(flags, 0.1 if ok else 1.0,
                                                0.1 if ok else 1.0, 0.1, 0.05, 0.0)
        return super().encode(msg_id, mav, s)

    def sys_status(self, mav, s):
        """SYS_STATUS; the geofence present and enabled only with FENCE_ENABLE (as AC_Fence
        reports it), the prearm bit as ArduCopter's checks stand."""
        msg = super().sys_status(mav, s)
        if not int(self.vehicle.param("FENCE_ENABLE")):
            fence = ~px4.SENSOR_GEOFENCE
            msg.onboard_control_sensors_present &= fence
            msg.onboard_control_sensors_enabled &= fence
        return msg

    def mission_current(self, mav):
        status = self.vehicle.mission_status
        seq = status.current + 1 if status.total else 0
        state = int(status.state) if status.total else 1  # NO_MISSION
        return mav.mission_current_encode(seq, status.total, state,
                                          1 if status.in_mission_mode else 0)

    def autopilot_version(self, mav):
        caps = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | M.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
                | M.MAV_PROTOCOL_CAPABILITY_COMPASS_CALIBRATION
                | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
                | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY | M.MAV_PROTOCOL_CAPABILITY_FTP)
        major, minor, patch = VERSION
        version = (major << 24) | (minor << 16) | (patch << 8) | 255  # official
        return mav.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                            0x1209, 0x5741, 0x5349_4D00 + self.instance)


class ArduParamServer(ParamServer):
    def value_message(self, mav, name: str):
        spec = self._specs[self._index[name]]
        return mav.param_value_encode(name.encode(), float(self.store.param(name)),
                                      _TYPES[spec.type], len(self._specs), self._index[name])

    def on_request_list(self, link, msg) -> None:
        for text in BANNER:
            self._say(link, text, 6)
        super().on_request_list(link, msg)

    def on_set(self, link, msg) -> None:
        name = param_name(msg.param_id)
        if name not in self._index or not math.isfinite(msg.param_value):
            return  # ArduPilot 4.5: no answer
        spec = self._specs[self._index[name]]
        value = float(msg.param_value)
        if spec.type.integer:
            value = float(round(value))  # ArduPilot casts to the parameter's own type
        self._spawn(self._set(link, name, value))

    @staticmethod
    def refusal_text(name: str, reason: str) -> str:
        return f"{name}: {reason}"


def _shift_jump(item: MissionItem, by: int) -> MissionItem:
    if item.command == MAV_CMD_DO_JUMP and math.isfinite(item.param1):
        return dataclasses.replace(item, param1=item.param1 + by)
    return item


class ArduMissionServer(MissionServer):
    """Home at seq 0 of the mission list (fence and rally lists as they are)."""

    def command_name(self, seq: int) -> str:
        items = self.store.mission_items(MissionType.MISSION)
        command = items[seq].command if 0 <= seq < len(items) else 0
        return _COMMAND_NAMES.get(command, str(command))

    async def _store(self, link, peer, items: list[MissionItem], mission_type: int) -> None:
        if mission_type == MissionType.MISSION:
            items = [_shift_jump(dataclasses.replace(item, seq=item.seq - 1), -1)
                     for item in items[1:]]
        await super()._store(link, peer, items, mission_type)

    def _ack(self, link, peer, result: int, mission_type: int) -> None:
        super()._ack(link, peer, result, mission_type)
        if result == MISSION_ACCEPTED and mission_type == MissionType.MISSION:
            self._say(link, "Flight plan received", 6)

    def _items(self, mission_type: int) -> list[MissionItem]:
        items = self.store.mission_items(mission_type)
        if mission_type != MissionType.MISSION:
            return items
        home = self.store.home()
        lat, lon, alt = (home[0], home[1], home[2]) if home is not None else (0.0, 0.0, 0.0)
        shifted = [_shift_jump(dataclasses.replace(i, seq=i.seq + 1), 1) for i in items]
        return [MissionItem(seq=0, frame=Frame.GLOBAL, command=16, param1=0.0, param2=0.0,
                            param3=0.0, param4=0.0, x=lat, y=lon, z=alt), *shifted]

    def on_request_list(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mission_type not in tuple(MissionType):
            self._ack(link, peer, MISSION_ERROR, mission_type)
            return
        self._send(link, link.mav.mission_count_encode(*peer, len(self._items(mission_type)),
                                                       mission_type))

    def on_request(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        items = self._items(mission_type)
        if not 0 <= msg.seq < len(items):
            self._ack(link, peer, MISSION_ERROR, mission_type)
            return
        item = items[msg.seq]
        status = self.store.mission_status
        current = mission_type == MissionType.MISSION and status.total > 0 and \
            msg.seq == status.current + 1
        frame = _INT_TO_FLOAT_FRAME.get(item.frame, item.frame)
        x, y = (0.0 if not math.isfinite(v) else v for v in (item.x, item.y))
        p = [0.0 if not math.isfinite(v) else v for v in (item.param1, item.param2,
                                                           item.param3, item.param4)]
        if msg.get_type() == "MISSION_REQUEST_INT":
            xi, yi = (round(x * 1e7), round(y * 1e7)) if frame in _GLOBAL else \
                (round(x * 1e4), round(y * 1e4))
            out = link.mav.mission_item_int_encode(*peer, msg.seq, frame, item.command,
                                                   int(current), 1, *p, xi, yi, item.z,
                                                   mission_type)
        else:
            out = link.mav.mission_item_encode(*peer, msg.seq, frame, item.command,
                                               int(current), 1, *p, x, y, item.z, mission_type)
        self._send(link, out)

    def on_set_current(self, link, msg) -> None:
        total = len(self.store.mission_items(MissionType.MISSION))
        if not 1 <= msg.seq <= total:
            return
        self._spawn(self.store.set_mission_current(msg.seq - 1))


class ArduIncoming(IncomingMessages):
    face: ArduPilotFace

    def _on_heartbeat(self, link: FaceLink, msg) -> None:
        if msg.get_srcSystem() == self.face.gcs_system_id():  # ArduPilot: SYSID_MYGCS only
            self.face.spawn(self.face.vehicle.gcs_heartbeat())

    async def _command(self, link: FaceLink, msg, params, frame) -> None:
        command = msg.command
        try:
            result = await self.face.commands.execute(command, params, frame,
                                                      FaceRequests(self.face, link))
        except CommandFailed as exc:
            self.face.say(link, exc.reason, exc.severity)
            result = FAILED
        except CommandDenied as exc:
            self.face.say(link, exc.reason, 4)
            result = FAILED
        except (VehicleError, Exception):  # a command we cannot carry out is still answered
            log.warning("command %d failed", command, exc_info=True)
            result = FAILED
        link.send(link.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(),
                                              msg.get_srcComponent()))

    def _on_set_mode(self, link: FaceLink, msg) -> None:
        async def change() -> None:
            try:
                await self.face.commands.set_mode(msg.base_mode, msg.custom_mode)
            except CommandDenied as exc:
                self.face.say(link, exc.reason, 4)

        self.face.spawn(change())

    def _on_setpoint(self, link: FaceLink, msg) -> None:
        try:
            self.face.guided_target(msg)
        except px4.SetpointNotSupported as exc:
            self.face.stats.rejected_setpoints += 1
            log.debug("target ignored: %s", exc)

    def _on_landing_target(self, link: FaceLink, msg) -> None:
        self.face.landing_target(link, msg)

    def _on_request_data_stream(self, link: FaceLink, msg) -> None:
        self.face.request_data_stream(link, msg.req_stream_id, msg.req_message_rate,
                                      msg.start_stop)

    def _on_mission_item(self, link: FaceLink, msg) -> None:
        """A mission item, or with ``current`` 2 a guided waypoint (3: a new altitude)."""
        if msg.current not in (2, 3):
            self.face.missions.on_item(link, msg)
            return
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        item = item_from_message(msg)
        ok = self.face.in_guided() and item.frame in (*_GLOBAL, *_INT_TO_FLOAT_FRAME)
        if ok:
            origin, home = self.face.telemetry.origin, self.face.vehicle.home()
            frame = _INT_TO_FLOAT_FRAME.get(item.frame, item.frame)
            down = origin.alt_amsl_m - item.z if frame == Frame.GLOBAL else \
                (float(home[3][2]) if home is not None else 0.0) - item.z
            state = self.face.state
            if msg.current == 3 and state is not None:
                n, e = (float(v) for v in state.position_ned_m[:2])
            else:
                n, e, _ = origin.to_ned(item.x, item.y, origin.alt_amsl_m)
            self.face.spawn(self.face.vehicle.send_setpoint(
                Setpoint(position_ned_m=[n, e, down])))
        link.send(link.mav.mission_ack_encode(*peer, MISSION_ACCEPTED if ok else MISSION_ERROR,
                                              0))

    _handlers: ClassVar = {
        **IncomingMessages._handlers,
        "HEARTBEAT": _on_heartbeat,
        "SET_MODE": _on_set_mode,
        "SET_POSITION_TARGET_LOCAL_NED": _on_setpoint,
        "SET_POSITION_TARGET_GLOBAL_INT": _on_setpoint,
        "LANDING_TARGET": _on_landing_target,
        "REQUEST_DATA_STREAM": _on_request_data_stream,
        "MISSION_ITEM": _on_mission_item,
        "MISSION_ITEM_INT": _on_mission_item,
    }
