"""What the simulated vehicle receives about a scenario's rover, each stream on its own schedule
and with its own latency: UWB ranges from the rover's anchors to the vehicle's tag (when the
rover carries anchors), and the rover's own state reports over its link (jittered latency,
delivered in order)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

from drivers.sim.config import SimConfig
from drivers.sim.rover import Rover, RoverLinkModel, RoverLinkSettings, UwbModel, UwbSettings
from drivers.sim.schedule import Schedule

#: (delivery time, output kind, payload)
Delivery = tuple[float, str, Any]


class RoverSensors:
    def __init__(self, config: SimConfig, rover: Rover, rng_uwb: np.random.Generator,
                 rng_rover: np.random.Generator, rng_latency: np.random.Generator) -> None:
        u, r = config.uwb, config.rover_link
        self.rover = rover
        self._uwb_cfg, self._link_cfg = u, r
        #: the latency jitter's generator, shared with the telemetry (one draw order)
        self._rng_latency = rng_latency
        self.uwb: UwbModel | None = None
        if len(rover.anchors_frd_m):
            self.uwb = UwbModel(UwbSettings(
                tuple(tuple(float(v) for v in a) for a in rover.anchors_frd_m),
                u.tag_frd_m, u.range_noise_m, u.dropout, u.nlos_fraction, u.nlos_max_m,
                u.max_range_m), rng_uwb)
        self.link = RoverLinkModel(RoverLinkSettings(
            r.position_error_m, r.position_error_time_constant_s, r.velocity_noise_m_s,
            r.heading_noise_deg, r.heading_bias_deg, r.system_id), rng_rover)
        rate = config.physics_rate_hz
        #: each stream's captures on the physics step grid
        self.schedules: dict[str, Schedule] = {}
        if self.uwb is not None:
            self.schedules["uwb"] = Schedule(rate / u.rate_hz)
        self.schedules["rover"] = Schedule(rate / r.rate_hz)
        self._last_link_delivery = 0.0

    def latency_s(self, name: str) -> float:
        return self._uwb_cfg.latency_s if name == "uwb" else self._link_cfg.latency_s

    def capture(self, name: str, t: float, data: mujoco.MjData,
                vehicle_state: Callable[[], tuple[np.ndarray, ...]]) -> Delivery | None:
        """A UWB reading or a rover state report captured at ``t`` (the world as it is now);
        None when the UWB gave no reading."""
        pos, vel, yaw, _ = self.rover.state(data)
        if name == "uwb":
            drone_pos, _, q, _ = vehicle_state()
            reading = self.uwb.measure(t, pos, yaw, drone_pos, q)
            return None if reading is None else (t + self._uwb_cfg.latency_s, "uwb", reading)
        link = self._link_cfg
        jitter = link.latency_jitter_s * float(self._rng_latency.random()) \
            if link.latency_jitter_s else 0.0
        delivery = max(t + link.latency_s + jitter, self._last_link_delivery)
        self._last_link_delivery = delivery
        return delivery, "rover", self.link.measure(t, pos, vel, yaw)
