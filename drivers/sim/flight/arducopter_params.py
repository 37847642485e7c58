"""ArduCopter's parameters as a ground station finds them (4.5/4.6): names, AP_Param types,
defaults, ranges and units, for the simulator as ArduCopter SITL (issue 34; the notes and their
sources: docs/reference/ardupilot-mavlink.md). ArduPilot's own units are kept — centimetres and
cm/s for the navigation speeds and altitudes, centidegrees for angles, milliseconds for
RTL_LOIT_TIME — so that scripts written for ArduPilot read and set what they expect;
:func:`si_limits` turns them into the SI values the flight code flies on.

Where SITL's ``copter.parm`` differs from the firmware's default (the battery monitor on, a
smaller fence radius), the SITL value is the default here, as a ground station connected to
SITL reads it. The SRn_ stream rates are 0 on Copter: nothing but the heartbeat streams until
a client asks (MAVProxy asks for every group at 4 Hz).
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.sim.flight.params import ParamSpec, ParamType

F, I8, I16, I32 = ParamType.FLOAT, ParamType.INT8, ParamType.INT16, ParamType.INT32

#: the stream-rate groups of one serial port (SRn_*), in Hz
STREAM_GROUPS = ("RAW_SENS", "EXT_STAT", "RC_CHAN", "RAW_CTRL", "POSITION", "EXTRA1", "EXTRA2",
                 "EXTRA3", "PARAMS", "ADSB")


def _streams(port: int) -> tuple[ParamSpec, ...]:
    return tuple(ParamSpec(f"SR{port}_{group}", I16, 0, 0, 50, "Hz",
                           f"serial {port}'s {group} stream rate") for group in STREAM_GROUPS)


ARDUCOPTER_PARAMS: tuple[ParamSpec, ...] = (
    # --- waypoint navigation (AC_WPNav)
    ParamSpec("WPNAV_SPEED", F, 1000.0, 20.0, 2000.0, "cm/s", "waypoint horizontal speed"),
    ParamSpec("WPNAV_SPEED_UP", F, 250.0, 10.0, 1000.0, "cm/s", "waypoint climb speed"),
    ParamSpec("WPNAV_SPEED_DN", F, 150.0, 10.0, 500.0, "cm/s", "waypoint descent speed"),
    ParamSpec("WPNAV_ACCEL", F, 250.0, 50.0, 500.0, "cm/s²", "waypoint acceleration"),
    ParamSpec("WPNAV_ACCEL_Z", F, 100.0, 50.0, 500.0, "cm/s²", "waypoint vertical acceleration"),
    ParamSpec("WPNAV_RADIUS", F, 200.0, 5.0, 1000.0, "cm", "waypoint radius"),
    ParamSpec("LOIT_SPEED", F, 1250.0, 20.0, 3500.0, "cm/s", "loiter max speed"),
    ParamSpec("ANGLE_MAX", I16, 3000, 1000, 8000, "cdeg", "max lean angle"),
    ParamSpec("PILOT_SPEED_UP", I16, 250, 50, 500, "cm/s", "pilot max climb"),
    ParamSpec("PILOT_SPEED_DN", I16, 0, 0, 500, "cm/s", "pilot max descent (0: as up)"),
    ParamSpec("PILOT_TKOFF_ALT", F, 0.0, 0.0, 1000.0, "cm", "pilot takeoff altitude"),
    # --- return to launch (mode_rtl)
    ParamSpec("RTL_ALT", I32, 1500, 30, 300000, "cm", "RTL return altitude above home"),
    ParamSpec("RTL_ALT_FINAL", I16, 0, 0, 1000, "cm", "RTL final altitude (0: land)"),
    ParamSpec("RTL_LOIT_TIME", I32, 5000, 0, 60000, "ms", "RTL loiter over home"),
    ParamSpec("RTL_SPEED", I16, 0, 0, 2000, "cm/s", "RTL speed (0: WPNAV_SPEED)"),
    ParamSpec("RTL_CLIMB_MIN", I16, 0, 0, 3000, "cm", "RTL minimum climb"),
    ParamSpec("RTL_CONE_SLOPE", F, 3.0, 0.5, 10.0, "", "RTL cone slope"),
    ParamSpec("RTL_ALT_TYPE", I8, 0, 0, 1, "", "RTL altitude type (1: terrain)"),
    # --- landing
    ParamSpec("LAND_SPEED", I16, 50, 30, 200, "cm/s", "final descent speed"),
    ParamSpec("LAND_SPEED_HIGH", I16, 0, 0, 500, "cm/s", "descent above LAND_ALT_LOW "
              "(0: WPNAV_SPEED_DN)"),
    ParamSpec("LAND_ALT_LOW", I16, 1000, 100, 10000, "cm", "slow descent below this"),
    ParamSpec("DISARM_DELAY", I8, 10, 0, 127, "s", "auto-disarm on the ground (0: off)"),
    # --- GUIDED and AUTO
    ParamSpec("GUID_TIMEOUT", F, 3.0, 0.1, 5.0, "s", "GUIDED velocity/accel target timeout"),
    ParamSpec("GUID_OPTIONS", I32, 0, 0, 2**16 - 1, "", "GUIDED options bitmask"),
    ParamSpec("AUTO_OPTIONS", I32, 0, 0, 2**16 - 1, "", "AUTO options (bit 0: arm in AUTO, "
              "bit 1: take off without raising the throttle)"),
    ParamSpec("CIRCLE_RADIUS", F, 1000.0, 0.0, 200000.0, "cm", "CIRCLE mode radius"),
    ParamSpec("CIRCLE_RATE", F, 20.0, -90.0, 90.0, "deg/s", "CIRCLE mode turn rate "
              "(positive: clockwise)"),
    ParamSpec("WP_YAW_BEHAVIOR", I8, 2, 0, 3, "", "yaw in auto modes (2: face next waypoint "
              "except RTL)"),
    # --- arming and failsafes
    ParamSpec("ARMING_CHECK", I32, 1, 0, 2**20 - 1, "", "pre-arm checks bitmask (1: all)"),
    ParamSpec("FS_GCS_ENABLE", I8, 0, 0, 7, "", "ground station failsafe action",
              values=(0, 1, 3, 4, 5, 6, 7)),
    ParamSpec("FS_GCS_TIMEOUT", F, 5.0, 2.0, 120.0, "s", "ground station failsafe timeout"),
    ParamSpec("FS_OPTIONS", I32, 0, 0, 2**16 - 1, "", "failsafe options bitmask"),
    ParamSpec("FS_THR_ENABLE", I8, 1, 0, 7, "", "throttle (RC) failsafe action"),
    ParamSpec("FS_THR_VALUE", I16, 975, 910, 1100, "PWM", "throttle failsafe value"),
    ParamSpec("FS_EKF_ACTION", I8, 1, 0, 3, "", "EKF failsafe action (1: land)"),
    ParamSpec("FS_EKF_THRESH", F, 0.8, 0.6, 1.0, "", "EKF failsafe variance threshold"),
    # --- battery (SITL's copter.parm: a monitor on)
    ParamSpec("BATT_MONITOR", I8, 4, 0, 30, "", "battery monitor (4: analog voltage and "
              "current)"),
    ParamSpec("BATT_CAPACITY", I32, 3300, 0, 1000000, "mAh", "battery capacity (the "
              "simulator sets its pack's)"),
    ParamSpec("BATT_LOW_VOLT", F, 10.5, 0.0, 100.0, "V", "low battery voltage"),
    ParamSpec("BATT_CRT_VOLT", F, 0.0, 0.0, 100.0, "V", "critical battery voltage"),
    ParamSpec("BATT_LOW_MAH", F, 0.0, 0.0, 1000000.0, "mAh", "low battery remaining"),
    ParamSpec("BATT_CRT_MAH", F, 0.0, 0.0, 1000000.0, "mAh", "critical battery remaining"),
    ParamSpec("BATT_LOW_TIMER", I8, 10, 0, 120, "s", "low voltage for this long"),
    ParamSpec("BATT_FS_LOW_ACT", I8, 0, 0, 7, "", "low battery action"),
    ParamSpec("BATT_FS_CRT_ACT", I8, 0, 0, 7, "", "critical battery action"),
    ParamSpec("BATT_FS_VOLTSRC", I8, 0, 0, 1, "", "failsafe voltage source (0 raw, 1 "
              "sag-compensated)"),
    # --- SmartRTL (AP_SmartRTL)
    ParamSpec("SRTL_ACCURACY", F, 2.0, 0.0, 10.0, "m", "SmartRTL accuracy (minimum distance "
              "between points)"),
    ParamSpec("SRTL_POINTS", I16, 300, 0, 500, "", "SmartRTL maximum points on the path (0: "
              "off)"),
    # --- fence (AC_Fence; SITL's copter.parm: radius 150 m)
    ParamSpec("FENCE_ENABLE", I8, 0, 0, 1, "", "fence enabled"),
    ParamSpec("FENCE_TYPE", I8, 7, 0, 15, "", "fence types (1 alt max, 2 circle, 4 polygon, "
              "8 alt min)"),
    ParamSpec("FENCE_ACTION", I8, 1, 0, 5, "", "fence breach action (1: RTL or land)"),
    ParamSpec("FENCE_ALT_MAX", F, 100.0, 10.0, 1000.0, "m", "fence maximum altitude"),
    ParamSpec("FENCE_ALT_MIN", F, -10.0, -100.0, 100.0, "m", "fence minimum altitude"),
    ParamSpec("FENCE_RADIUS", F, 150.0, 30.0, 10000.0, "m", "circular fence radius"),
    ParamSpec("FENCE_MARGIN", F, 2.0, 1.0, 10.0, "m", "fence margin"),
    # --- precision landing (AC_PrecLand)
    ParamSpec("PLND_ENABLED", I8, 0, 0, 1, "", "precision landing enabled"),
    ParamSpec("PLND_TYPE", I8, 0, 0, 4, "", "precision landing sensor (1: companion "
              "over MAVLink)"),
    ParamSpec("PLND_EST_TYPE", I8, 1, 0, 1, "", "estimator (0 raw, 1 Kalman)"),
    ParamSpec("PLND_STRICT", I8, 1, 0, 2, "", "on target loss: 0 land, 1 retry, 2 hover"),
    ParamSpec("PLND_RET_MAX", I8, 4, 0, 10, "", "maximum retries"),
    ParamSpec("PLND_TIMEOUT", F, 4.0, 0.0, 20.0, "s", "target lost after this"),
    ParamSpec("PLND_RET_BEHAVE", I8, 0, 0, 1, "", "retry to (0) the last vehicle position, "
              "(1) the target"),
    ParamSpec("PLND_XY_DIST_MAX", F, 2.5, 0.0, 10.0, "m", "no descent further than this"),
    ParamSpec("PLND_ALT_MIN", F, 0.75, 0.0, 5.0, "m", "target detection minimum altitude"),
    ParamSpec("PLND_ALT_MAX", F, 8.0, 0.0, 50.0, "m", "target detection maximum altitude"),
    ParamSpec("PLND_LAG", F, 0.02, 0.0, 0.25, "s", "sensor lag"),
    # --- identity and serial ports (SITL: SERIAL0-2 MAVLink 2)
    ParamSpec("SYSID_THISMAV", I16, 1, 1, 255, "", "this vehicle's MAVLink system id"),
    ParamSpec("SYSID_MYGCS", I16, 255, 1, 255, "", "the ground station's system id"),
    ParamSpec("SERIAL0_PROTOCOL", I8, 2, -1, 50, "", "serial 0 protocol (2: MAVLink 2)"),
    ParamSpec("SERIAL1_PROTOCOL", I8, 2, -1, 50, "", "serial 1 protocol (2: MAVLink 2)"),
    ParamSpec("SERIAL2_PROTOCOL", I8, 2, -1, 50, "", "serial 2 protocol (2: MAVLink 2)"),
    ParamSpec("SERIAL0_BAUD", I32, 115, 1, 12500000, "", "serial 0 baud (kbaud code; unused on "
              "SITL's TCP)"),
    ParamSpec("SERIAL1_BAUD", I32, 57, 1, 12500000, "", "serial 1 baud"),
    ParamSpec("SERIAL2_BAUD", I32, 57, 1, 12500000, "", "serial 2 baud"),
    *_streams(0), *_streams(1), *_streams(2),
)

SPECS: dict[str, ParamSpec] = {spec.name: spec for spec in ARDUCOPTER_PARAMS}


@dataclass(frozen=True, slots=True)
class SiLimits:
    """ArduCopter's navigation parameters in SI units, for the flight code."""

    wp_speed_m_s: float
    wp_climb_m_s: float
    wp_descent_m_s: float
    rtl_altitude_m: float
    rtl_final_altitude_m: float
    rtl_loiter_s: float
    rtl_speed_m_s: float
    land_speed_m_s: float
    land_speed_high_m_s: float
    land_alt_low_m: float
    guided_timeout_s: float
    disarm_delay_s: float
    max_tilt_deg: float


