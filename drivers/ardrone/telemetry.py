"""The AR.Drone 2.0's limits as the driver knows them (:class:`DroneLimits`: what a PCMD's
fractions are fractions of, from the drone's configuration) and navdata to
:class:`~drivers.base.VehicleState` (:class:`NavdataTelemetry`, the position dead-reckoned,
as the drone has no GPS). Synchronous; the async shell is :mod:`drivers.ardrone.driver`.

Frames and signs (the SDK 2.0 developer guide; what ardrone_autonomy negates to get ROS's
FLU): the demo navdata's ``theta`` is positive nose up, ``phi`` positive right wing down,
``psi`` positive clockwise seen from above, so they are FRD/NED's pitch, roll and yaw as they
stand; ``vx``/``vy`` are along the drone's heading (x forward, y right), ``vz`` down. The local
NED frame's north is the drone's ``psi`` zero (its heading reference: where it booted or was
last trimmed), its origin where the driver started dead-reckoning (``connect``), on the ground.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from drivers.ardrone.at import AtCommands
from drivers.ardrone.navdata import ControlState, Navdata, State
from drivers.base import (
    Battery,
    FlightMode,
    Health,
    LandedState,
    ProgressiveCommand,
    VehicleState,
)
from drivers.geometry import (
    quat_conjugate,
    quat_from_euler,
    quat_multiply,
    wrap_pi,
)

NAN = math.nan
GRAVITY_M_S2 = 9.80665

# --------------------------------------------------------------------------------------------
# The drone's limits and PCMD
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DroneLimits:
    """What a PCMD's fractions are fractions of (``control:euler_angle_max``,
    ``control:control_vz_max``, ``control:control_yaw``) and the height the drone never
    climbs above (``control:altitude_max``); the AR.Drone 2.0's indoor defaults."""

    euler_angle_max_rad: float = 0.20943999
    control_vz_max_m_s: float = 0.7
    control_yaw_rad_s: float = 1.7453293
    altitude_max_m: float = 3.0
    #: the airframe's linear drag (1/s: deceleration per m/s of airspeed), not a setting:
    #: tum_ardrone's identified c1 for the AR.Drone 2.0 (its simulated one flies the same)
    drag_per_s: float = 0.58

    @property
    def time_constant_s(self) -> float:
        """The drag's time constant: how fast a tilt's speed builds up and dies away."""
        return 1.0 / self.drag_per_s

    def acceleration_m_s2(self, tilt_fraction: float = 1.0) -> float:
        """Horizontal acceleration from rest at this fraction of ``euler_angle_max``."""
        return GRAVITY_M_S2 * math.tan(tilt_fraction * self.euler_angle_max_rad)

    def terminal_speed_m_s(self, tilt_fraction: float = 1.0) -> float:
        """The speed a steady tilt at this fraction of ``euler_angle_max`` ends at."""
        return self.acceleration_m_s2(tilt_fraction) / self.drag_per_s

    @classmethod
    def from_config(cls, values: Mapping[str, object]) -> DroneLimits:
        """The limits in a configuration dump (TCP 5559, as
        :func:`drivers.ardrone.config.parse_config_text` reads it); a key missing or not a
        number keeps its default."""
        default = cls()

        def number(key: str, scale: float, fallback: float) -> float:
            value = values.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float):
                return fallback
            value = float(value) * scale
            return value if math.isfinite(value) and value > 0.0 else fallback

        return cls(number("control:euler_angle_max", 1.0, default.euler_angle_max_rad),
                   number("control:control_vz_max", 1e-3, default.control_vz_max_m_s),
                   number("control:control_yaw", 1.0, default.control_yaw_rad_s),
                   number("control:altitude_max", 1e-3, default.altitude_max_m))


def encode_pcmd(command: ProgressiveCommand, commands: AtCommands) -> bytes:
    """``AT*PCMD`` for ``command`` (its fractions clamped to [−1, 1]; ``hover``: the
    progressive bit clear, the drone's own velocity and height hold)."""
    return commands.pcmd(command.roll, command.pitch, command.gaz, command.yaw,
                         hover=command.hover)


#: the drone's hover (the fractions ignored)
HOVER = ProgressiveCommand()


def clamp_fraction(value: float, limit: float = 1.0) -> float:
    return max(-limit, min(limit, value))


# --------------------------------------------------------------------------------------------
# Navdata → VehicleState
# --------------------------------------------------------------------------------------------

LANDED_STATES = {ControlState.LANDED: LandedState.ON_GROUND,
           ControlState.TAKING_OFF: LandedState.TAKING_OFF,
           ControlState.FLYING: LandedState.IN_AIR, ControlState.HOVERING: LandedState.IN_AIR,
           ControlState.LANDING: LandedState.LANDING}
CONTROL_MODES = {ControlState.TAKING_OFF: FlightMode.TAKEOFF,
                 ControlState.HOVERING: FlightMode.HOLD,
          ControlState.FLYING: FlightMode.OFFBOARD, ControlState.LANDING: FlightMode.LAND,
          ControlState.LANDED: FlightMode.HOLD}
#: states in which the drone is off the ground
AIRBORNE = frozenset({ControlState.TAKING_OFF, ControlState.HOVERING, ControlState.FLYING,
                      ControlState.LANDING, ControlState.GOTO_FIX, ControlState.LOOPING})


