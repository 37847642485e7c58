"""PX4's MAVLink conventions, shared by the simulator's MAVLink face and the MAVLink drivers.

Custom modes are ``(main << 16) | (sub << 24)`` (PX4 ``px4_custom_mode.h``); setpoint type
masks follow MAVLink's POSITION_TARGET_TYPEMASK (a set bit means "ignore this field").
"""

from __future__ import annotations

import math

import numpy as np

from drivers.base import NAN, FlightMode, LandedState, Setpoint, SetpointFrame

MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_QUADROTOR = 2
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
MAV_STATE_CRITICAL = 5

#: COMPONENT_ARM_DISARM param2 that disarms even in flight
FORCE_DISARM_MAGIC = 21196

# MAV_RESULT
MAV_RESULT_ACCEPTED, MAV_RESULT_TEMPORARILY_REJECTED, MAV_RESULT_DENIED = 0, 1, 2
MAV_RESULT_UNSUPPORTED, MAV_RESULT_FAILED, MAV_RESULT_IN_PROGRESS = 3, 4, 5
MAV_RESULT_NAMES = {0: "accepted", 1: "temporarily rejected", 2: "denied", 3: "unsupported",
                    4: "failed", 5: "in progress", 6: "cancelled"}


def mav_result_name(result: int) -> str:
    return MAV_RESULT_NAMES.get(result, f"result {result}")


def timesync_period_s(requests_sent: int, settling: bool = False) -> float:
    """When a driver sends its next TIMESYNC request: ten a second for the first two
    seconds (to find a short round trip quickly) and while the vehicle's clock is seen moving
    against ours (``settling``), then one a second."""
    return 0.1 if requests_sent < 20 or settling else 1.0


MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_NED = 8

#: PX4 (main, sub) modes and our FlightMode.
PX4_MODES: dict[FlightMode, tuple[int, int]] = {
    FlightMode.MANUAL: (1, 0),
    FlightMode.ALTCTL: (2, 0),
    FlightMode.POSCTL: (3, 0),
    FlightMode.TAKEOFF: (4, 2),
    FlightMode.HOLD: (4, 3),
    FlightMode.MISSION: (4, 4),
    FlightMode.RETURN: (4, 5),
    FlightMode.LAND: (4, 6),
    FlightMode.PRECLAND: (4, 9),
    FlightMode.OFFBOARD: (6, 0),
}
_MODES_BY_PAIR = {pair: mode for mode, pair in PX4_MODES.items()}


def px4_custom_mode(mode: FlightMode) -> int:
    main, sub = PX4_MODES.get(mode, (0, 0))
    return (main << 16) | (sub << 24)


def px4_flight_mode(custom_mode: int) -> FlightMode:
    """FlightMode of a PX4 HEARTBEAT ``custom_mode`` (UNKNOWN for modes we do not model)."""
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    return _MODES_BY_PAIR.get((main, sub), FlightMode.UNKNOWN)


def px4_mode_from_pair(main: int, sub: int) -> FlightMode | None:
    """The mode DO_SET_MODE asks for with (param2, param3), or None if not a PX4 mode we fly."""
    return _MODES_BY_PAIR.get((main, sub))


#: MAVLink MAV_LANDED_STATE
LANDED_STATES: dict[LandedState, int] = {
    LandedState.UNKNOWN: 0,
    LandedState.ON_GROUND: 1,
    LandedState.IN_AIR: 2,
    LandedState.TAKING_OFF: 3,
    LandedState.LANDING: 4,
}
_LANDED_BY_VALUE = {v: k for k, v in LANDED_STATES.items()}


def landed_state(value: int) -> LandedState:
    return _LANDED_BY_VALUE.get(value, LandedState.UNKNOWN)


# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR)
SENSOR_GYRO = 0x01
SENSOR_ACCEL = 0x02
SENSOR_MAG = 0x04
SENSOR_ABS_PRESSURE = 0x08
SENSOR_GPS = 0x20
SENSOR_MOTOR_OUTPUTS = 0x8000
SENSOR_GEOFENCE = 0x100000
SENSOR_BATTERY = 0x2000000
SENSOR_PREARM_CHECK = 0x10000000

