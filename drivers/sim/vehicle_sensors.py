"""What the simulated vehicle knows of itself and reports, as a PX4 vehicle's sensors, EKF2 and
telemetry would: the estimator's output (the true state with its error processes, and what
injected faults do to it), the rangefinder, the battery, each sensor's health (failures a test
injects, the position lost to a fault), and the telemetry built from them with its latency,
jitter and link faults. Drawn from the simulator's seeded generators, in capture order."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from drivers.base import Health, VehicleState
from drivers.sim.config import SimConfig
from drivers.sim.fault_effects import FaultEffects
from drivers.sim.faults import FaultSchedule
from drivers.sim.flight.flight_stack import FlightStack
from drivers.sim.flight.params import Parameters
from drivers.sim.sensors import BatteryModel, EstimatedState, EstimatorModel, Rangefinder

#: sensor failures a test can inject; "telemetry" stops the telemetry stream (the vehicle flies
#: on, as when a companion computer's telemetry stalls while its commands still get through)
FAILURE_NAMES = ("gyro", "accel", "mag", "local_position", "telemetry")


class VehicleSensors:
    def __init__(self, config: SimConfig, model: mujoco.MjModel, data: mujoco.MjData,
                 body_id: int, params: Parameters, faults: FaultSchedule,
                 effects: FaultEffects, rng_est: np.random.Generator,
                 rng_range: np.random.Generator, rng_latency: np.random.Generator) -> None:
        self._cfg = config
        self._model, self._data = model, data
        self._params = params
        self._faults, self._effects = faults, effects
        self.estimator = EstimatorModel(config.estimator, rng_est)
        self.rangefinder = Rangefinder(config.rangefinder, rng_range, body_id)
        self.battery = BatteryModel(config.battery, config.vehicle.prop_diameter_m,
                                    config.vehicle.propulsion_efficiency)
        #: the latency jitter's generator, shared with the rover link (one draw order)
        self._rng_latency = rng_latency
        self._failures: set[str] = set()
        self._last_delivery = 0.0
        #: the estimator's latest output (what telemetry reports and the flight stack flies on)
        self.estimate: EstimatedState | None = None

    def first_estimate(self, truth: tuple[np.ndarray, ...]) -> EstimatedState:
        """The estimate before the first step (so commands can be answered at once)."""
        self.estimate = self.estimator.estimate(*truth)
        return self.estimate

    def update(self, dt_s: float, truth: tuple[np.ndarray, ...],
               fault_time_s: float | None) -> EstimatedState:
        """The estimator's step at the position-loop rate, on the true state ``truth``
        (position, velocity, attitude, rates)."""
        pos, vel, q, rates = truth
        self.estimator.step(dt_s, vel)
        est = self.estimator.estimate(pos, vel, q, rates)
        if self._faults:
            est = self._effects.estimate(est, fault_time_s, dt_s)
        self.estimate = est
        return est

    def inject_failure(self, name: str, failed: bool = True) -> None:
        """Make a sensor unhealthy (or healthy again): one of :data:`FAILURE_NAMES`."""
        if name not in FAILURE_NAMES:
            raise ValueError(f"unknown failure {name!r}; expected one of {FAILURE_NAMES}")
        (self._failures.add if failed else self._failures.discard)(name)

    def health(self, time_s: float, fault_time_s: float | None) -> Health:
        est_ok = time_s >= self._cfg.estimator.init_time_s
        f = self._failures
        return Health(
            gyro_ok="gyro" not in f,
            accel_ok="accel" not in f,
            mag_ok="mag" not in f,
            local_position_ok=est_ok and "local_position" not in f and not (
                self._faults and self._effects.position_lost(fault_time_s)),
            battery_ok=self.battery.remaining > self._params["BAT_LOW_THR"],
        )

    def range(self, fault_time_s: float | None) -> float:
        """The rangefinder's reading now (NaN: none)."""
        if self._faults and self._faults.active("rangefinder_dropout", fault_time_s):
            return math.nan
        return self.rangefinder.measure(self._model, self._data)

    def telemetry(self, t: float, fault_time_s: float | None, flight: FlightStack,
                  link_faults: bool) -> tuple[float, str, VehicleState] | None:
        """The telemetry captured at ``t`` (now) and its delivery time; None when a failure
        or a fault keeps it from the vehicle interface (``link_faults``: this simulator, not
        the MAVLink face, applies ``link_loss``)."""
        if "telemetry" in self._failures:
            return None
        extra_s = 0.0
        if self._faults:
            ft, faults = fault_time_s, self._faults
            if faults.active("telemetry_dropout", ft) or (link_faults and faults.lost(ft)):
                return None
            extra_s = sum(f.delay_s for f in faults.active("telemetry_delay", ft)) + \
                (sum(f.latency_s for f in faults.active("link_loss", ft))
                 if link_faults else 0.0)
        est = self.estimate
        tel = self._cfg.telemetry
        state = VehicleState(
            time_s=t,
            position_ned_m=est.position_ned_m,
            velocity_ned_m_s=est.velocity_ned_m_s,
            attitude_q=est.q_ned_frd,
            angular_velocity_frd_rad_s=est.rates_frd_rad_s,
            armed=flight.armed,
            mode=flight.mode,
            landed_state=flight.landed_state,
            distance_to_ground_m=self.range(fault_time_s),
            battery=self.battery.reading(),
            health=self.health(t, fault_time_s),
            failsafe=flight.failsafe is not None,
        )
        jitter = tel.latency_jitter_s * float(self._rng_latency.random()) \
            if tel.latency_jitter_s else 0.0
        delivery = max(t + tel.latency_s + jitter + extra_s, self._last_delivery)
        self._last_delivery = delivery
        return delivery, "telemetry", state
