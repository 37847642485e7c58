"""What arrives at the MAVLink face (:mod:`drivers.mavlink.face`): each message checked (bad
data and bad signatures counted, messages for another system or component ignored, as PX4) and
handed to its handler — commands, SET_MODE, offboard setpoints, parameters and the mission
protocol, LANDING_TARGET, TIMESYNC, ground stations' heartbeats. A message that cannot be acted
on is counted and ignored, never allowed to take the vehicle down."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import CommandDenied, LandingTarget, VehicleError
from drivers.mavlink import px4
from drivers.mavlink.face_commands import ModeNotAvailable
from drivers.mavlink.face_link import COMPONENT_ID, FaceRequests

if TYPE_CHECKING:
    from drivers.mavlink.face import MavlinkFace
    from drivers.mavlink.face_link import FaceLink

log = logging.getLogger(__name__)

#: compids PX4 takes mission and parameter messages for besides its own (0: broadcast,
#: 190: MAV_COMP_ID_MISSIONPLANNER)
_OUR_COMPONENTS = (0, COMPONENT_ID, 190)
_MAV_TYPE_GCS = mavlink.MAV_TYPE_GCS
# MAV_RESULT
DENIED, FAILED = px4.MAV_RESULT_DENIED, px4.MAV_RESULT_FAILED
TEMPORARILY_REJECTED = px4.MAV_RESULT_TEMPORARILY_REJECTED


class IncomingMessages:
    """The face's message handlers, by message type."""

    def __init__(self, face: MavlinkFace) -> None:
        self.face = face

    def receive(self, link: FaceLink, msg) -> None:
        self.face.stats.received += 1
        kind = msg.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(msg, "reason", "")).lower()
            if "signature" in reason or "unsigned" in reason:
                self.face.stats.bad_signature += 1
            else:
                self.face.stats.bad_data += 1
            return
        target = getattr(msg, "target_system", self.face.system_id)
        component = getattr(msg, "target_component", COMPONENT_ID)
        if target not in (0, self.face.system_id) or component not in _OUR_COMPONENTS:
            self.face.stats.ignored += 1
            return
        handler = self._handlers.get(kind)
        if handler is None:
            self.face.stats.ignored += 1
            return
        try:
            handler(self, link, msg)
        except Exception:  # a message we cannot act on must never take the vehicle down
            self.face.stats.ignored += 1
            log.warning("ignoring %s from %s", kind, link.peer, exc_info=True)

    def _on_heartbeat(self, link: FaceLink, msg) -> None:
        if msg.type == _MAV_TYPE_GCS:
            self.face.spawn(self.face.vehicle.gcs_heartbeat())

    def _on_command(self, link: FaceLink, msg) -> None:
        self.face.stats.commands += 1
        frame = None
        if msg.get_type() == "COMMAND_INT":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x),
                      float(msg.y), msg.z)
            frame = msg.frame
        else:
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                      msg.param7)
        self.face.spawn(self._command(link, msg, params, frame))

    async def _command(self, link: FaceLink, msg, params: tuple[float, ...],
                       frame: int | None) -> None:
        command = msg.command
        try:
            result = await self.face.commands.execute(command, params, frame,
                                                      FaceRequests(self.face, link))
        except ModeNotAvailable as exc:
            log.info("command %d: %s", command, exc.reason)
            self.face.say(link, exc.reason, 4)
            result = TEMPORARILY_REJECTED
        except CommandDenied as exc:
            log.info("command %d denied: %s", command, exc.reason)
            self.face.say(link, exc.reason, 4)
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
                await self.face.commands.set_mode(msg.base_mode, main, sub)
            except CommandDenied as exc:
                self.face.say(link, exc.reason, 4)

        self.face.spawn(change())

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
            self.face.stats.rejected_setpoints += 1
            log.debug("setpoint ignored: %s", exc)
            return
        self.face.stats.setpoints += 1
        self.face.spawn(self.face.vehicle.send_setpoint(setpoint))

    def _global_setpoint(self, msg):
        """SET_POSITION_TARGET_GLOBAL_INT as a local setpoint (position about the origin)."""
        origin = self.face.telemetry.origin
        n, e, _ = origin.to_ned(msg.lat_int / 1e7, msg.lon_int / 1e7, origin.alt_amsl_m)
        if msg.coordinate_frame in (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            home = self.face.vehicle.home()
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
            target = LandingTarget(self.face.vehicle.clock.now(), (msg.x, msg.y, msg.z),
                                   msg.target_num)
            self.face.stats.landing_targets += 1
            self.face.spawn(self.face.vehicle.send_landing_target(target))
        elif getattr(msg, "position_valid", 0):
            self.face.say(link, f"Landing target: coordinate frame {msg.frame} unsupported", 2)
        else:
            self.face.stats.ignored += 1

    def _on_timesync(self, link: FaceLink, msg) -> None:
        """MAVLink time synchronisation: answer a request (tc1 = 0) with our boot time."""
        if msg.tc1 == 0:
            now_ns = int(self.face.vehicle.clock.now() * 1e9)
            link.send(link.mav.timesync_encode(now_ns, msg.ts1))

    _handlers: ClassVar[dict[str, Callable[[IncomingMessages, FaceLink, object], None]]] = {
        "COMMAND_LONG": _on_command,
        "COMMAND_INT": _on_command,
        "SET_MODE": _on_set_mode,
        "SET_POSITION_TARGET_LOCAL_NED": _on_setpoint,
        "SET_POSITION_TARGET_GLOBAL_INT": _on_setpoint,
        "PARAM_REQUEST_LIST": lambda self, link, msg: self.face.params.on_request_list(link, msg),
        "PARAM_REQUEST_READ": lambda self, link, msg: self.face.params.on_request_read(link, msg),
        "PARAM_SET": lambda self, link, msg: self.face.params.on_set(link, msg),
        "MISSION_COUNT": lambda self, link, msg: self.face.missions.on_count(link, msg),
        "MISSION_ITEM": lambda self, link, msg: self.face.missions.on_item(link, msg),
        "MISSION_ITEM_INT": lambda self, link, msg: self.face.missions.on_item(link, msg),
        "MISSION_REQUEST_LIST":
            lambda self, link, msg: self.face.missions.on_request_list(link, msg),
        "MISSION_REQUEST": lambda self, link, msg: self.face.missions.on_request(link, msg),
        "MISSION_REQUEST_INT": lambda self, link, msg: self.face.missions.on_request(link, msg),
        "MISSION_ACK": lambda self, link, msg: self.face.missions.on_ack(link, msg),
        "MISSION_CLEAR_ALL": lambda self, link, msg: self.face.missions.on_clear_all(link, msg),
        "MISSION_SET_CURRENT": lambda self, link, msg: self.face.missions.on_set_current(link, msg),
        "TIMESYNC": _on_timesync,
        "LANDING_TARGET": _on_landing_target,
        "HEARTBEAT": _on_heartbeat,
    }
