"""What the scenario's injected faults (:mod:`drivers.sim.faults`) do to the simulated vehicle,
on the faults' clock (seconds since the first arming): frozen and corrupt camera frames, a
position estimate that jumps (``ekf_glitch``) or dead-reckons away (``gps_loss``) and, after
``invalid_after_s``, is reported invalid, weak motors, a sagging battery and wind steps with
gusts. The simulator asks at each point where a fault may act; the random parts draw from one
generator seeded by the simulator's seed, so a faulted run replays exactly."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from drivers.base import Frame
from drivers.sim.faults import FaultSchedule, TimeWarp, WarpedPath, corrupt_image
from drivers.sim.rover import Rover


class FaultEffects:
    def __init__(self, schedule: FaultSchedule, seed: int, cameras: Mapping[str, object],
                 motors: int, rover: Rover | None = None) -> None:
        for f in schedule.faults:  # what the faults name must exist on this vehicle
            camera = getattr(f, "camera", None)
            if camera is not None and camera not in cameras:
                raise ValueError(f"fault {f.kind}: no camera {camera!r} (the vehicle's cameras: "
                                 f"{', '.join(cameras) or 'none'})")
            if f.kind == "motor_failure" and f.motor >= motors:
                raise ValueError(f"fault motor_failure: no motor {f.motor} (the vehicle has "
                                 f"{motors}: 0 to {motors - 1})")
        if schedule.of("rover_stop"):  # the rover's path on a clock that stops or reverses
            if rover is None:
                raise ValueError("fault rover_stop: the scenario has no rover")
            path = rover.path
            path = path.path if isinstance(path, WarpedPath) else path
            rover.path = WarpedPath(path, TimeWarp(schedule.of("rover_stop")))
        self.schedule = schedule
        self._rng = np.random.default_rng((seed, 6152))
        self._last_image: dict[str, np.ndarray] = {}
        self._frozen: dict[str, np.ndarray] = {}
        #: each motor's thrust as a fraction of what it should give (motor_failure)
        self.motor_scale = np.ones(motors)
        self._sagged: set[int] = set()
        self._gps_drift = np.zeros(3)
        self._gps_dir = np.zeros(3)
        self._gust_state: dict[int, np.ndarray] = {}

    def frame(self, frame: Frame, ft: float | None) -> Frame:
        """A rendered frame as its camera's faults leave it (frozen, corrupt)."""
        name = frame.camera.name
        image = frame.image
        if self.schedule.camera("camera_freeze", name, ft):
            frozen = self._frozen.setdefault(name, self._last_image.get(name, image))
            image = frozen
        else:
            self._frozen.pop(name, None)
            self._last_image[name] = image
        corrupt = self.schedule.camera("camera_corrupt", name, ft)
        if corrupt is not None:
            image = corrupt_image(image, corrupt, self._rng)
        if image is frame.image:
            return frame
        image.flags.writeable = False
        return dataclasses.replace(frame, image=image)

    def position_lost(self, ft: float | None) -> bool:
        """A gps_loss has lasted past its ``invalid_after_s``: no valid local position."""
        return any(ft - f.start_s >= f.invalid_after_s
                   for f in self.schedule.active("gps_loss", ft))

    def outer(self, ft: float | None, dt_s: float, battery, wind) -> None:
        """The slowly varying faults, at the position-loop rate: motors, battery, wind."""
        scale = np.ones(len(self.motor_scale))
        for f in self.schedule.active("motor_failure", ft):
            scale[f.motor] *= f.efficiency
        self.motor_scale = scale
        for f in self.schedule.active("battery_sag", ft):
            if id(f) not in self._sagged:
                self._sagged.add(id(f))
                battery.remaining = min(battery.remaining, f.remaining_fraction)
        extra = np.zeros(3)
        for f in self.schedule.active("wind_step", ft):
            angle = math.radians(f.direction_deg)
            extra += f.speed_m_s * np.array([math.cos(angle), math.sin(angle), 0.0])
            if f.gust_mps > 0.0:  # Gauss–Markov gusts (2 s), horizontal
                g = self._gust_state.setdefault(id(f), np.zeros(3))
                a = math.exp(-dt_s / 2.0)
                g[:] = a * g + f.gust_mps * math.sqrt(1.0 - a * a) * np.array(
                    [*self._rng.standard_normal(2), 0.0])
                extra += g
        wind.extra_ned_m_s = extra

    def estimate(self, est, ft: float | None, dt_s: float):
        """The vehicle's position estimate as ekf_glitch and gps_loss leave it."""
        offset = np.zeros(3)
        for f in self.schedule.active("ekf_glitch", ft):
            angle = math.radians(f.direction_deg)
            direction = np.array([math.cos(angle), math.sin(angle), 0.0])
            offset += direction * (f.magnitude_m + f.drift_m_s * (ft - f.start_s))
        lost = self.schedule.active("gps_loss", ft)
        if lost:
            if not self._gps_dir.any():
                angle = float(self._rng.uniform(0.0, 2.0 * math.pi))
                self._gps_dir = np.array([math.cos(angle), math.sin(angle), 0.0])
            self._gps_drift = self._gps_drift + self._gps_dir * max(
                f.drift_m_s for f in lost) * dt_s
            offset += self._gps_drift
        else:
            self._gps_drift = np.zeros(3)  # position aiding back: the estimate converges
            self._gps_dir = np.zeros(3)
        if not offset.any():
            return est
        return dataclasses.replace(est, position_ned_m=est.position_ned_m + offset)