class NavdataTelemetry:
    """Demo navdata packets, each with its receive time on our clock, to telemetry samples.

    The sample's ``time_s`` is the receive time less :attr:`latency_s` (the demo option
    carries no time of its own). The height is the demo altitude (the drone's fused sonar and
    IMU estimate: height above the floor under it), as ``-z`` and as ``distance_to_ground_m``.
    The horizontal position is dead-reckoned: the NED velocity integrated between packets
    (trapezoidal) while the motors turn — a landed drone does not move, whatever its optical
    flow says. :attr:`drift_m` estimates how far off that position may be by now:
    :data:`DRIFT_PER_METRE` of the path flown (optical flow's scale error) plus
    :data:`DRIFT_RATE_M_S` for every second in the air (its velocity bias in a hover). Both
    are estimates, not measurements of a real drone: the simulated drone's optical-flow grade
    has a 3 % scale error; published AR.Drone odometry drifts by several percent of the
    distance. Body rates, which the demo option does not carry, are the attitude's change
    between consecutive packets (zero for the first, or after a gap).

    Battery: the voltage and current are not in the demo option (NaN). Health: armable
    unless the navdata says ``EMERGENCY`` (``prearm``) or ``VBAT_LOW`` (``battery``);
    ``failsafe`` is the drone's ``COM_LOST``.
    """

    #: the dead-reckoned position's error growth (estimates; see the class docstring)
    DRIFT_PER_METRE = 0.04
    DRIFT_RATE_M_S = 0.02
    #: a gap between packets longer than this: no body rates from it
    RATE_GAP_S = 0.25

    def __init__(self, latency_s: float = 0.03) -> None:
        self.latency_s = latency_s
        self._position = np.zeros(2)
        self._last_time: float | None = None
        self._last_velocity = np.zeros(2)
        self._last_q: np.ndarray | None = None
        self._last_flying = False
        #: the dead-reckoned position's estimated error (m) and the path flown (m)
        self.drift_m = 0.0
        self.path_m = 0.0
        #: the newest sample (None before the first)
        self.latest: VehicleState | None = None
        #: the newest packet's control state and state bits
        self.control_state: ControlState | int | None = None
        self.flags = State(0)

    def reset_position(self, north_m: float = 0.0, east_m: float = 0.0) -> None:
        """Start dead-reckoning again from (``north_m``, ``east_m``), its drift zero."""
        self._position = np.array([north_m, east_m], dtype=float)
        self.drift_m = 0.0
        self.path_m = 0.0

    def update(self, navdata: Navdata, received_s: float) -> VehicleState | None:
        """The sample of a demo packet received at ``received_s`` (None without the demo
        option). Packets must come in order (:class:`~drivers.ardrone.session.NavdataSession`
        drops older ones)."""
        demo = navdata.demo
        if demo is None:
            return None
        time_s = received_s - self.latency_s
        flags = navdata.state
        roll = math.radians(demo.phi_mdeg / 1000.0)
        pitch = math.radians(demo.theta_mdeg / 1000.0)
        yaw = wrap_pi(math.radians(demo.psi_mdeg / 1000.0))
        c, s = math.cos(yaw), math.sin(yaw)
        forward, right = demo.vx_mm_s / 1000.0, demo.vy_mm_s / 1000.0
        velocity = np.array([c * forward - s * right, s * forward + c * right])
        flying = State.FLY in flags
        q = quat_from_euler(roll, pitch, yaw)
        rates = np.zeros(3)
        if self._last_time is not None:
            dt = max(0.0, time_s - self._last_time)
            if flying or self._last_flying:
                step = 0.5 * (self._last_velocity + velocity) * dt
                distance = float(np.hypot(*step))
                self._position = self._position + step
                self.path_m += distance
                self.drift_m += self.DRIFT_PER_METRE * distance + self.DRIFT_RATE_M_S * dt
            if self._last_q is not None and 1e-3 < dt <= self.RATE_GAP_S:
                rates = _body_rates(self._last_q, q, dt)
        self._last_time, self._last_velocity = time_s, velocity
        self._last_q, self._last_flying = q, flying
        height_m = max(0.0, demo.altitude_mm / 1000.0)
        major = demo.major_state
        self.control_state, self.flags = major, flags
        landed = LANDED_STATES.get(major, LandedState.IN_AIR if flying else LandedState.ON_GROUND)
        fraction = max(0.0, min(1.0, demo.battery_percent / 100.0))
        state = VehicleState(
            time_s=time_s,
            position_ned_m=(self._position[0], self._position[1], -height_m),
            velocity_ned_m_s=(velocity[0], velocity[1], demo.vz_mm_s / 1000.0),
            attitude_q=q, angular_velocity_frd_rad_s=rates,
            armed=flying, mode=CONTROL_MODES.get(major, FlightMode.UNKNOWN), landed_state=landed,
            distance_to_ground_m=height_m,
            battery=Battery(NAN, NAN, fraction),
            health=Health(battery_ok=State.VBAT_LOW not in flags,
                          prearm_ok=State.EMERGENCY not in flags),
            failsafe=State.COM_LOST in flags)
        self.latest = state
        return state


def _body_rates(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """The body rates (FRD) that turn attitude ``q0`` into ``q1`` in ``dt``."""
    dq = quat_multiply(quat_conjugate(q0), q1)
    if dq[0] < 0.0:
        dq = -dq
    vector = dq[1:]
    norm = float(np.linalg.norm(vector))
    if norm < 1e-12:
        return np.zeros(3)
    angle = 2.0 * math.atan2(norm, float(dq[0]))
    return vector / norm * angle / dt