def si_limits(values: dict[str, float]) -> SiLimits:
    """The values (by name; defaults for those missing) in SI units, ArduCopter's fallbacks
    applied (RTL_SPEED 0 → WPNAV_SPEED, LAND_SPEED_HIGH 0 → WPNAV_SPEED_DN, GUID_TIMEOUT at
    least 0.1 s)."""
    def v(name: str) -> float:
        return float(values.get(name, SPECS[name].default))

    wp_speed = v("WPNAV_SPEED") / 100.0
    return SiLimits(
        wp_speed_m_s=wp_speed, wp_climb_m_s=v("WPNAV_SPEED_UP") / 100.0,
        wp_descent_m_s=v("WPNAV_SPEED_DN") / 100.0,
        rtl_altitude_m=max(v("RTL_ALT"), 30.0) / 100.0,
        rtl_final_altitude_m=v("RTL_ALT_FINAL") / 100.0,
        rtl_loiter_s=v("RTL_LOIT_TIME") / 1000.0,
        rtl_speed_m_s=v("RTL_SPEED") / 100.0 or wp_speed,
        land_speed_m_s=v("LAND_SPEED") / 100.0,
        land_speed_high_m_s=v("LAND_SPEED_HIGH") / 100.0 or v("WPNAV_SPEED_DN") / 100.0,
        land_alt_low_m=v("LAND_ALT_LOW") / 100.0,
        guided_timeout_s=max(v("GUID_TIMEOUT"), 0.1),
        disarm_delay_s=v("DISARM_DELAY"),
        max_tilt_deg=v("ANGLE_MAX") / 100.0)
