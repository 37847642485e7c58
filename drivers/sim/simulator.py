"""The simulated vehicle, synchronous core: MuJoCo physics + PX4-like flight stack + sensors.

One physics step (``1 / physics_rate_hz``):

1. scenario objects move (mocap; their scripted time starts when the vehicle first arms),
   ``mj_step1`` computes kinematics for time *t*;
2. every ``physics_rate_hz / rate_loop_hz`` steps the flight stack runs on the estimator's
   output and sets new rotor speed commands, and wind/drag forces are updated;
3. rotor speeds follow their commands with a first-order lag; thrust = T_max·(ω/ω_max)²;
4. telemetry, ground truth and camera frames due at *t* are captured (state at *t*) and queued
   with their delivery time (capture + latency);
5. ``mj_step2`` integrates to *t + dt*; MuJoCo's instability warnings raise
   :class:`SimulationDiverged` (MuJoCo would otherwise silently reset the state).

:meth:`Simulator.advance_to` runs steps and returns the outputs whose delivery time has come.
Not thread-safe: the driver calls everything from one thread. Ground truth is available here
and in the ``truth`` outputs, for scoring and tests only; the vehicle interface never exposes it.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import mujoco
import numpy as np

from drivers.base import CameraInfo, ConnectionLost, Frame, Health, Setpoint, VehicleState
from drivers.geo import GlobalOrigin
from drivers.sim.camera import CameraRig, SimCamera
from drivers.sim.camera_effects import CameraEffects, CaptureModel, VehicleMotion
from drivers.sim.config import SimConfig
from drivers.sim.fault_effects import FaultEffects
from drivers.sim.faults import FaultSchedule, TimeWarp, WarpedPath
from drivers.sim.flight.flight_stack import FlightStack
from drivers.sim.flight.navigator import NavEvent
from drivers.sim.flight.params import Parameters, config_defaults
from drivers.sim.frames import q_enu_flu_to_ned_frd, quat_ned_frd_to_enu_flu
from drivers.sim.model import build_model, reported_camera_info
from drivers.sim.rover import (
    Rover,
    RoverLinkModel,
    RoverLinkSettings,
    UwbModel,
    UwbSettings,
)
from drivers.sim.scenario import BodyTruth, ScenarioObject
from drivers.sim.sensors import BatteryModel, EstimatorModel, Rangefinder
from drivers.sim.wind import DragModel, WindModel

log = logging.getLogger(__name__)


def _mujoco_warning(message: str) -> None:
    # MuJoCo's default handler prints and appends to MUJOCO_LOG.TXT in the working directory;
    # instability is detected from its warning counters (see _check_stability) anyway.
    log.warning("MuJoCo: %s", message.strip())


mujoco.set_mju_user_warning(_mujoco_warning)

OutputKind = Literal["telemetry", "frame", "truth", "event", "mission", "photo", "uwb",
                     "rover"]
#: The camera that takes the photos of missions and camera commands.
PHOTO_CAMERA = "down"
#: sensor failures a test can inject; "telemetry" stops the telemetry stream (the vehicle flies
#: on, as when a companion computer's telemetry stalls while its commands still get through)
FAILURE_NAMES = ("gyro", "accel", "mag", "local_position", "telemetry")
#: commands the navigator answers itself, as PX4's does (DO_CHANGE_SPEED, the camera trigger)
NAVIGATOR_COMMANDS = frozenset({"set_speed", "take_photo", "start_photos", "stop_photos"})
_EPS = 1e-9
_INSTABILITY_WARNINGS = np.array([
    int(mujoco.mjtWarning.mjWARN_BADQPOS),
    int(mujoco.mjtWarning.mjWARN_BADQVEL),
    int(mujoco.mjtWarning.mjWARN_BADQACC),
    int(mujoco.mjtWarning.mjWARN_BADCTRL),
])


class SimulationDiverged(ConnectionLost):
    """The physics went unstable (NaN or huge values); the simulated vehicle is gone."""


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruth:
    """True state of the world at ``time_s`` (local NED: origin on the ground under the start)."""

    time_s: float
    vehicle: BodyTruth
    angular_velocity_frd_rad_s: np.ndarray
    rotor_thrust_n: np.ndarray
    wind_ned_m_s: np.ndarray
    bodies: dict[str, BodyTruth] = field(default_factory=dict)
    armed: bool | None = None  # the flight stack's own state (not as telemetry last told it)
    mode: str | None = None
    landed_state: str | None = None  # its land detector's (on_ground on a deck or a pad too)


@dataclass(frozen=True, slots=True, eq=False)
class Photo:
    """A photo the vehicle's camera took (a mission's camera item, a trigger distance, …):
    the image, and where the vehicle was when it was taken (as the estimator had it)."""

    time_s: float
    index: int
    frame: Frame | None  # None: the vehicle has no such camera (disabled)
    position_ned_m: np.ndarray
    attitude_q: np.ndarray
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    height_above_home_m: float


@dataclass(frozen=True, slots=True)
class SimOutput:
    delivery_s: float
    kind: OutputKind
    payload: Any


class Simulator:
    def __init__(self, config: SimConfig, scenario: Sequence[ScenarioObject] = (),
                 seed: int | None = None) -> None:
        self.cfg = config
        self.seed = config.seed if seed is None else seed
        seeds = np.random.SeedSequence(self.seed).spawn(7)
        rng_est, rng_range, rng_wind, rng_latency, _spare, rng_uwb, rng_rover = (
            np.random.default_rng(s) for s in seeds)
        self._rng_latency = rng_latency

        self.scenario = list(scenario)
        built = build_model(config.model_copy(update={"seed": self.seed}), self.scenario)
        self.model = built.model
        self.data = mujoco.MjData(self.model)
        self.frame = built.frame
        self.airframe = built.airframe
        self._body = built.body_id
        self._act = built.actuator_ids
        self._qpos0 = self.model.jnt_qposadr[self.model.body_jntadr[self._body]]
        self._qvel0 = self.model.jnt_dofadr[self.model.body_jntadr[self._body]]
        for obj in self.scenario:
            obj.bind(self.model, self.data, self.frame)
        mujoco.mj_forward(self.model, self.data)

        self.dt = 1.0 / config.physics_rate_hz
        self._rate_div = config.physics_rate_hz // config.flight_stack.rate_loop_hz
        self._dt_ctrl = self.dt * self._rate_div
        self.params = Parameters(config_defaults(config))
        self.origin = GlobalOrigin(*config.global_origin)
        self.flight = FlightStack(config.flight_stack, self.airframe,
                                  config.flight_stack.motor_idle_fraction, self.params,
                                  self.origin)
        self.estimator = EstimatorModel(config.estimator, rng_est)
        self.rangefinder = Rangefinder(config.rangefinder, rng_range, self._body)
        self.battery = BatteryModel(config.battery, config.vehicle.prop_diameter_m,
                                    config.vehicle.propulsion_efficiency)
        self.wind = WindModel(config.wind, rng_wind)
        self.drag = DragModel(config.vehicle)

        n = len(self._act)
        self._thrust_max = self.airframe.thrust_max_n
        self._motor_alpha = 1.0 - math.exp(-self.dt / config.vehicle.motor_time_constant_s)
        self._omega = np.zeros(n)  # rotor speed as a fraction of full speed
        self._omega_cmd = np.zeros(n)
        self.rotor_thrust_n = np.zeros(n)
        self._weight_n = self.airframe.mass_kg * 9.80665

        self.cameras = {name: SimCamera(cam_id, info, config.cameras[name].latency_s,
                                        CameraEffects.from_config(config.cameras[name]),
                                        reported_camera_info(name, config.cameras[name]))
                        for name, (cam_id, info) in built.cameras.items()}
        self._capture_models = {name: CaptureModel(name, config.cameras[name], self.seed)
                                for name in self.cameras}
        self._rig = CameraRig(self.model, self.seed)
        #: real time, behind the wall clock: every other frame due is skipped, not rendered,
        #: as is any while its camera still draws the last, and a frame not drawn when due is
        #: delivered when it is (the physics and telemetry come first, never waiting for the
        #: rendering; set by the driver)
        self.shed_rendering = False
        self._moving = [obj for obj in self.scenario if obj.moves]
        #: the rover (a scenario with one), its UWB anchors and its own telemetry
        self.rover: Rover | None = next((o for o in self.scenario if isinstance(o, Rover)),
                                        None)
        self.uwb: UwbModel | None = None
        self.rover_link: RoverLinkModel | None = None
        if self.rover is not None:
            u, r = config.uwb, config.rover_link
            if len(self.rover.anchors_frd_m):
                self.uwb = UwbModel(UwbSettings(
                    tuple(tuple(float(v) for v in a) for a in self.rover.anchors_frd_m),
                    u.tag_frd_m, u.range_noise_m, u.dropout, u.nlos_fraction, u.nlos_max_m,
                    u.max_range_m), rng_uwb)
            self.rover_link = RoverLinkModel(RoverLinkSettings(
                r.position_error_m, r.position_error_time_constant_s, r.velocity_noise_m_s,
                r.heading_noise_deg, r.heading_bias_deg, r.system_id), rng_rover)

        #: injected faults (drivers/sim/faults.py), on the scenario's clock
        self.faults = FaultSchedule(config.faults, self.seed)
        self.fault_effects = FaultEffects(self.faults, self.seed, self.cameras, len(self._act))
        if self.faults.of("rover_stop"):
            if self.rover is None:
                raise ValueError("fault rover_stop: the scenario has no rover")
            path = self.rover.path
            path = path.path if isinstance(path, WarpedPath) else path
            self.rover.path = WarpedPath(path, TimeWarp(self.faults.of("rover_stop")))
        #: set by the MAVLink face, which applies link_loss to its datagrams itself (the
        #: simulator then does not lose telemetry and setpoints a second time)
        self.link_faults_in_face = False

        self._step = 0
        #: Scripted motion starts when the vehicle first arms (None until then), so that a
        #: scenario unfolds the same however long a client took to connect and arm.
        self._scenario_t0: float | None = None
        self._failures: set[str] = set()
        self._outbox: list[tuple[float, int, SimOutput]] = []
        self._seq = itertools.count()
        rate = config.physics_rate_hz
        self._tel = _Schedule(rate / config.telemetry.rate_hz)
        self._truth = _Schedule(rate / config.ground_truth_rate_hz)
        self._cam_schedules = {name: _Schedule(rate / cam.info.rate_hz)
                               for name, cam in self.cameras.items()}
        self._sensor_schedules: dict[str, _Schedule] = {}
        if self.uwb is not None:
            self._sensor_schedules["uwb"] = _Schedule(rate / config.uwb.rate_hz)
        if self.rover_link is not None:
            self._sensor_schedules["rover"] = _Schedule(rate / config.rover_link.rate_hz)
        self._last_rover_delivery = 0.0
        self._last_tel_delivery = 0.0
        self._next_capture = 0
        self._tick = 0
        self._outer_div = config.flight_stack.rate_loop_hz // config.flight_stack.position_loop_hz
        self._height = math.nan
        self._health = Health(local_position_ok=False)
        self._origin = tuple(self.frame.origin_enu_m.tolist())
        self._warnings0 = self.data.warning.number[_INSTABILITY_WARNINGS].copy()
        # the flight stack sees an estimate before the first step, so commands can be answered
        self._est = self.estimator.estimate(*self._truth_state())
        self.flight.observe(self.time_s, self._est, self.health())

    # ------------------------------------------------------------------------------------
    # Time and stepping
    # ------------------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        return self._step * self.dt

    def advance_to(self, time_s: float) -> list[SimOutput]:
        """Step until ``time_s`` (rounded up to a physics step); return outputs now due."""
        target = math.ceil(time_s / self.dt - _EPS)
        while self._step < target:
            self._step_once()
        return self.pop_due()

    def pop_due(self) -> list[SimOutput]:
        """Outputs whose delivery time has come (frames are read back from the GPU now)."""
        now = self.time_s + _EPS
        out, rendering = [], []
        while self._outbox and self._outbox[0][0] <= now:
            item = heapq.heappop(self._outbox)[2]
            if item.kind == "frame":
                if self.shed_rendering and not item.payload.image.done():
                    rendering.append(item.payload)  # delivered when drawn, later than due
                    continue
                frame = self._rig.finish(item.payload)
                if self.faults:
                    frame = self.fault_effects.frame(frame, self._fault_time(frame.time_s))
                item = SimOutput(item.delivery_s, "frame", frame)
            elif item.kind == "photo" and isinstance(item.payload, tuple):
                meta, pending = item.payload
                item = SimOutput(item.delivery_s, "photo", dataclasses.replace(
                    meta, frame=self._rig.finish(pending)))
            out.append(item)
        for pending in rendering:
            self._queue(self.time_s + self.dt, "frame", pending)
        return out

    def next_event_s(self, include_truth: bool = False) -> float:
        """Earliest time at which telemetry or a frame can become due (a lower bound).

        Ground truth and events are not included unless asked: they carry their own stamps and
        are delivered to buffered subscribers, so stepping need not stop for them.
        """
        dt = self.dt
        candidates = [self._tel.next_step * dt + self.cfg.telemetry.latency_s]
        candidates.extend(out[0] for out in self._outbox
                          if include_truth or out[2].kind in ("telemetry", "frame"))
        candidates.extend(self._cam_schedules[name].next_step * dt + cam.latency_s
                          for name, cam in self.cameras.items() if cam.active)
        candidates.extend(sched.next_step * dt + self._sensor_latency(name)
                          for name, sched in self._sensor_schedules.items())
        if include_truth:
            candidates.append(self._truth.next_step * dt)
        return max(min(candidates), self.time_s + dt)

    @property
    def scenario_start_s(self) -> float | None:
        """When scripted motion started (the first arming), None before."""
        return self._scenario_t0

    def _scenario_time(self, time_s: float) -> float:
        """Where scripted motion is at simulator time ``time_s`` (0 until the first arming)."""
        return time_s - self._scenario_t0 if self._scenario_t0 is not None else 0.0

    def _step_once(self) -> None:
        m, d = self.model, self.data
        k = self._step
        control = k % self._rate_div == 0
        if self._scenario_t0 is None and self.flight.armed and \
                (control or k >= self._next_capture):
            self._scenario_t0 = k * self.dt
        if self._moving and (control or k >= self._next_capture):
            t = self._scenario_time(k * self.dt)
            for obj in self._moving:
                obj.update(t, d)
        mujoco.mj_step1(m, d)
        if control:
            self._control_tick()
        omega = self._omega
        omega += self._motor_alpha * (self._omega_cmd - omega)
        self.rotor_thrust_n = thrust = self._thrust_max * omega * omega * \
            self.fault_effects.motor_scale
        d.ctrl[self._act] = thrust
        if k >= self._next_capture:
            self._captures(k)
        mujoco.mj_step2(m, d)
        self._step = k + 1

    def _captures(self, k: int) -> None:
        """Telemetry, ground truth and frames due at step ``k`` (state at its time)."""
        t = k * self.dt
        if k >= self._tel.next_step:
            self._capture_telemetry(t)
            self._tel.advance(k)
        if k >= self._truth.next_step:
            self._queue(t, "truth", self.ground_truth())
            self._truth.advance(k)
        for name, sched in self._sensor_schedules.items():
            if k >= sched.next_step:
                self._capture_rover_sensor(name, t)
                sched.advance(k)
        motion = None
        for name, cam in self.cameras.items():
            sched = self._cam_schedules[name]
            if k >= sched.next_step:
                if cam.active and self.shed_rendering and (cam.may_shed
                                                           or self._rig.rendering(cam)):
                    # every other frame (the video goes on at half its rate), and any frame
                    # whose camera is still rendering the last one: physics does not wait
                    cam.shed += 1
                    cam.may_shed = False
                elif cam.active and not (self.faults and self.faults.camera(
                        "camera_dropout", name, self._fault_time(t))):
                    capture = self._capture_models[name].next()
                    if capture.dropped:
                        cam.seq += 1  # the autopilot sees the gap in the sequence numbers
                    else:
                        due = t + cam.latency_s + capture.delay_s
                        if motion is None:
                            motion = self._vehicle_motion()
                        cam.may_shed = True
                        pending = self._rig.submit(self.data, cam, t,
                                                   due - self.cfg.realtime_render_lead_s,
                                                   motion, capture.gain)
                        self._queue(due, "frame", pending)
                sched.advance(k)
        self._update_next_capture()

    def _update_next_capture(self) -> None:
        self._next_capture = min(self._tel.next_step, self._truth.next_step,
                                 *(s.next_step for s in self._cam_schedules.values()),
                                 *(s.next_step for s in self._sensor_schedules.values()))

    def _control_tick(self) -> None:
        """Rate-loop tick. The position loop and the slowly varying inputs (estimator error
        processes, battery, wind and drag, rangefinder, health) run at the position-loop rate;
        every tick runs attitude and rate control on the estimated attitude and gyro."""
        d = self.data
        if self._tick % self._outer_div == 0:
            self._check_stability()
            pos, vel, q, rates = self._truth_state()
            dt_outer = self._dt_ctrl * self._outer_div
            self.estimator.step(dt_outer, vel)
            if self.faults:
                self.fault_effects.outer(self._fault_time(self.time_s), dt_outer, self.battery,
                                         self.wind)
            thrust = self.rotor_thrust_n
            self.battery.step(dt_outer, thrust)
            wind = self.wind.step(dt_outer)
            f = self.drag.force_ned(vel, wind, q, float(thrust.sum()) / self._weight_n)
            d.xfrc_applied[self._body, :3] = (f[1], f[0], -f[2])  # NED → ENU
            self._health = self.health()
            est = self.estimator.estimate(pos, vel, q, rates)
            if self.faults:
                est = self.fault_effects.estimate(est, self._fault_time(self.time_s), dt_outer)
            self._est = est
            self.flight.update_outer(self.time_s, dt_outer, est, self._health,
                                     self._range(),
                                     self.battery.remaining,
                                     self.rangefinder.surface_velocity(self.model, d))
            q_est, gyro = est.q_ned_frd.tolist(), est.rates_frd_rad_s.tolist()
            while self.flight.events:
                when, text = self.flight.events.popleft()
                self._queue(when, "event", text)
            nav_events = self.flight.navigator.events  # mission and camera events, drained
            while nav_events:
                self._nav_event(nav_events.popleft())
        else:
            q_est, gyro = self.estimator.attitude(*self._truth_attitude())
        self._tick += 1
        thrust_cmd = self.flight.update_inner(self._dt_ctrl, q_est, gyro)
        for value in thrust_cmd:
            if not math.isfinite(value):
                raise SimulationDiverged(f"flight stack produced non-finite thrust at "
                                         f"t={self.time_s:.3f} s: {thrust_cmd}")
        self._omega_cmd = np.sqrt(np.clip(np.array(thrust_cmd) / self._thrust_max, 0.0, 1.0))

    def _nav_event(self, event: NavEvent) -> None:
        if event.kind != "photo":
            self._queue(event.time_s, "mission", event)
            return
        est = self._est
        lat, lon, alt = self.origin.to_global(*(float(v) for v in est.position_ned_m))
        home = self.flight.navigator.home
        height = float((home[2] if home is not None else 0.0) - est.position_ned_m[2])
        meta = Photo(event.time_s, event.seq, None, est.position_ned_m.copy(),
                     est.q_ned_frd.copy(), lat, lon, alt, height)
        cam = self.cameras.get(PHOTO_CAMERA)
        if cam is None:
            self._queue(event.time_s, "photo", meta)
            return
        pending = self._rig.submit(self.data, cam, event.time_s, motion=self._vehicle_motion())
        self._queue(event.time_s + cam.latency_s, "photo", (meta, pending))

    def _vehicle_motion(self) -> VehicleMotion:
        """The vehicle's true motion now (motion blur and rolling shutter of its cameras)."""
        return VehicleMotion(*self._truth_state())

    def _truth_attitude(self) -> tuple[tuple[float, ...], list[float]]:
        qw, qx, qy, qz = self.data.qpos[self._qpos0 + 3:self._qpos0 + 7].tolist()
        wx, wy, wz = self.data.qvel[self._qvel0 + 3:self._qvel0 + 6].tolist()
        # free joint: angular velocity is in body (FLU) axes
        return q_enu_flu_to_ned_frd((qw, qx, qy, qz)), [wx, -wy, -wz]

    def _truth_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        d = self.data
        x, y, z = d.qpos[self._qpos0:self._qpos0 + 3].tolist()
        vx, vy, vz = d.qvel[self._qvel0:self._qvel0 + 3].tolist()
        q, rates = self._truth_attitude()
        ox, oy, oz = self._origin
        return (np.array((y - oy, x - ox, oz - z)), np.array((vy, vx, -vz)), np.array(q),
                np.array(rates))

    def _check_stability(self) -> None:
        counts = self.data.warning.number[_INSTABILITY_WARNINGS]
        if (counts != self._warnings0).any():
            bad = _INSTABILITY_WARNINGS[counts != self._warnings0]
            names = ", ".join(mujoco.mjtWarning(int(w)).name.removeprefix("mjWARN_") for w in bad)
            raise SimulationDiverged(
                f"MuJoCo physics diverged ({names}) at t={self.time_s:.3f} s; last rotor "
                f"thrust {np.round(self.rotor_thrust_n, 2).tolist()} N, "
                f"mode {self.flight.mode.value}"
            )

    def _queue(self, delivery_s: float, kind: OutputKind, payload: Any) -> None:
        heapq.heappush(self._outbox, (delivery_s, next(self._seq),
                                      SimOutput(delivery_s, kind, payload)))

    # ------------------------------------------------------------------------------------
    # Sensors and truth
    # ------------------------------------------------------------------------------------

    def _sensor_latency(self, name: str) -> float:
        return self.cfg.uwb.latency_s if name == "uwb" else self.cfg.rover_link.latency_s

    def _capture_rover_sensor(self, name: str, t: float) -> None:
        """A UWB reading or a rover state report captured now (state at ``t``)."""
        pos, vel, yaw, _ = self.rover.state(self.data)
        if name == "uwb":
            drone_pos, _, q, _ = self._truth_state()
            reading = self.uwb.measure(t, pos, yaw, drone_pos, q)
            if reading is not None:
                self._queue(t + self.cfg.uwb.latency_s, "uwb", reading)
            return
        link = self.cfg.rover_link
        jitter = link.latency_jitter_s * float(self._rng_latency.random()) \
            if link.latency_jitter_s else 0.0
        delivery = max(t + link.latency_s + jitter, self._last_rover_delivery)
        self._last_rover_delivery = delivery
        self._queue(delivery, "rover", self.rover_link.measure(t, pos, vel, yaw))

    def health(self) -> Health:
        est_ok = self.time_s >= self.cfg.estimator.init_time_s
        f = self._failures
        return Health(
            gyro_ok="gyro" not in f,
            accel_ok="accel" not in f,
            mag_ok="mag" not in f,
            local_position_ok=est_ok and "local_position" not in f and not (
                self.faults and self.fault_effects.position_lost(self._fault_time(self.time_s))),
            battery_ok=self.battery.remaining > self.params["BAT_LOW_THR"],
        )

    def _capture_telemetry(self, t: float) -> None:
        if "telemetry" in self._failures:
            return
        extra_s = 0.0
        if self.faults:
            ft = self._fault_time(t)
            link = not self.link_faults_in_face
            if self.faults.active("telemetry_dropout", ft) or (link and self.faults.lost(ft)):
                return
            extra_s = sum(f.delay_s for f in self.faults.active("telemetry_delay", ft)) + \
                (sum(f.latency_s for f in self.faults.active("link_loss", ft)) if link else 0.0)
        est = self._est
        tel = self.cfg.telemetry
        state = VehicleState(
            time_s=t,
            position_ned_m=est.position_ned_m,
            velocity_ned_m_s=est.velocity_ned_m_s,
            attitude_q=est.q_ned_frd,
            angular_velocity_frd_rad_s=est.rates_frd_rad_s,
            armed=self.flight.armed,
            mode=self.flight.mode,
            landed_state=self.flight.landed_state,
            distance_to_ground_m=self._range(),
            battery=self.battery.reading(),
            health=self.health(),
            failsafe=self.flight.failsafe is not None,
        )
        jitter = tel.latency_jitter_s * float(self._rng_latency.random()) \
            if tel.latency_jitter_s else 0.0
        delivery = max(t + tel.latency_s + jitter + extra_s, self._last_tel_delivery)
        self._last_tel_delivery = delivery
        self._queue(delivery, "telemetry", state)

    def ground_truth(self) -> GroundTruth:
        pos, vel, q, rates = self._truth_state()
        t = self.time_s
        return GroundTruth(
            time_s=t,
            vehicle=BodyTruth(pos, vel, q),
            angular_velocity_frd_rad_s=rates,
            rotor_thrust_n=self.rotor_thrust_n.copy(),
            wind_ned_m_s=self.wind.velocity_ned_m_s.copy(),
            bodies={obj.name: obj.truth(self._scenario_time(t), self.data)
                    for obj in self.scenario},
            armed=bool(self.flight.armed), mode=self.flight.mode.value,
            landed_state=self.flight.landed_state.value,
        )

    # ------------------------------------------------------------------------------------
    # Injected faults (drivers/sim/faults.py)
    # ------------------------------------------------------------------------------------

    def _fault_time(self, time_s: float) -> float | None:
        """Scenario time of simulator time ``time_s`` (None before the first arming)."""
        return None if self._scenario_t0 is None else time_s - self._scenario_t0

    def fault_time_s(self) -> float | None:
        """Now on the faults' clock (seconds since the first arming; None before)."""
        return self._fault_time(self.time_s)

    def _range(self) -> float:
        if self.faults and self.faults.active("rangefinder_dropout",
                                              self._fault_time(self.time_s)):
            return math.nan
        return self.rangefinder.measure(self.model, self.data)

    # ------------------------------------------------------------------------------------
    # Commands and inputs (raise CommandRejected to deny)
    # ------------------------------------------------------------------------------------

    def command(self, name: str, *args: Any) -> Any:
        """Run a flight-stack command: arm, disarm, takeoff, land, hold, start_offboard,
        stop_offboard, start_mission, return_to_launch, set_mode, reposition, set_mission,
        set_mission_current, gcs_heartbeat, precision_land, landing_target; and the ones the
        navigator answers itself (:data:`NAVIGATOR_COMMANDS`: the speed, the camera)."""
        self.flight.observe(self.time_s, self._est, self.health())
        target = self.flight.navigator if name in NAVIGATOR_COMMANDS else self.flight
        return getattr(target, name)(*args)

    def set_param(self, name: str, value: float) -> float:
        """Set a PX4 parameter (raises ParamError if refused); returns the stored value."""
        return self.params.set(name, value)

    def push_setpoint(self, setpoint: Setpoint) -> None:
        if self.faults and not self.link_faults_in_face and \
                self.faults.lost(self._fault_time(self.time_s)):
            return  # a link_loss fault lost it on the way
        self.flight.push_setpoint(setpoint, self.time_s)

    def set_camera_active(self, name: str, active: bool) -> None:
        self.cameras[name].active = active

    def inject_failure(self, name: str, failed: bool = True) -> None:
        """Make a sensor unhealthy (or healthy again): one of :data:`FAILURE_NAMES`."""
        if name not in FAILURE_NAMES:
            raise ValueError(f"unknown failure {name!r}; expected one of {FAILURE_NAMES}")
        (self._failures.add if failed else self._failures.discard)(name)

    # -- test and debugging utilities ---------------------------------------------------------

    def set_vehicle_pose(self, position_ned_m, attitude_q) -> None:
        """Teleport the airframe (at rest) to a pose in the local NED frame."""
        qp, qv = self._qpos0, self._qvel0
        self.data.qpos[qp:qp + 3] = self.frame.to_enu(np.asarray(position_ned_m, dtype=float))
        self.data.qpos[qp + 3:qp + 7] = quat_ned_frd_to_enu_flu(np.asarray(attitude_q,
                                                                           dtype=float))
        self.data.qvel[qv:qv + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def capture(self, camera: str) -> Frame:
        """Render a camera now, synchronously (whether or not it is active)."""
        cam = self.cameras[camera]
        return self._rig.finish(self._rig.submit(self.data, cam, self.time_s,
                                                 motion=self._vehicle_motion()))

    def set_realtime_rendering(self, gate: Callable[[float], None] | None,
                               background: bool = True) -> None:
        """Render as the real-time driver needs (see camera.py): at a lower CPU priority
        (``background``), and each scheduled frame held until ``gate(t)`` returns, where ``t``
        is ``realtime_render_lead_s`` before the frame is due. Call before the first render."""
        self._rig.render_gate = gate
        self._rig.background = background

    def prepare_cameras(self) -> None:
        """Make every camera's render context now (see :meth:`CameraRig.prepare`)."""
        self._rig.prepare(self.data, self.cameras.values())

    def camera_infos(self) -> dict[str, CameraInfo]:
        return {name: cam.info for name, cam in self.cameras.items()}

    def close(self) -> None:
        self._rig.close()


class _Schedule:
    """Periodic capture on the physics step grid: the k-th capture is the first step at or
    after k·period (in steps), so the average rate is exact and stamps are true step times."""

    def __init__(self, period_steps: float) -> None:
        self._period = period_steps
        self._count = 0
        self.next_step = 0

    def advance(self, step: int) -> None:
        while self.next_step <= step:
            self._count += 1
            self.next_step = math.ceil(self._count * self._period - _EPS)
