"""What the simulated vehicle measures: estimator output errors, rangefinder, battery.

All noise comes from generators seeded by the simulator, one per source, so that switching one
source on or off does not change the others' sequences.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from drivers.base import Battery
from drivers.geometry import qmul, quat_from_axis_angle
from drivers.sim.config import BatteryConfig, EstimatorConfig, RangefinderConfig
from drivers.sim.flight.flight_stack import EstimatedState


class GaussMarkov:
    """First-order Gauss–Markov process, per component: stationary std ``sigma``, correlation
    time ``tau_s``. Starts from its stationary distribution."""

    def __init__(self, rng: np.random.Generator, sigma: np.ndarray,
                 tau_s: np.ndarray | float) -> None:
        self._rng = rng
        self._sigma = np.asarray(sigma, dtype=float)
        self._tau = np.broadcast_to(np.asarray(tau_s, dtype=float), self._sigma.shape)
        self._coeffs: tuple[float, np.ndarray, np.ndarray] | None = None
        self.value = self._sigma * rng.standard_normal(self._sigma.shape)

    def step(self, dt_s: float) -> np.ndarray:
        if self._coeffs is None or self._coeffs[0] != dt_s:
            a = np.exp(-dt_s / self._tau)
            self._coeffs = (dt_s, a, self._sigma * np.sqrt(1.0 - a * a))
        _, a, b = self._coeffs
        self.value = a * self.value + b * self._rng.standard_normal(self.value.shape)
        return self.value


class EstimatorModel:
    """PX4's EKF output as truth plus the errors of its navigation grade (and white gyro noise).

    The flight controller flies on this estimate and the telemetry reports it, so the vehicle
    holds position to within the estimator's error, as a real one does. With absolute aiding
    (GNSS, RTK) the position error wanders about zero; on optical flow it is dead reckoning's
    drift: the flow's scale error and the heading error act on every metre flown, and a
    wandering velocity bias integrates even in a hover.
    """

    def __init__(self, cfg: EstimatorConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        g = self.grade = cfg.chosen
        self._rng = rng
        tilt = math.radians(g.attitude_error_deg)
        sigma = [g.horizontal_error_m] * 2 + [g.height_error_m] + [g.velocity_error_m_s] * 3 + \
            [tilt, tilt, math.radians(g.yaw_error_deg)]
        taus = [g.horizontal_time_constant_s] * 2 + [g.height_time_constant_s] + \
            [g.velocity_time_constant_s] * 3 + [g.attitude_time_constant_s] * 3
        smooth = g.position_smoothing_s
        if smooth:  # the lag's output keeps the asked σ: var = σ_in² τ / (τ + T)
            for i in range(3):
                sigma[i] *= math.sqrt((taus[i] + smooth) / taus[i])
        self._errors = GaussMarkov(rng, np.array(sigma), np.array(taus))
        self._position_error = self._errors.value[0:3].copy()
        self._q_err: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)
        self._noise: list[list[float]] = []
        self._white = np.zeros(3)
        # dead reckoning (only drawn when flown: the aided grades keep their sequences)
        self._flow = bool(g.flow_scale_error or g.flow_velocity_bias_m_s)
        self._drift = np.zeros(3)
        self._flow_velocity_error = np.zeros(3)
        if self._flow:
            self._scale = g.flow_scale_error * float(rng.standard_normal())
            self._bias = GaussMarkov(rng, np.full(2, g.flow_velocity_bias_m_s),
                                     g.horizontal_time_constant_s)
        self.step(0.0)

    def step(self, dt_s: float, velocity_ned_m_s: np.ndarray | None = None) -> None:
        """Advance the errors by ``dt_s``; ``velocity_ned_m_s`` (the true velocity) drives an
        optical-flow grade's drift."""
        err = self._errors.step(dt_s)
        smooth = self.grade.position_smoothing_s
        if smooth:
            a = math.exp(-dt_s / smooth)
            self._position_error = a * self._position_error + (1.0 - a) * err[0:3]
        else:
            self._position_error = err[0:3]
        att = err[6:9]
        angle = float(np.sqrt(att @ att))
        self._q_err = tuple(quat_from_axis_angle(att, angle).tolist())
        if self.grade.position_noise_m:
            self._white = self.grade.position_noise_m * self._rng.standard_normal(3)
        if self._flow:
            bias = self._bias.step(dt_s)
            v = np.zeros(2) if velocity_ned_m_s is None else np.asarray(velocity_ned_m_s)[:2]
            # flow measures ground speed in the body frame, scaled by (1 + s); the estimated
            # heading (off by ψ) turns it into NED: error = s·v + ψ × v (small angles)
            psi = float(err[8])
            rate = self._scale * v + psi * np.array([-v[1], v[0]]) + bias
            self._flow_velocity_error[:2] = rate
            self._drift[:2] += rate * dt_s

    def attitude(self, q: tuple[float, ...], rates: list[float]) -> tuple[tuple, list[float]]:
        """Estimated attitude and gyro from the true ones (plain floats, for the rate loop)."""
        q_est = qmul(q, self._q_err)
        sigma = self.cfg.gyro_noise_rad_s
        if sigma:
            n = self._gyro_noise()
            rates = [rates[0] + sigma * n[0], rates[1] + sigma * n[1], rates[2] + sigma * n[2]]
        return q_est, rates

    def _gyro_noise(self) -> list[float]:
        if not self._noise:
            self._noise = self._rng.standard_normal((256, 3)).tolist()
            self._noise.reverse()
        return self._noise.pop()

    def estimate(self, position: np.ndarray, velocity: np.ndarray, q: np.ndarray,
                 rates: np.ndarray) -> EstimatedState:
        err = self._errors.value
        q_est, gyro = self.attitude(q.tolist(), rates.tolist())
        return EstimatedState(position + self._position_error + self._white + self._drift,
                              velocity + err[3:6] + self._flow_velocity_error,
                              np.array(q_est), np.array(gyro))

    @property
    def position_error_ned_m(self) -> np.ndarray:
        """The estimate's position error now (for tests and scoring)."""
        return self._position_error + self._white + self._drift


