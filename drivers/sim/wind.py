"""Wind (steady plus Gauss–Markov gusts) and the aerodynamic drag it acts through.

Drag has two parts: rotor drag, linear in the body-horizontal airspeed and proportional to the
rotors' thrust share (blade flapping and induced drag dominate for small multirotors), and
quadratic body drag on the frame's frontal areas.
"""

from __future__ import annotations

import numpy as np

from drivers.geometry import q_to_mat
from drivers.sim.config import VehicleConfig, WindConfig
from drivers.sim.sensors import GaussMarkov

AIR_DENSITY_KG_M3 = 1.225


class WindModel:
    def __init__(self, cfg: WindConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        sigma = cfg.gust_mps * np.array([1.0, 1.0, 0.3])
        self._gust = GaussMarkov(rng, sigma, cfg.gust_time_constant_s) if cfg.gust_mps else None
        self._steady = np.asarray(cfg.steady_ned_m_s, dtype=float)
        #: added by the simulator's faults (wind_step)
        self.extra_ned_m_s = np.zeros(3)
        self.velocity_ned_m_s = self._steady + (self._gust.value if self._gust else 0.0)

    def step(self, dt_s: float) -> np.ndarray:
        gust = self._gust.step(dt_s) if self._gust is not None else 0.0
        self.velocity_ned_m_s = self._steady + gust + self.extra_ned_m_s
        return self.velocity_ned_m_s


class DragModel:
    def __init__(self, cfg: VehicleConfig) -> None:
        self._rotor_drag = cfg.rotor_drag_n_per_m_s
        self._body = [0.5 * AIR_DENSITY_KG_M3 * cfg.body_drag_coefficient * a
                      for a in cfg.body_area_frd_m2]

    def force_ned(self, velocity_ned: np.ndarray, wind_ned: np.ndarray, q_ned_frd: np.ndarray,
                  thrust_ratio: float) -> tuple[float, float, float]:
        """Aerodynamic force on the vehicle in NED. ``thrust_ratio``: total thrust ÷ weight."""
        r = q_to_mat(q_ned_frd.tolist())
        air = (velocity_ned - wind_ned).tolist()
        # airspeed in body axes: R^T · air
        body = [r[0][i] * air[0] + r[1][i] * air[1] + r[2][i] * air[2] for i in range(3)]
        f = [-self._body[i] * abs(body[i]) * body[i] for i in range(3)]
        f[0] -= self._rotor_drag * thrust_ratio * body[0]
        f[1] -= self._rotor_drag * thrust_ratio * body[1]
        return tuple(r[i][0] * f[0] + r[i][1] * f[1] + r[i][2] * f[2] for i in range(3))
