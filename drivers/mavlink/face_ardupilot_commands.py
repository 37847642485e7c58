"""The commands and targets of the ArduCopter face (:mod:`drivers.mavlink.face_ardupilot`), as
ArduCopter's ``GCS_MAVLink_Copter.cpp`` and ``GCS_Common.cpp`` answer them
(``docs/reference/ardupilot-mavlink.md`` §2–3, §9):

* a refusal is FAILED with the vehicle's reason as STATUSTEXT (``Arm: …`` CRITICAL, ``Mode
  change to … failed: …`` WARNING), a bad parameter DENIED, an unknown command UNSUPPORTED;
* COMPONENT_ARM_DISARM: 2989 forces an arming, 21196 a disarm; DO_SET_MODE and SET_MODE carry
  the Copter mode number; NAV_TAKEOFF's altitude is above home (COMMAND_INT: frame
  GLOBAL_RELATIVE_ALT only); MISSION_START (p1 = p2 = 0) starts AUTO, from the ground too;
  DO_REPOSITION only as COMMAND_INT (flag 1 switches to GUIDED);
* SET_POSITION_TARGET_* with ArduCopter's type-mask rules (any ignored position axis ignores
  all three, and so on; FORCE with an acceleration, NaN velocities and unknown frames stop
  the vehicle), in LOCAL_NED, LOCAL_OFFSET_NED and BODY(_OFFSET)_NED (offsets from the
  vehicle, turned by its heading, yaw relative);
* LANDING_TARGET in BODY_FRD or LOCAL_FRD, relative to the vehicle (a position, or angles
  with a distance), turned into the local NED target the vehicle lands on.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from drivers.base import CommandDenied, Setpoint, VehicleState
from drivers.geo import GlobalOrigin
from drivers.geometry import quat_to_matrix, rot_z
from drivers.mavlink import px4

ACCEPTED, DENIED, UNSUPPORTED, FAILED = 0, 2, 3, 4
GUIDED = 4  # the Copter mode number
FORCE_ARM, FORCE_DISARM = 2989, 21196
NAN = float("nan")
_STOP = Setpoint(velocity_m_s=[0.0, 0.0, 0.0])  # mode_guided.init(): brake and hold

LOCAL_NED, LOCAL_OFFSET_NED, BODY_NED, BODY_OFFSET_NED = 1, 7, 8, 9
BODY_FRD, LOCAL_FRD = 12, 20
_AMSL_FRAMES = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
_RELATIVE_FRAMES = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    # terrain: the simulated ground is flat at home's height
                    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


class CommandFailed(CommandDenied):
    """A command ArduCopter answers FAILED, with its words and their severity."""

    def __init__(self, command: str, reason: str, severity: int = 4) -> None:
        super().__init__(command, reason)
        self.severity = severity


def guided_setpoint(frame: int, mask: int, pos, vel, acc, yaw: float, yaw_rate: float,
                    state: VehicleState | None) -> Setpoint:
    """What SET_POSITION_TARGET_LOCAL_NED asks of an ArduCopter in GUIDED, in local NED."""
    pos_ignore, vel_ignore = bool(mask & 0x7), bool(mask & 0x38)
    acc_ignore, force = bool(mask & 0x1C0), bool(mask & 0x200)
    if force and not acc_ignore:
        return _STOP
    if frame not in (LOCAL_NED, LOCAL_OFFSET_NED, BODY_NED, BODY_OFFSET_NED):
        return _STOP
    p, v, a = np.array(pos, float), np.array(vel, float), np.array(acc, float)
    if not vel_ignore and (not np.isfinite(v).all() or np.abs(v).max() > 1000.0):
        return _STOP
    heading = state.yaw_rad if state is not None else 0.0
    here = np.array(state.position_ned_m, float) if state is not None else np.zeros(3)
    relative_yaw = False
    if frame == LOCAL_OFFSET_NED:
        p = here + p
    elif frame in (BODY_NED, BODY_OFFSET_NED):
        turn = rot_z(heading)
        p, v, a = here + turn @ p, turn @ v, turn @ a
        relative_yaw = True
    use_yaw, use_rate = not mask & px4.IGNORE_YAW, not mask & px4.IGNORE_YAW_RATE
    yaw_sp = (heading + yaw if relative_yaw else yaw) if use_yaw else NAN
    rate_sp = yaw_rate if use_rate else NAN
    # an acceleration with a velocity is its feed-forward (set_destination_posvelaccel,
    # set_velaccel)
    a = a if not acc_ignore and np.isfinite(a).all() else np.full(3, NAN)
    if not pos_ignore and not vel_ignore:
        return Setpoint(position_ned_m=p, velocity_m_s=v, yaw_rad=yaw_sp, yaw_rate_rad_s=rate_sp,
                        acceleration_m_s2=a)
    if pos_ignore and not vel_ignore:
        return Setpoint(velocity_m_s=v, yaw_rad=yaw_sp, yaw_rate_rad_s=rate_sp,
                        acceleration_m_s2=a)
    if not pos_ignore:
        return Setpoint(position_ned_m=p, yaw_rad=yaw_sp, yaw_rate_rad_s=rate_sp)
    if not acc_ignore:
        raise px4.SetpointNotSupported("acceleration-only targets are not flown by the "
                                       "simulator")
    return _STOP


def global_setpoint(msg, origin: GlobalOrigin, home_down_m: float,
                    state: VehicleState | None) -> Setpoint:
    """SET_POSITION_TARGET_GLOBAL_INT as ArduCopter takes it (AMSL, above home; terrain as
    above home over the simulator's flat ground)."""
    if msg.coordinate_frame in _AMSL_FRAMES:
        down = origin.alt_amsl_m - msg.alt
    elif msg.coordinate_frame in _RELATIVE_FRAMES:
        down = home_down_m - msg.alt
    else:
        return _STOP
    lat, lon = msg.lat_int / 1e7, msg.lon_int / 1e7
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        return _STOP
    n, e, _ = origin.to_ned(lat, lon, origin.alt_amsl_m)
    return guided_setpoint(LOCAL_NED, msg.type_mask, (n, e, down), (msg.vx, msg.vy, msg.vz),
                           (msg.afx, msg.afy, msg.afz), msg.yaw, msg.yaw_rate, state)


def landing_target_ned(msg, state: VehicleState) -> np.ndarray | None:
    """LANDING_TARGET (BODY_FRD or LOCAL_FRD, relative to the vehicle) as a local NED
    position; None when it carries no measurement ArduPilot would use."""
    if getattr(msg, "position_valid", 0):
        rel = np.array([msg.x, msg.y, msg.z], float)
        if not np.isfinite(rel).all() or float(np.linalg.norm(rel)) <= 0.0:
            return None
    else:
        if not msg.distance > 0:
            return None  # angles without a distance need a rangefinder: not modelled
        los = np.array([-math.tan(msg.angle_y), math.tan(msg.angle_x), 1.0])
        rel = los / np.linalg.norm(los) * float(msg.distance)
    turn = quat_to_matrix(np.asarray(state.attitude_q, float)) if msg.frame == BODY_FRD \
        else rot_z(state.yaw_rad)
    return np.array(state.position_ned_m, float) + turn @ rel


class ArduCommands:
    """Carries out the commands on ``vehicle`` (the simulator driver, on its ArduCopter
    firmware); ``state()`` is the newest telemetry sample."""

    def __init__(self, vehicle, origin: GlobalOrigin, state) -> None:
        self.vehicle = vehicle
        self.origin = origin
        self._state = state

    async def _firmware(self, name: str, what: str, *args, severity: int = 4) -> None:
        try:
            await self.vehicle.firmware_command(name, *args)
        except CommandDenied as exc:
            raise CommandFailed(what, exc.reason, severity) from None

    async def set_mode(self, base_mode: int, number: int) -> int:
        if not base_mode & px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return DENIED
        await self._firmware("set_copter_mode", "set mode", int(number))
        return ACCEPTED

    async def execute(self, command: int, p: tuple[float, ...], frame: int | None = None,
                      request=None) -> int:
        v, c = self.vehicle, mavlink
        q = tuple(x if math.isfinite(x) else 0.0 for x in p)
        if command == c.MAV_CMD_COMPONENT_ARM_DISARM:
            return await self._arm(q)
        if command == c.MAV_CMD_DO_SET_MODE:
            return await self.set_mode(int(q[0]), int(q[1]))
        if command == c.MAV_CMD_NAV_TAKEOFF:
            if frame is not None and frame != c.MAV_FRAME_GLOBAL_RELATIVE_ALT:
                return DENIED
            await self._firmware("takeoff", "takeoff", q[6])
            return ACCEPTED
        modes = {c.MAV_CMD_NAV_LAND: "land", c.MAV_CMD_NAV_RETURN_TO_LAUNCH: "return_to_launch",
                 c.MAV_CMD_NAV_LOITER_UNLIM: "hold"}
        if command in modes:
            await self._firmware(modes[command], "set mode")
            return ACCEPTED
        if command == c.MAV_CMD_MISSION_START:
            if q[0] != 0 or q[1] != 0:
                return DENIED
            await self._firmware("mission_start", "mission start")
            return ACCEPTED
        if command == c.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = int(q[0])  # ArduPilot's numbering: 0 is home
            if not 1 <= seq <= v.mission_status.total:
                return DENIED
            await v.set_mission_current(seq - 1)
            return ACCEPTED
        if command == c.MAV_CMD_DO_REPOSITION:
            return await self._reposition(p, q, frame)
        if command == c.MAV_CMD_CONDITION_YAW:
            if not 0.0 <= q[0] <= 360.0 or q[3] not in (0.0, 1.0):
                return FAILED
            await self._firmware("condition_yaw", "condition yaw", math.radians(q[0]),
                                 q[3] != 0, q[2] if q[2] else 1.0)
            return ACCEPTED
        if command == c.MAV_CMD_DO_CHANGE_SPEED:
            if not q[1] > 0:
                return FAILED
            if q[0] < 1.9:  # 2, 3: climb and descent speeds (not modelled: kept)
                await v.set_speed(q[1])
            return ACCEPTED
        if command == c.MAV_CMD_DO_FENCE_ENABLE:
            if int(q[0]) not in (0, 1, 2):
                return DENIED
            await v.set_param("FENCE_ENABLE", 1 if int(q[0]) == 1 else 0)
            return ACCEPTED
        if command == c.MAV_CMD_DO_FLIGHTTERMINATION:
            if q[0] >= 0.5:
                await v.disarm(force=True)
            return ACCEPTED
        if command == c.MAV_CMD_GET_HOME_POSITION:
            if request is None or v.home() is None:
                return FAILED
            request.send_now(c.MAVLINK_MSG_ID_HOME_POSITION)
            return ACCEPTED
        if command == c.MAV_CMD_RUN_PREARM_CHECKS:
            state = self._state()
            return ACCEPTED if state is None or not state.armed else 1  # TEMPORARILY_REJECTED
        return await self._camera_or_request(command, q, p, request)

    async def _arm(self, q: tuple[float, ...]) -> int:
        v = self.vehicle
        state = self._state()
        if q[0] == 1.0:
            if state is not None and state.armed:
                return ACCEPTED
            try:
                await v.arm()  # (2989 forces it: the simulator's checks are all mandatory)
            except CommandDenied as exc:
                raise CommandFailed("arm", exc.reason, 2) from None
            return ACCEPTED
        if q[0] == 0.0:
            if state is not None and not state.armed:
                return ACCEPTED
            try:
                await v.disarm(force=round(q[1]) == FORCE_DISARM)
            except CommandDenied:
                return FAILED
            return ACCEPTED
        return UNSUPPORTED

    async def _reposition(self, p, q, frame: int | None) -> int:
        if frame is None:
            return UNSUPPORTED  # COMMAND_LONG carries no frame for a location on Copter
        state = self._state()
        in_guided = state is not None and self.vehicle.simulator.flight.custom_mode == GUIDED
        if not in_guided and not int(q[1]) & 1:
            return DENIED
        lat, lon = p[4] / 1e7, p[5] / 1e7
        if frame in _AMSL_FRAMES:
            down = self.origin.alt_amsl_m - p[6]
        elif frame in _RELATIVE_FRAMES:
            home = self.vehicle.home()
            down = (float(home[3][2]) if home is not None else 0.0) - p[6]
        else:
            return DENIED
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return DENIED
        n, e, _ = self.origin.to_ned(lat, lon, self.origin.alt_amsl_m)
        await self._firmware("reposition", "reposition", (n, e, down))
        return ACCEPTED

    async def _camera_or_request(self, command: int, q, p, request) -> int:
        v, c = self.vehicle, mavlink
        if command == c.MAV_CMD_IMAGE_START_CAPTURE:
            await v.start_photos(q[1], int(q[2]))
        elif command == c.MAV_CMD_IMAGE_STOP_CAPTURE:
            await v.stop_photos()
        elif command == c.MAV_CMD_DO_DIGICAM_CONTROL:
            if q[4] >= 0.5:
                await v.take_photo()
        elif command == c.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
            await v.set_trigger_distance(q[0], trigger_now=q[2] >= 0.5)
        elif command == c.MAV_CMD_SET_MESSAGE_INTERVAL and request is not None:
            return request.set_interval(int(q[0]), p[1] if math.isfinite(p[1]) else 0.0)
        elif command in (c.MAV_CMD_REQUEST_MESSAGE, c.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES) \
                and request is not None:
            msg_id = c.MAVLINK_MSG_ID_AUTOPILOT_VERSION \
                if command == c.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES else int(q[0])
            return ACCEPTED if request.send_now(msg_id) else FAILED
        else:
            return UNSUPPORTED
        return ACCEPTED
