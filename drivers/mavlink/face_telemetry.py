"""The telemetry of the simulator's MAVLink face: each message PX4 streams, from a sample.

:class:`TelemetryEncoder` turns the vehicle's newest :class:`~drivers.base.VehicleState` (and
its home, mission and geofence state) into the MAVLink message a stream is due to send, as
PX4 fills them: global position from the local one about the estimator's origin, altitudes
above home, SYS_STATUS health bits (with the PREARM_CHECK and geofence bits), MISSION_CURRENT
with its state. A value MAVLink cannot carry skips that one message, never the stream.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink

from drivers.base import FlightMode, VehicleState
from drivers.geo import GlobalOrigin
from drivers.geometry import euler_from_quat
from drivers.mavlink import px4

#: Default stream rates (Hz): PX4's onboard link, limited by a 50 Hz telemetry source.
DEFAULT_RATES_HZ: dict[int, float] = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mavlink.MAVLINK_MSG_ID_ALTITUDE: 10.0,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
}

#: MAVLink MISSION_CURRENT.mission_mode
_MISSION_MODE_ACTIVE, _MISSION_MODE_SUSPENDED = 1, 2
_AUTO_FLAGS = (mavlink.MAV_MODE_FLAG_AUTO_ENABLED | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
               | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED)
_AUTO_MODES = {FlightMode.HOLD, FlightMode.TAKEOFF, FlightMode.LAND, FlightMode.MISSION,
               FlightMode.RETURN, FlightMode.OFFBOARD, FlightMode.PRECLAND}


def base_mode(state: VehicleState | None) -> int:
    """HEARTBEAT.base_mode as PX4 sets it: custom mode always, the auto flags in the auto
    modes and OFFBOARD (MAVProxy and QGroundControl read them), armed."""
    flags = px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if state is None:
        return flags
    if state.mode in _AUTO_MODES:
        flags |= _AUTO_FLAGS
    if state.armed:
        flags |= px4.MAV_MODE_FLAG_SAFETY_ARMED
    return flags


class TelemetryEncoder:
    """``vehicle`` is the simulator driver (home, mission status, geofence); ``boot_ms`` maps
    a sample time onto ``time_boot_ms``."""

    def __init__(self, vehicle, origin: GlobalOrigin, boot_ms: Callable[[float], int],
                 instance: int = 0) -> None:
        self.vehicle = vehicle
        self.origin = origin
        self._boot_ms = boot_ms
        self.instance = instance

    def encode(self, msg_id: int, mav, s: VehicleState | None):
        """Message ``msg_id`` from sample ``s`` (None if it cannot be made now)."""
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return self.autopilot_version(mav)
        if msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            return self.home_position(mav)
        if msg_id == mavlink.MAVLINK_MSG_ID_MISSION_CURRENT:
            return self.mission_current(mav)
        if s is None:
            return None
        t_ms = self._boot_ms(s.time_s)
        n, e, d = (float(v) for v in s.position_ned_m)
        vn, ve, vd = (float(v) for v in s.velocity_ned_m_s)
        p, q, r = (float(v) for v in s.angular_velocity_frd_rad_s)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return mav.attitude_quaternion_encode(t_ms, *(float(v) for v in s.attitude_q),
                                                  p, q, r)
        if msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            roll, pitch, yaw = euler_from_quat(s.attitude_q)
            return mav.attitude_encode(t_ms, roll, pitch, yaw, p, q, r)
        if msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return mav.local_position_ned_encode(t_ms, n, e, d, vn, ve, vd)
        if msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            lat, lon, alt = self.origin.to_global(n, e, d)
            return mav.global_position_int_encode(
                t_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                round(self._height_above_home(d) * 1000), round(vn * 100), round(ve * 100),
                round(vd * 100), _heading_cdeg(s))
        if msg_id == mavlink.MAVLINK_MSG_ID_GPS_RAW_INT:
            lat, lon, alt = self.origin.to_global(n, e, d)
            cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
            # a healthy 3D fix: what the EKF's position error model stands for
            fix = 3 if s.health.local_position_ok else 0
            return mav.gps_raw_int_encode(t_ms * 1000, fix, round(lat * 1e7), round(lon * 1e7),
                                          round(alt * 1000), 80, 120,
                                          round(math.hypot(vn, ve) * 100), cog, 16 if fix else 0)
        if msg_id == mavlink.MAVLINK_MSG_ID_VFR_HUD:
            _, _, alt = self.origin.to_global(n, e, d)
            return mav.vfr_hud_encode(0.0, math.hypot(vn, ve), _heading_cdeg(s) // 100,
                                      0, alt, -vd)
        if msg_id == mavlink.MAVLINK_MSG_ID_ALTITUDE:
            _, _, alt = self.origin.to_global(n, e, d)
            dist = s.distance_to_ground_m
            return mav.altitude_encode(t_ms * 1000, -d, alt, -d, self._height_above_home(d),
                                       math.nan, dist if math.isfinite(dist) else math.nan)
        if msg_id == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return mav.extended_sys_state_encode(0, px4.LANDED_STATES[s.landed_state])
        if msg_id == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            return self.sys_status(mav, s)
        if msg_id == mavlink.MAVLINK_MSG_ID_BATTERY_STATUS:
            b = s.battery
            cells = [int(b.voltage_v * 1000)] + [65535] * 9
            return mav.battery_status_encode(0, 1, 1, 32767, cells, int(b.current_a * 100), -1,
                                             -1, round(b.remaining_fraction * 100))
        if msg_id == mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR:
            dist = s.distance_to_ground_m
            cm = 65535 if not math.isfinite(dist) else round(dist * 100)
            # MAV_DISTANCE_SENSOR_LASER 0, orientation MAV_SENSOR_ROTATION_PITCH_270 (down) 25
            return mav.distance_sensor_encode(t_ms, 10, 4000, cm, 0, 0, 25, 0)
        return None

    def _height_above_home(self, down_m: float) -> float:
        home = self.vehicle.home()
        home_down = float(home[3][2]) if home is not None else 0.0
        return home_down - down_m

    def home_position(self, mav):
        home = self.vehicle.home()
        if home is None:
            return None
        lat, lon, alt, ned = home
        return mav.home_position_encode(round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                                        float(ned[0]), float(ned[1]), float(ned[2]),
                                        [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)

    def mission_current(self, mav):
        status = self.vehicle.mission_status
        total = status.total if status.total else 0xFFFF
        mode = _MISSION_MODE_ACTIVE if status.in_mission_mode else _MISSION_MODE_SUSPENDED
        return mav.mission_current_encode(status.current, total, int(status.state), mode)

    def sys_status(self, mav, s: VehicleState):
        h = s.health
        present = (px4.SENSOR_GYRO | px4.SENSOR_ACCEL | px4.SENSOR_MAG | px4.SENSOR_ABS_PRESSURE
                   | px4.SENSOR_GPS | px4.SENSOR_MOTOR_OUTPUTS | px4.SENSOR_BATTERY
                   | px4.SENSOR_GEOFENCE | px4.SENSOR_PREARM_CHECK)
        healthy = 0 if self.vehicle.geofence_breach is not None else px4.SENSOR_GEOFENCE
        for ok, bit in ((h.gyro_ok, px4.SENSOR_GYRO), (h.accel_ok, px4.SENSOR_ACCEL),
                        (h.mag_ok, px4.SENSOR_MAG), (True, px4.SENSOR_ABS_PRESSURE),
                        (h.local_position_ok, px4.SENSOR_GPS), (True, px4.SENSOR_MOTOR_OUTPUTS),
                        (h.battery_ok, px4.SENSOR_BATTERY), (h.armable, px4.SENSOR_PREARM_CHECK)):
            if ok:
                healthy |= bit
        b = s.battery
        return mav.sys_status_encode(present, present, healthy, 0, int(b.voltage_v * 1000),
                                     int(b.current_a * 100), round(b.remaining_fraction * 100),
                                     0, 0, 0, 0, 0, 0)

    def autopilot_version(self, mav):
        caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # 1.15.0, FIRMWARE_VERSION_TYPE_OFFICIAL
        return mav.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                            0, 0, 0x5349_4D00 + self.instance)


def _heading_cdeg(s: VehicleState) -> int:
    return round(math.degrees(s.yaw_rad) % 360.0 * 100.0) % 36000