# POSITION_TARGET_TYPEMASK bits (set = ignore)
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 0x1, 0x2, 0x4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 0x8, 0x10, 0x20
IGNORE_AX, IGNORE_AY, IGNORE_AZ = 0x40, 0x80, 0x100
IGNORE_ACCEL = IGNORE_AX | IGNORE_AY | IGNORE_AZ
FORCE_SET = 0x200
IGNORE_YAW = 0x400
IGNORE_YAW_RATE = 0x800
_IGNORE_POS = (IGNORE_PX, IGNORE_PY, IGNORE_PZ)
_IGNORE_VEL = (IGNORE_VX, IGNORE_VY, IGNORE_VZ)
_IGNORE_ACC = (IGNORE_AX, IGNORE_AY, IGNORE_AZ)


class SetpointNotSupported(ValueError):
    """A SET_POSITION_TARGET_LOCAL_NED our vehicle cannot fly (acceleration-only, bad frame)."""


def setpoint_to_mavlink(sp: Setpoint) -> tuple[int, int, list[float], list[float], float, float,
                                               list[float]]:
    """(frame, type_mask, position, velocity, yaw, yaw_rate, acceleration) for
    SET_POSITION_TARGET_LOCAL_NED (acceleration as feed-forward: FORCE_SET is never set)."""
    mask = 0
    for i in range(3):
        if not math.isfinite(sp.position_ned_m[i]):
            mask |= _IGNORE_POS[i]
        if not math.isfinite(sp.velocity_m_s[i]):
            mask |= _IGNORE_VEL[i]
        if not math.isfinite(sp.acceleration_m_s2[i]):
            mask |= _IGNORE_ACC[i]
    if not math.isfinite(sp.yaw_rad):
        mask |= IGNORE_YAW
    if not math.isfinite(sp.yaw_rate_rad_s):
        mask |= IGNORE_YAW_RATE
    frame = MAV_FRAME_BODY_NED if sp.frame is SetpointFrame.BODY_FRD else MAV_FRAME_LOCAL_NED
    pos = [0.0 if not math.isfinite(v) else float(v) for v in sp.position_ned_m]
    vel = [0.0 if not math.isfinite(v) else float(v) for v in sp.velocity_m_s]
    acc = [0.0 if not math.isfinite(v) else float(v) for v in sp.acceleration_m_s2]
    yaw = float(sp.yaw_rad) if math.isfinite(sp.yaw_rad) else 0.0
    rate = float(sp.yaw_rate_rad_s) if math.isfinite(sp.yaw_rate_rad_s) else 0.0
    return frame, mask, pos, vel, yaw, rate, acc


def setpoint_from_mavlink(frame: int, type_mask: int, position, velocity, yaw: float,
                          yaw_rate: float, acceleration=(0.0, 0.0, 0.0),
                          time_s: float = NAN) -> Setpoint:
    """The :class:`Setpoint` a SET_POSITION_TARGET_LOCAL_NED asks for (as PX4 reads it)."""
    if frame not in (MAV_FRAME_LOCAL_NED, MAV_FRAME_BODY_NED):
        raise SetpointNotSupported(f"coordinate frame {frame} (supported: LOCAL_NED 1, "
                                   "BODY_NED 8)")
    pos = np.array([NAN if type_mask & _IGNORE_POS[i] else position[i] for i in range(3)])
    vel = np.array([NAN if type_mask & _IGNORE_VEL[i] else velocity[i] for i in range(3)])
    # acceleration is a feed-forward here; as a force setpoint (FORCE_SET) it is not flown
    acc = np.array([NAN if type_mask & (_IGNORE_ACC[i] | FORCE_SET) else acceleration[i]
                    for i in range(3)])
    yaw_sp = NAN if type_mask & IGNORE_YAW else float(yaw)
    rate_sp = NAN if type_mask & IGNORE_YAW_RATE else float(yaw_rate)
    try:
        if frame == MAV_FRAME_BODY_NED:
            if np.isfinite(pos).any():
                raise SetpointNotSupported("BODY_NED position setpoints are not supported")
            return Setpoint(velocity_m_s=vel, yaw_rate_rad_s=0.0 if math.isnan(rate_sp)
                            else rate_sp, frame=SetpointFrame.BODY_FRD, time_s=time_s)
        return Setpoint(position_ned_m=pos, velocity_m_s=vel, yaw_rad=yaw_sp,
                        yaw_rate_rad_s=rate_sp, time_s=time_s,
                        acceleration_m_s2=np.where(np.isfinite(pos) | np.isfinite(vel), acc,
                                                   NAN))
    except ValueError as exc:
        if isinstance(exc, SetpointNotSupported):
            raise
        raise SetpointNotSupported(str(exc)) from None
