"""The simulated vehicle's parameters: PX4's names, types, defaults and ranges.

Clients read and set these over MAVLink (PARAM_REQUEST_LIST / _READ, PARAM_SET): MAVSDK's
``action`` reads MIS_TAKEOFF_ALT, RTL_RETURN_ALT and MPC_XY_CRUISE as floats (it refuses an
INT32 answer), its ``telemetry`` reads the calibration ids, QGroundControl expects the battery
thresholds and TRIG_MODE. Values are kept for the life of the process.

Where the simulator models what a parameter controls, the flight stack reads its value live
(speeds, takeoff and RTL altitudes, acceptance radii, failsafe actions, the geofence, battery
thresholds, auto-disarm); the rest are there so that clients find them, with PX4's defaults.
``sim.params`` in the configuration overrides any default; some defaults come from the
simulator's own configuration keys that mirror them (:data:`CONFIG_MIRRORS`).

Setting a value outside a parameter's range, of the wrong type, or an unknown name is refused
(:class:`ParamError`); the MAVLink face then echoes the unchanged value and says why in a
STATUSTEXT. (PX4 itself stores any value of the right type; refusing is safer for a simulator
that others test against.)
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

INF = math.inf
INT32_MAX = 2**31 - 1


class ParamType(enum.Enum):
    INT8 = "INT8"  # (ArduPilot's AP_Int8; PX4 has INT32 and FLOAT only)
    INT16 = "INT16"
    INT32 = "INT32"
    FLOAT = "FLOAT"

    @property
    def integer(self) -> bool:
        return self is not ParamType.FLOAT


@dataclass(frozen=True, slots=True)
class ParamSpec:
    name: str
    type: ParamType
    default: float
    min: float = -INF
    max: float = INF
    unit: str = ""
    description: str = ""
    #: the values an enum parameter may take (None: any integer in range)
    values: tuple[int, ...] | None = None

    def check(self, value: float) -> float:
        """``value`` as this parameter stores it; :class:`ParamError` if it cannot be."""
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ParamError(self.name, f"{value!r} is not a number") from None
        if not math.isfinite(value):
            raise ParamError(self.name, f"{value} is not a number")
        if self.type.integer:
            if value != int(value):
                raise ParamError(self.name, f"{value:g} is not an integer")
            value = int(value)
            if self.values is not None and value not in self.values:
                raise ParamError(self.name, f"{value} is not one of "
                                 f"{', '.join(str(v) for v in self.values)}")
        if not self.min <= value <= self.max:
            raise ParamError(self.name, f"{value:g} is out of range [{self.min:g}, "
                             f"{self.max:g}]")
        return float(value) if self.type is ParamType.FLOAT else value


class ParamError(ValueError):
    def __init__(self, name: str, reason: str) -> None:
        super().__init__(f"{name}: {reason}")
        self.name = name
        self.reason = reason


F, I = ParamType.FLOAT, ParamType.INT32  # noqa: E741 (a table reads better short)

#: PX4 parameters the simulated vehicle has, with PX4's metadata (v1.14–1.15 module.yaml).
PX4_PARAMS: tuple[ParamSpec, ...] = (
    # --- mission and navigator
    ParamSpec("MIS_TAKEOFF_ALT", F, 2.5, 0.0, 80.0, "m", "takeoff altitude above home"),
    ParamSpec("MIS_DIST_1WP", F, 10000.0, -1.0, 100000.0, "m",
              "max distance from home to the first waypoint (≤0: off)"),
    ParamSpec("MIS_TKO_LAND_REQ", I, 0, 0, 5, "", "mission takeoff/landing requirement"),
    ParamSpec("MIS_YAW_TMT", F, -1.0, -1.0, 20.0, "s", "time to reach the waypoint yaw"),
    ParamSpec("MIS_YAW_ERR", F, 12.0, 0.0, 90.0, "deg", "max waypoint yaw error"),
    ParamSpec("NAV_ACC_RAD", F, 10.0, 0.05, 200.0, "m", "waypoint acceptance radius"),
    ParamSpec("NAV_MC_ALT_RAD", F, 0.8, 0.05, 200.0, "m", "waypoint altitude acceptance"),
    ParamSpec("NAV_LOITER_RAD", F, 80.0, -10000.0, 10000.0, "m", "loiter radius (FW)"),
    ParamSpec("NAV_DLL_ACT", I, 0, 0, 6, "", "data-link loss action",
              values=(0, 1, 2, 3, 5, 6)),
    ParamSpec("NAV_RCL_ACT", I, 2, 1, 6, "", "RC loss action", values=(1, 2, 3, 5, 6)),
    ParamSpec("RTL_RETURN_ALT", F, 60.0, 0.0, 150.0, "m", "RTL return altitude above home"),
    ParamSpec("RTL_DESCEND_ALT", F, 30.0, 0.0, 100.0, "m", "RTL loiter altitude above home"),
    ParamSpec("RTL_LAND_DELAY", F, 0.0, -1.0, 300.0, "s", "RTL hover before landing (-1: stay)"),
    ParamSpec("RTL_MIN_DIST", F, 10.0, 0.5, 100.0, "m", "RTL special rules within this radius"),
    ParamSpec("RTL_CONE_ANG", I, 45, 0, 90, "deg", "RTL cone half angle",
              values=(0, 25, 45, 65, 80, 90)),
    ParamSpec("RTL_TYPE", I, 0, 0, 3, "", "RTL destination type"),
    ParamSpec("GF_ACTION", I, 2, 0, 5, "", "geofence breach action"),
    ParamSpec("GF_MAX_HOR_DIST", F, 0.0, 0.0, 10000.0, "m", "max distance from home (0: off)"),
    ParamSpec("GF_MAX_VER_DIST", F, 0.0, 0.0, 10000.0, "m", "max height above home (0: off)"),
    ParamSpec("GF_PREDICT", I, 0, 0, 1, "", "predict geofence breaches"),
    ParamSpec("TRIG_MODE", I, 0, 0, 4, "", "camera trigger mode"),
    ParamSpec("TRIG_DISTANCE", F, 25.0, 0.0, INF, "m", "camera trigger distance"),
    # --- multicopter position control
    ParamSpec("MPC_XY_CRUISE", F, 5.0, 3.0, 20.0, "m/s", "auto-mode horizontal speed"),
    ParamSpec("MPC_XY_VEL_MAX", F, 12.0, 0.0, 20.0, "m/s", "max horizontal speed"),
    ParamSpec("MPC_Z_VEL_MAX_UP", F, 3.0, 0.5, 8.0, "m/s", "max climb rate"),
    ParamSpec("MPC_Z_VEL_MAX_DN", F, 1.5, 0.5, 4.0, "m/s", "max descent rate"),
    ParamSpec("MPC_Z_V_AUTO_UP", F, 3.0, 0.5, 8.0, "m/s", "auto-mode climb rate"),
    ParamSpec("MPC_Z_V_AUTO_DN", F, 1.5, 0.5, 4.0, "m/s", "auto-mode descent rate"),
    ParamSpec("MPC_LAND_SPEED", F, 0.7, 0.6, 4.0, "m/s", "landing descent rate"),
    ParamSpec("MPC_LAND_ALT1", F, 10.0, 0.0, 122.0, "m", "landing slow-down starts"),
    ParamSpec("MPC_LAND_ALT2", F, 5.0, 0.0, 122.0, "m", "landing speed from here down"),
    ParamSpec("MPC_TKO_SPEED", F, 1.5, 1.0, 5.0, "m/s", "takeoff climb rate"),
    ParamSpec("MPC_TKO_RAMP_T", F, 3.0, 0.0, 5.0, "s", "takeoff ramp time"),
    ParamSpec("MPC_ACC_HOR", F, 3.0, 2.0, 15.0, "m/s²", "auto-mode horizontal acceleration"),
    ParamSpec("MPC_ACC_UP_MAX", F, 4.0, 2.0, 15.0, "m/s²", "max upward acceleration"),
    ParamSpec("MPC_ACC_DOWN_MAX", F, 3.0, 2.0, 15.0, "m/s²", "max downward acceleration"),
    ParamSpec("MPC_TILTMAX_AIR", F, 45.0, 20.0, 89.0, "deg", "max tilt"),
    ParamSpec("MPC_YAW_MODE", I, 0, 0, 4, "", "auto-mode heading (0: towards waypoint)"),
    ParamSpec("MPC_YAWRAUTO_MAX", F, 45.0, 5.0, 360.0, "deg/s", "auto-mode max yaw rate"),
    ParamSpec("MPC_JERK_AUTO", F, 4.0, 1.0, 80.0, "m/s³", "auto-mode jerk limit"),
    # --- precision landing (navigator/precland_params.c)
    ParamSpec("PLD_BTOUT", F, 5.0, 0.0, 50.0, "s", "landing target timeout"),
    ParamSpec("PLD_HACC_RAD", F, 0.2, 0.0, INF, "m", "horizontal acceptance radius"),
    ParamSpec("PLD_FAPPR_ALT", F, 0.1, 0.0, INF, "m", "final approach altitude"),
    ParamSpec("PLD_SRCH_ALT", F, 10.0, 0.0, INF, "m", "search altitude"),
    ParamSpec("PLD_SRCH_TOUT", F, 10.0, 0.0, INF, "s", "search timeout"),
    ParamSpec("PLD_MAX_SRCH", I, 3, 0, 100, "", "maximum number of searches"),
    # --- commander
    ParamSpec("COM_OF_LOSS_T", F, 1.0, 0.0, 60.0, "s", "offboard setpoint timeout"),
    ParamSpec("COM_OBL_RC_ACT", I, 0, 0, 7, "", "offboard loss action"),
    ParamSpec("COM_FAIL_ACT_T", F, 5.0, 0.0, 25.0, "s", "failsafe action delay (HOLD first)"),
    ParamSpec("COM_DL_LOSS_T", I, 10, 5, 300, "s", "data-link loss timeout"),
    ParamSpec("COM_DLL_EXCEPT", I, 0, 0, 31, "", "modes excepted from data-link loss"),
    ParamSpec("COM_RC_IN_MODE", I, 3, 0, 4, "", "manual control input source"),
    ParamSpec("COM_RC_LOSS_T", F, 0.5, 0.0, 35.0, "s", "RC loss timeout"),
    ParamSpec("COM_RCL_EXCEPT", I, 0, 0, 31, "", "modes excepted from RC loss"),
    ParamSpec("COM_DISARM_LAND", F, 2.0, -1.0, 20.0, "s", "auto-disarm after landing (≤0: off)"),
    ParamSpec("COM_DISARM_PRFLT", F, 10.0, -1.0, 20.0, "s", "auto-disarm without takeoff"),
    ParamSpec("COM_LOW_BAT_ACT", I, 0, 0, 3, "", "battery failsafe action"),
    ParamSpec("COM_ARM_WO_GPS", I, 1, 0, 2, "", "arming without GPS"),
    # --- battery
    ParamSpec("BAT_LOW_THR", F, 0.15, 0.12, 0.5, "", "low battery level"),
    ParamSpec("BAT_CRIT_THR", F, 0.07, 0.05, 0.25, "", "critical battery level"),
    ParamSpec("BAT_EMERGEN_THR", F, 0.05, 0.03, 0.1, "", "emergency battery level"),
    ParamSpec("BAT_N_CELLS", I, 4, 1, 16, "", "battery cells"),
    ParamSpec("BAT_V_CHARGED", F, 4.05, 0.0, INF, "V", "cell voltage when full"),
    ParamSpec("BAT_V_EMPTY", F, 3.6, 0.0, INF, "V", "cell voltage when empty"),
    ParamSpec("BAT_V_LOAD_DROP", F, 0.3, 0.07, 0.5, "V", "cell voltage drop under load"),
    # --- system, sensors (read by clients at connect)
    ParamSpec("MAV_SYS_ID", I, 1, 1, 250, "", "MAVLink system id (reboot)"),
    ParamSpec("MAV_COMP_ID", I, 1, 1, 250, "", "MAVLink component id (reboot)"),
    ParamSpec("MAV_TYPE", I, 2, 0, 40, "", "vehicle type (2: quadrotor)"),
    ParamSpec("SYS_AUTOSTART", I, 10016, 0, 9999999, "", "airframe (10016: SITL quadrotor)"),
    ParamSpec("SYS_HITL", I, 0, -1, 2, "", "hardware in the loop"),
    ParamSpec("CBRK_SUPPLY_CHK", I, 0, 0, 894281, "", "power check circuit breaker"),
    ParamSpec("CAL_ACC0_ID", I, 1310988, 0, INT32_MAX, "", "accelerometer 0 calibration id"),
    ParamSpec("CAL_GYRO0_ID", I, 1310988, 0, INT32_MAX, "", "gyroscope 0 calibration id"),
    ParamSpec("CAL_MAG0_ID", I, 197388, 0, INT32_MAX, "", "magnetometer 0 calibration id"),
    ParamSpec("CAL_MAG0_ROT", I, -1, -1, 40, "", "magnetometer 0 rotation"),
    ParamSpec("CAL_MAG1_ID", I, 0, 0, INT32_MAX, "", "magnetometer 1 calibration id"),
    ParamSpec("CAL_MAG1_ROT", I, -1, -1, 40, "", "magnetometer 1 rotation"),
    ParamSpec("CAL_MAG2_ID", I, 0, 0, INT32_MAX, "", "magnetometer 2 calibration id"),
    ParamSpec("CAL_MAG2_ROT", I, -1, -1, 40, "", "magnetometer 2 rotation"),
    ParamSpec("CAL_MAG3_ID", I, 0, 0, INT32_MAX, "", "magnetometer 3 calibration id"),
    ParamSpec("CAL_MAG3_ROT", I, -1, -1, 40, "", "magnetometer 3 rotation"),
    ParamSpec("SENS_BOARD_ROT", I, 0, -1, 40, "", "board rotation"),
    ParamSpec("SENS_BOARD_X_OFF", F, 0.0, -INF, INF, "deg", "board roll offset"),
    ParamSpec("SENS_BOARD_Y_OFF", F, 0.0, -INF, INF, "deg", "board pitch offset"),
    ParamSpec("SENS_BOARD_Z_OFF", F, 0.0, -INF, INF, "deg", "board yaw offset"),
    ParamSpec("SENS_DPRES_OFF", F, 0.0, -INF, INF, "Pa", "differential pressure offset"),
    ParamSpec("UAVCAN_ENABLE", I, 0, 0, 3, "", "UAVCAN mode"),
)

#: Parameters whose default comes from a key of the simulator's configuration (that key is
#: what the simulator was tuned with): name → (path under sim, scale).
CONFIG_MIRRORS: dict[str, tuple[str, float]] = {
    "MIS_TAKEOFF_ALT": ("flight_stack.commander.takeoff_altitude_m", 1.0),
    "MPC_TKO_SPEED": ("flight_stack.commander.takeoff_speed_m_s", 1.0),
    "MPC_TKO_RAMP_T": ("flight_stack.commander.takeoff_ramp_s", 1.0),
    "MPC_ACC_UP_MAX": ("flight_stack.commander.takeoff_accel_m_s2", 1.0),
    "MPC_LAND_SPEED": ("flight_stack.commander.land_speed_m_s", 1.0),
    "MPC_Z_V_AUTO_DN": ("flight_stack.commander.descent_speed_m_s", 1.0),
    "MPC_LAND_ALT2": ("flight_stack.commander.land_slow_altitude_m", 1.0),
    "COM_OF_LOSS_T": ("flight_stack.commander.offboard_loss_timeout_s", 1.0),
    "COM_DISARM_LAND": ("flight_stack.commander.disarm_after_land_s", 1.0),
    "COM_DISARM_PRFLT": ("flight_stack.commander.disarm_preflight_s", 1.0),
    "MPC_XY_CRUISE": ("flight_stack.position.xy_cruise_m_s", 1.0),
    "MPC_XY_VEL_MAX": ("flight_stack.position.xy_vel_max_m_s", 1.0),
    "MPC_Z_VEL_MAX_UP": ("flight_stack.position.z_vel_max_up_m_s", 1.0),
    "MPC_Z_VEL_MAX_DN": ("flight_stack.position.z_vel_max_down_m_s", 1.0),
    "MPC_TILTMAX_AIR": ("flight_stack.position.tilt_max_deg", 1.0),
    "MPC_ACC_HOR": ("flight_stack.position.brake_accel_m_s2", 1.0),
    "BAT_LOW_THR": ("battery.low_fraction", 1.0),
    "BAT_CRIT_THR": ("battery.critical_fraction", 1.0),
    "BAT_N_CELLS": ("battery.cells", 1.0),
}

SPECS: dict[str, ParamSpec] = {spec.name: spec for spec in PX4_PARAMS}


class Parameters:
    """The vehicle's parameter values, in a fixed order (PARAM_VALUE's index).

    Written only by the simulator's thread; other threads read single values (a float or an
    int per name), which is safe without a lock.
    """

    def __init__(self, defaults: Mapping[str, float] | None = None,
                 specs: Iterable[ParamSpec] = PX4_PARAMS) -> None:
        self._specs = {spec.name: spec for spec in sorted(specs, key=lambda s: s.name)}
        self._values: dict[str, float] = {name: spec.check(spec.default)
                                          for name, spec in self._specs.items()}
        self._listeners: list[Callable[[str, float], None]] = []
        for name, value in (defaults or {}).items():
            self.set(name, value)

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __contains__(self, name: str) -> bool:
        return name in self._specs

    def __len__(self) -> int:
        return len(self._specs)

    @property
    def names(self) -> list[str]:
        return list(self._specs)

    def spec(self, name: str) -> ParamSpec:
        try:
            return self._specs[name]
        except KeyError:
            raise ParamError(name, "unknown parameter") from None

    def index(self, name: str) -> int:
        return self.names.index(name)

    def set(self, name: str, value: float) -> float:
        """Set ``name``; returns the stored value, raises :class:`ParamError` if refused."""
        stored = self.spec(name).check(value)
        if self._values[name] != stored:
            self._values[name] = stored
            for listener in self._listeners:
                listener(name, stored)
        return stored

    def on_change(self, listener: Callable[[str, float], None]) -> None:
        self._listeners.append(listener)

    def snapshot(self) -> dict[str, float]:
        return dict(self._values)


def validate_overrides(overrides: Mapping[str, float], specs: Mapping[str, ParamSpec] = SPECS,
                       firmware: str = "PX4",
                       source: str = "drivers/sim/flight/params.py") -> list[str]:
    """Problems with a configuration's parameter overrides (empty: all fine), against the
    firmware's table ``specs``."""
    problems = []
    for name, value in overrides.items():
        spec = specs.get(name)
        if spec is None:
            problems.append(f"{name}: unknown {firmware} parameter (the simulator has "
                            f"{len(specs)}; see {source})")
            continue
        try:
            spec.check(float(value))
        except (ParamError, TypeError, ValueError) as exc:
            problems.append(str(exc))
    return problems


def config_defaults(sim_config, overrides: bool = True) -> dict[str, float]:
    """The parameter defaults a simulator configuration gives: its mirrored keys, then (unless
    ``overrides`` is false: another firmware's table holds them) its ``params`` overrides."""
    values: dict[str, float] = {}
    for name, (path, scale) in CONFIG_MIRRORS.items():
        node = sim_config
        for part in path.split("."):
            node = getattr(node, part)
        values[name] = float(node) * scale
    if overrides:
        values.update(sim_config.params)
    return values