class Rangefinder:
    """Downward distance sensor at the body origin, measuring along the body z axis."""

    def __init__(self, cfg: RangefinderConfig, rng: np.random.Generator, body_id: int) -> None:
        self.cfg = cfg
        self._rng = rng
        self._body_id = body_id
        self._geom = np.zeros(1, dtype=np.int32)
        self._groups = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # visible geometry only

    def true_range(self, model: mujoco.MjModel, data: mujoco.MjData) -> float:
        origin = data.xpos[self._body_id]
        down = -data.xmat[self._body_id].reshape(3, 3)[:, 2]  # body -z in MuJoCo (FLU) = FRD +z
        dist = mujoco.mj_ray(model, data, origin, down, self._groups, 1, self._body_id, self._geom)
        return dist if dist >= 0.0 else math.inf

    def surface_velocity(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """The velocity (NED) of what the last ray hit (zero for the ground or nothing): a
        land detector on a moving deck judges the vehicle's motion relative to it."""
        geom = int(self._geom[0])
        body = int(model.geom_bodyid[geom]) if geom >= 0 else 0
        if body <= 0:
            return np.zeros(3)
        res = np.zeros(6)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, res, 0)
        return np.array([res[4], res[3], -res[5]])

    def measure(self, model: mujoco.MjModel, data: mujoco.MjData) -> float:
        dist = self.true_range(model, data)
        body_z = data.xmat[self._body_id].reshape(3, 3)[:, 2]
        return self.reading(dist, float(body_z[2]))

    def reading(self, dist: float, cos_incidence: float) -> float:
        """What the sensor reports for a surface ``dist`` away along its beam, met at an angle
        whose cosine is ``cos_incidence`` (its tilt from the vertical, on a level surface)."""
        cfg = self.cfg
        if cos_incidence < math.cos(math.radians(cfg.max_incidence_deg)):
            return math.nan
        if cfg.dropout_fraction and self._rng.random() < cfg.dropout_fraction:
            return math.nan
        if cfg.outlier_fraction and math.isfinite(dist) and \
                self._rng.random() < cfg.outlier_fraction:
            dist = cfg.max_m if self._rng.random() < 0.5 else \
                cfg.min_m + (dist - cfg.min_m) * float(self._rng.random())
            return dist if cfg.min_m <= dist <= cfg.max_m else math.nan
        if not cfg.min_m <= dist <= cfg.max_m:
            return math.nan
        return dist + cfg.noise_m * float(self._rng.standard_normal())


class BatteryModel:
    """Lithium pack drained by the rotors' power (momentum theory ÷ propulsive efficiency)."""

    def __init__(self, cfg: BatteryConfig, prop_diameter_m: float, efficiency: float,
                 air_density: float = 1.225) -> None:
        self.cfg = cfg
        disc_area = math.pi * (prop_diameter_m / 2.0) ** 2
        self._k_power = 1.0 / (math.sqrt(2.0 * air_density * disc_area) * efficiency)
        self._capacity_as = cfg.capacity_mah * 3.6
        self.remaining = cfg.initial_fraction
        self.current_a = 0.0
        self.voltage_v = self._open_circuit_v()

    def _open_circuit_v(self) -> float:
        # roughly linear LiPo discharge curve between 3.5 V and 4.2 V per cell
        return self.cfg.cells * (3.5 + 0.7 * self.remaining)

    def step(self, dt_s: float, rotor_thrust_n: np.ndarray) -> None:
        power_w = sum(t ** 1.5 for t in rotor_thrust_n.tolist() if t > 0.0) * self._k_power \
            + self.cfg.avionics_power_w
        ocv = self._open_circuit_v()
        self.current_a = power_w / max(ocv, 1e-3)
        self.voltage_v = ocv - self.current_a * self.cfg.internal_resistance_ohm
        self.remaining = max(0.0, self.remaining - self.current_a * dt_s / self._capacity_as)

    def reading(self) -> Battery:
        return Battery(voltage_v=self.voltage_v, current_a=self.current_a,
                       remaining_fraction=self.remaining)
