"""Position and velocity control, after PX4's ``mc_pos_control`` (PositionControl.cpp).

P on position → velocity setpoint (feed-forward added, horizontal speed limited with priority to
the position term) → PID on velocity → acceleration → a thrust vector, tilt-limited and
thrust-limited with vertical priority, with PX4's tracking anti-windup → an attitude setpoint
(thrust direction + yaw) and a collective thrust.

World frame NED. Thrust is normalised: 1 is all rotors at full thrust; ``hover_thrust`` is the
fraction that balances gravity. Vectors are plain float sequences (this runs in the simulator's
control loop, where numpy's overhead on 3-vectors would dominate).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from drivers.geometry import constrain_xy, cross, mat_to_q
from drivers.sim.config import PositionControlConfig

GRAVITY_M_S2 = 9.80665
NAN = float("nan")
Vec3 = Sequence[float]


@dataclass(slots=True)
class ControlSetpoint:
    """What a flight mode asks of the position controller (NaN: not controlled)."""

    position_ned_m: Vec3
    velocity_ned_m_s: Vec3
    yaw_rad: float
    yaw_rate_rad_s: float = NAN
    acceleration_ned_m_s2: Vec3 = (NAN, NAN, NAN)  # feed-forward
    xy_vel_max_m_s: float = NAN
    z_vel_max_up_m_s: float = NAN
    z_vel_max_down_m_s: float = NAN


@dataclass(frozen=True, slots=True)
class AttitudeSetpoint:
    q_ned_frd: tuple[float, float, float, float]
    thrust: float  # normalised collective thrust (0..1)
    yaw_rate_ff_rad_s: float


def limit_tilt(up: Sequence[float], max_tilt_rad: float) -> tuple[float, float, float]:
    """Limit the angle between an upward unit vector and world "up" (0, 0, 1)."""
    dot = min(max(up[2], -1.0), 1.0)
    angle = min(math.acos(dot), max_tilt_rad)
    rx, ry = up[0], up[1]
    norm = math.hypot(rx, ry)
    if norm < 1e-9:
        rx, ry, norm = 1.0, 0.0, 1.0
    s = math.sin(angle) / norm
    return (rx * s, ry * s, math.cos(angle))


def body_z_to_attitude(body_z: Sequence[float], yaw_rad: float) -> tuple[float, float, float,
                                                                          float]:
    """Attitude whose body z axis (FRD "down") points along ``body_z`` with heading ``yaw_rad``
    (PX4's ControlMath::bodyzToAttitude)."""
    n = math.sqrt(body_z[0] ** 2 + body_z[1] ** 2 + body_z[2] ** 2)
    bz = (0.0, 0.0, 1.0) if n < 1e-9 else (body_z[0] / n, body_z[1] / n, body_z[2] / n)
    y_c = (-math.sin(yaw_rad), math.cos(yaw_rad), 0.0)
    bx = cross(y_c, bz)
    if bz[2] < 0.0:
        bx = (-bx[0], -bx[1], -bx[2])
    if abs(bz[2]) < 1e-6:
        bx = (0.0, 0.0, 1.0)
    nx = math.sqrt(bx[0] ** 2 + bx[1] ** 2 + bx[2] ** 2)
    bx = (bx[0] / nx, bx[1] / nx, bx[2] / nx)
    by = cross(bz, bx)
    return mat_to_q(((bx[0], by[0], bz[0]), (bx[1], by[1], bz[1]), (bx[2], by[2], bz[2])))


LEVEL_DOWN = (0.0, 0.0, 1.0)


class PositionController:
    def __init__(self, cfg: PositionControlConfig, hover_thrust: float,
                 velocity_derivative_cutoff_hz: float = 5.0) -> None:
        self.cfg = cfg
        self.hover_thrust = hover_thrust
        self._pos_p = (cfg.xy_p, cfg.xy_p, cfg.z_p)
        self._vel_p = (cfg.xy_vel_p, cfg.xy_vel_p, cfg.z_vel_p)
        self._vel_i = (cfg.xy_vel_i, cfg.xy_vel_i, cfg.z_vel_i)
        self._vel_d = (cfg.xy_vel_d, cfg.xy_vel_d, cfg.z_vel_d)
        #: limits the flight stack may change in flight (PX4 parameters)
        self.tilt_max_rad = math.radians(cfg.tilt_max_deg)
        self.xy_vel_max_m_s = cfg.xy_vel_max_m_s
        self.z_vel_max_up_m_s = cfg.z_vel_max_up_m_s
        self.z_vel_max_down_m_s = cfg.z_vel_max_down_m_s
        self._dcutoff = velocity_derivative_cutoff_hz
        self._vel_int = [0.0, 0.0, 0.0]
        self._vel_dot = [0.0, 0.0, 0.0]
        self._prev_vel: Sequence[float] | None = None
        #: Outputs of the last update, for logging and the land detector.
        self.velocity_setpoint = [0.0, 0.0, 0.0]
        self.thrust_setpoint = [0.0, 0.0, -hover_thrust]

    def reset(self) -> None:
        """Clear integrators and filters (on the ground, when a mode restarts the controller)."""
        self.reset_integral()
        self._vel_dot = [0.0, 0.0, 0.0]
        self._prev_vel = None

    def reset_integral(self) -> None:
        self._vel_int = [0.0, 0.0, 0.0]

    def reset_xy_integral(self) -> None:
        self._vel_int[0] = self._vel_int[1] = 0.0

    def update(self, dt: float, position: Vec3, velocity: Vec3,
               sp: ControlSetpoint) -> AttitudeSetpoint:
        cfg = self.cfg
        self._update_velocity_derivative(dt, velocity)

        # -- position P → velocity setpoint ---------------------------------------------------
        vel_sp = [0.0, 0.0, 0.0]
        vel_sp_pos = [0.0, 0.0, 0.0]
        for i in range(3):
            err = sp.position_ned_m[i] - position[i]
            ff = sp.velocity_ned_m_s[i]
            ff = ff if ff == ff else 0.0  # NaN feed-forward counts as zero
            if err == err:
                vel_sp_pos[i] = err * self._pos_p[i]
                vel_sp[i] = vel_sp_pos[i] + ff
            else:
                vel_sp[i] = ff  # neither: brake to zero velocity
        xy_max = min(_or(sp.xy_vel_max_m_s, self.xy_vel_max_m_s), self.xy_vel_max_m_s)
        up_max = _or(sp.z_vel_max_up_m_s, self.z_vel_max_up_m_s)
        down_max = _or(sp.z_vel_max_down_m_s, self.z_vel_max_down_m_s)
        vel_sp[0], vel_sp[1] = constrain_xy(
            vel_sp_pos, (vel_sp[0] - vel_sp_pos[0], vel_sp[1] - vel_sp_pos[1]), xy_max)
        vel_sp[2] = min(max(vel_sp[2], -up_max), down_max)
        self.velocity_setpoint = vel_sp

        # -- velocity PID → acceleration → thrust ----------------------------------------------
        vel_err = [vel_sp[i] - velocity[i] for i in range(3)]
        acc_ff = sp.acceleration_ned_m_s2
        acc_sp = [vel_err[i] * self._vel_p[i] + self._vel_int[i] - self._vel_dot[i] *
                  self._vel_d[i] + (acc_ff[i] if acc_ff[i] == acc_ff[i] else 0.0)
                  for i in range(3)]
        thr = self._acceleration_to_thrust(acc_sp)

        # vertical anti-windup
        if (thr[2] >= -cfg.thrust_min and vel_err[2] >= 0.0) or (
            thr[2] <= -cfg.thrust_max and vel_err[2] <= 0.0
        ):
            vel_err[2] = 0.0

        # vertical priority: saturate vertical, then horizontal with what is left
        thr[2] = max(thr[2], -cfg.thrust_max)
        xy_norm = math.hypot(thr[0], thr[1])
        xy_left_sq = cfg.thrust_max * cfg.thrust_max - thr[2] * thr[2]
        xy_left = math.sqrt(xy_left_sq) if xy_left_sq > 0.0 else 0.0
        if xy_norm > xy_left:
            thr[0] *= xy_left / xy_norm
            thr[1] *= xy_left / xy_norm

        # horizontal tracking anti-windup (Rundqwist): bleed the integrator while saturated
        k = GRAVITY_M_S2 / self.hover_thrust
        ax_prod, ay_prod = thr[0] * k, thr[1] * k
        if acc_sp[0] ** 2 + acc_sp[1] ** 2 > ax_prod ** 2 + ay_prod ** 2:
            arw_gain = 2.0 / self._vel_p[0]
            vel_err[0] -= arw_gain * (acc_sp[0] - ax_prod)
            vel_err[1] -= arw_gain * (acc_sp[1] - ay_prod)

        for i in range(3):
            self._vel_int[i] += vel_err[i] * self._vel_i[i] * dt
        self._vel_int[2] = math.copysign(min(abs(self._vel_int[2]), GRAVITY_M_S2),
                                         self._vel_int[2])
        self.thrust_setpoint = thr

        q_sp = body_z_to_attitude((-thr[0], -thr[1], -thr[2]), sp.yaw_rad)
        yaw_rate_ff = sp.yaw_rate_rad_s if math.isfinite(sp.yaw_rate_rad_s) else 0.0
        return AttitudeSetpoint(q_sp, math.sqrt(thr[0] ** 2 + thr[1] ** 2 + thr[2] ** 2),
                                yaw_rate_ff)

    def _acceleration_to_thrust(self, acc_sp: Sequence[float]) -> list[float]:
        # PX4 with MPC_ACC_DECOUPLE: attitude from horizontal acceleration and gravity only.
        n = math.sqrt(acc_sp[0] ** 2 + acc_sp[1] ** 2 + GRAVITY_M_S2 ** 2)
        up = limit_tilt((-acc_sp[0] / n, -acc_sp[1] / n, GRAVITY_M_S2 / n), self.tilt_max_rad)
        thrust_ned_z = acc_sp[2] * (self.hover_thrust / GRAVITY_M_S2) - self.hover_thrust
        collective = min(thrust_ned_z / up[2], -self.cfg.thrust_min)
        return [up[0] * collective, up[1] * collective, up[2] * collective]

    def _update_velocity_derivative(self, dt: float, velocity: Vec3) -> None:
        prev = self._prev_vel
        if prev is not None and dt > 0.0:
            alpha = dt / (dt + 1.0 / (2.0 * math.pi * self._dcutoff))
            for i in range(3):
                self._vel_dot[i] += alpha * ((velocity[i] - prev[i]) / dt - self._vel_dot[i])
        self._prev_vel = tuple(velocity)


def _or(value: float, default: float) -> float:
    return value if math.isfinite(value) else default
