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

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from drivers.base import CameraInfo, Frame, Health, Setpoint
from drivers.geo import GlobalOrigin
from drivers.sim.body import SimulationDiverged, VehicleBody
from drivers.sim.captures import CameraCaptures, Photo
from drivers.sim.config import SimConfig
from drivers.sim.fault_effects import FaultEffects
from drivers.sim.faults import FaultSchedule
from drivers.sim.firmwares import make_firmware, make_params
from drivers.sim.flight.navigator import NavEvent
from drivers.sim.model import build_model
from drivers.sim.outbox import Outbox, OutputKind, SimOutput
from drivers.sim.rover import Rover
from drivers.sim.rover_sensors import RoverSensors
from drivers.sim.scenario import BodyTruth, ScenarioObject
from drivers.sim.schedule import Schedule
from drivers.sim.vehicle_sensors import FAILURE_NAMES, VehicleSensors
from drivers.sim.wind import DragModel, WindModel
from drivers.stages import STAGES

__all__ = ["FAILURE_NAMES", "GroundTruth", "OutputKind", "Photo", "SimOutput", "SimulationDiverged",
           "Simulator"]

log = logging.getLogger(__name__)


def _mujoco_warning(message: str) -> None:
    # MuJoCo's default handler prints and appends to MUJOCO_LOG.TXT in the working directory;
    # instability is detected from its warning counters (see VehicleBody.check_stability) anyway.
    log.warning("MuJoCo: %s", message.strip())


mujoco.set_mju_user_warning(_mujoco_warning)

#: commands the navigator answers itself, as PX4's does (DO_CHANGE_SPEED, the camera trigger)
NAVIGATOR_COMMANDS = frozenset({"set_speed", "take_photo", "start_photos", "stop_photos"})
_EPS = 1e-9


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


class Simulator:
    def __init__(self, config: SimConfig, scenario: Sequence[ScenarioObject] = (),
                 seed: int | None = None) -> None:
        self.cfg = config
        self.seed = config.seed if seed is None else seed
        seeds = np.random.SeedSequence(self.seed).spawn(7)
        rng_est, rng_range, rng_wind, rng_latency, _spare, rng_uwb, rng_rover = (
            np.random.default_rng(s) for s in seeds)

        self.scenario = list(scenario)
        built = build_model(config.model_copy(update={"seed": self.seed}), self.scenario)
        self.model = built.model
        self.data = mujoco.MjData(self.model)
        self.frame = built.frame
        self.airframe = built.airframe
        for obj in self.scenario:
            obj.bind(self.model, self.data, self.frame)
        mujoco.mj_forward(self.model, self.data)

        self.dt = 1.0 / config.physics_rate_hz
        #: the airframe: its true state, rotors and the forces on it
        self.body = VehicleBody(built, self.data, self.dt, config.vehicle.motor_time_constant_s)
        self._rate_div = config.physics_rate_hz // config.flight_stack.rate_loop_hz
        self._dt_ctrl = self.dt * self._rate_div
        self.origin = GlobalOrigin(*config.global_origin)
        params = self.params, self.ground_params = make_params(config)  # cascade's, GCS's
        #: the vehicle's autopilot: the firmware ``sim.firmware`` names
        self.flight = make_firmware(config, self.airframe, *params, self.origin)
        self.wind = WindModel(config.wind, rng_wind)
        self.drag = DragModel(config.vehicle)

        #: injected faults (drivers/sim/faults.py), on the scenario's clock
        self.faults = FaultSchedule(config.faults, self.seed)
        #: the cameras: their captures, shedding in real time, photos; ``rig`` draws them
        self.captures = CameraCaptures(self.model, built.cameras, config, self.seed,
                                       self.faults)
        self.cameras = self.captures.cameras
        self.rig = self.captures.rig
        self._moving = [obj for obj in self.scenario if obj.moves]
        #: the rover (a scenario with one), and its UWB ranges and reports as received
        self.rover: Rover | None = next((o for o in self.scenario if isinstance(o, Rover)),
                                        None)
        self.rover_sensors = None if self.rover is None else RoverSensors(
            config, self.rover, rng_uwb, rng_rover, rng_latency)

        self.fault_effects = FaultEffects(self.faults, self.seed, self.cameras,
                                          self.body.rotors, self.rover)
        #: what the vehicle knows of itself and reports (estimate, rangefinder, battery, health)
        self.onboard = VehicleSensors(config, self.model, self.data, self.body.body_id,
                                      self.params, self.faults, self.fault_effects, rng_est,
                                      rng_range, rng_latency)
        #: set by the MAVLink face, which applies link_loss to its datagrams itself (the
        #: simulator then does not lose telemetry and setpoints a second time)
        self.link_faults_in_face = False

        self._step = 0
        #: Scripted motion starts when the vehicle first arms (None until then), so that a
        #: scenario unfolds the same however long a client took to connect and arm.
        self._scenario_t0: float | None = None
        self._outbox = Outbox(self.captures, self._faulted)
        rate = config.physics_rate_hz
        self._tel = Schedule(rate / config.telemetry.rate_hz)
        self._truth = Schedule(rate / config.ground_truth_rate_hz)
        self._rover_schedules = self.rover_sensors.schedules if self.rover_sensors else {}
        self._schedules = (self._tel, self._truth, *self.captures.schedules.values(),
                           *self._rover_schedules.values())
        self._next_capture = 0
        self._tick = 0
        self._outer_div = config.flight_stack.rate_loop_hz // config.flight_stack.position_loop_hz
        # the flight stack sees an estimate before the first step, so commands can be answered
        self.flight.observe(self.time_s, self.onboard.first_estimate(self.body.state()),
                            self.health())

    # ------------------------------------------------------------------------------------
    # Time and stepping
    # ------------------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        return self._step * self.dt

    def advance_to(self, time_s: float) -> list[SimOutput]:
        """Step until ``time_s`` (rounded up to a physics step); return outputs now due."""
        target = math.ceil(time_s / self.dt - _EPS)
        with STAGES.stage("physics"):  # (the control ticks and captures charged within)
            while self._step < target:
                self._step_once()
        return self.pop_due()

    def pop_due(self) -> list[SimOutput]:
        """Outputs whose delivery time has come (frames are read back from the GPU now)."""
        return self._outbox.due(self.time_s + _EPS, self.time_s + self.dt)

    def _faulted(self, frame: Frame) -> Frame:
        """A frame as the injected faults leave it."""
        return self.fault_effects.frame(frame, self._fault_time(frame.time_s)) if self.faults \
            else frame

    def next_event_s(self, include_truth: bool = False) -> float:
        """Earliest time at which telemetry or a frame can become due (a lower bound).

        Ground truth and events are not included unless asked: they carry their own stamps and
        are delivered to buffered subscribers, so stepping need not stop for them.
        """
        dt = self.dt
        candidates = [self._tel.next_step * dt + self.cfg.telemetry.latency_s]
        candidates.extend(self._outbox.deliveries(include_truth))
        candidates.extend(self.captures.next_due_s(dt))
        candidates.extend(sched.next_step * dt + self.rover_sensors.latency_s(name)
                          for name, sched in self._rover_schedules.items())
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
            STAGES.call("flight stack", self._control_tick)
        self.body.spin(self.fault_effects.motor_scale)
        if k >= self._next_capture:
            STAGES.call("sensors", self._captures, k)
        mujoco.mj_step2(m, d)
        self._step = k + 1

    def _captures(self, k: int) -> None:
        """Telemetry, ground truth, rover sensors and frames due at step ``k`` (state at its
        time)."""
        t = k * self.dt
        if k >= self._tel.next_step:
            report = self.onboard.telemetry(t, self._fault_time(t), self.flight,
                                            not self.link_faults_in_face)
            if report is not None:
                self._outbox.put(*report)
            self._tel.advance(k)
        if k >= self._truth.next_step:
            self._outbox.put(t, "truth", self.ground_truth())
            self._truth.advance(k)
        for name, sched in self._rover_schedules.items():
            if k >= sched.next_step:
                reading = self.rover_sensors.capture(name, t, self.data, self.body.state)
                if reading is not None:
                    self._outbox.put(*reading)
                sched.advance(k)
        for due, pending in self.captures.capture_due(k, t, self.data, self.body.motion,
                                                      self._fault_time(t)):
            self._outbox.put(due, "frame", pending)
        self._next_capture = min(s.next_step for s in self._schedules)

    def _control_tick(self) -> None:
        """Rate-loop tick. The position loop and the slowly varying inputs (estimator error
        processes, battery, wind and drag, rangefinder, health) run at the position-loop rate;
        every tick runs attitude and rate control on the estimated attitude and gyro."""
        if self._tick % self._outer_div == 0:
            t, ft = self.time_s, self._fault_time(self.time_s)
            self.body.check_stability(t, self.flight)
            truth = self.body.state()
            dt_outer = self._dt_ctrl * self._outer_div
            battery = self.onboard.battery
            if self.faults:
                self.fault_effects.outer(ft, dt_outer, battery, self.wind)
            thrust = self.body.rotor_thrust_n
            battery.step(dt_outer, thrust)
            wind = self.wind.step(dt_outer)
            self.body.push(self.drag.force_ned(truth[1], wind, truth[2],
                                               float(thrust.sum()) / self.body.weight_n))
            health = self.onboard.health(t, ft)
            est = self.onboard.update(dt_outer, truth, ft)
            self.flight.update_outer(t, dt_outer, est, health, self.onboard.range(ft),
                                     battery.reading(),
                                     self.onboard.rangefinder.surface_velocity(self.model,
                                                                               self.data))
            q_est, gyro = est.q_ned_frd.tolist(), est.rates_frd_rad_s.tolist()
            while self.flight.events:
                when, text = self.flight.events.popleft()
                self._outbox.put(when, "event", text)
            nav_events = self.flight.nav_events  # mission and camera events, drained
            while nav_events:
                self._nav_event(nav_events.popleft())
        else:
            q_est, gyro = self.onboard.estimator.attitude(*self.body.attitude())
        self._tick += 1
        self.body.command_thrust(self.flight.update_inner(self._dt_ctrl, q_est, gyro),
                                 self.time_s)

    def _nav_event(self, event: NavEvent) -> None:
        if event.kind != "photo":
            self._outbox.put(event.time_s, "mission", event)
            return
        self._outbox.put(*self.captures.photo(
            self.data, event, self.onboard.estimate, self.origin, self.flight.navigator.home,
            self.body.motion()))

    # ------------------------------------------------------------------------------------
    # Sensors and truth
    # ------------------------------------------------------------------------------------

    def health(self) -> Health:
        """The vehicle's sensor health now."""
        return self.onboard.health(self.time_s, self.fault_time_s())

    def ground_truth(self) -> GroundTruth:
        pos, vel, q, rates = self.body.state()
        t = self.time_s
        return GroundTruth(
            time_s=t,
            vehicle=BodyTruth(pos, vel, q),
            angular_velocity_frd_rad_s=rates,
            rotor_thrust_n=self.body.rotor_thrust_n.copy(),
            wind_ned_m_s=self.wind.velocity_ned_m_s.copy(),
            bodies={obj.name: obj.truth(self._scenario_time(t), self.data)
                    for obj in self.scenario},
            armed=bool(self.flight.armed), mode=self.flight.mode.value,
            landed_state=self.flight.landed_state.value,
        )

    def _fault_time(self, time_s: float) -> float | None:
        """Scenario time of simulator time ``time_s`` (None before the first arming): the
        injected faults' clock (drivers/sim/faults.py)."""
        return None if self._scenario_t0 is None else time_s - self._scenario_t0

    def fault_time_s(self) -> float | None:
        """Now on the faults' clock (seconds since the first arming; None before)."""
        return self._fault_time(self.time_s)

    # ------------------------------------------------------------------------------------
    # Commands and inputs (raise CommandRejected to deny)
    # ------------------------------------------------------------------------------------

    def command(self, name: str, *args: Any) -> Any:
        """Run a flight-stack command: arm, disarm, takeoff, land, hold, start_offboard,
        stop_offboard, start_mission, return_to_launch, set_mode, reposition, set_mission,
        set_mission_current, gcs_heartbeat, precision_land, landing_target; and the ones the
        navigator answers itself (:data:`NAVIGATOR_COMMANDS`: the speed, the camera)."""
        self.flight.observe(self.time_s, self.onboard.estimate, self.health())
        target = self.flight.navigator if name in NAVIGATOR_COMMANDS else self.flight
        return getattr(target, name)(*args)

    def set_param(self, name: str, value: float) -> float:
        """Set a firmware parameter (ParamError if refused); returns the stored value."""
        return self.ground_params.set(name, value)

    def push_setpoint(self, setpoint: Setpoint) -> None:
        if self.faults and not self.link_faults_in_face and \
                self.faults.lost(self._fault_time(self.time_s)):
            return  # a link_loss fault lost it on the way
        self.flight.push_setpoint(setpoint, self.time_s)

    def set_telemetry_rate(self, rate_hz: float) -> None:
        """Telemetry at ``rate_hz`` from now on (the AR.Drone's navdata: demo 15, full 200 Hz)."""
        self._tel.retime(max(1.0, self.cfg.physics_rate_hz / rate_hz), self._step)

    def set_camera_active(self, name: str, active: bool) -> None:
        self.cameras[name].active = active

    def inject_failure(self, name: str, failed: bool = True) -> None:
        """Make a sensor unhealthy (or healthy again): one of :data:`FAILURE_NAMES`."""
        self.onboard.inject_failure(name, failed)

    # -- test and debugging utilities ---------------------------------------------------------

    def set_vehicle_pose(self, position_ned_m, attitude_q) -> None:
        """Teleport the airframe (at rest) to a pose in the local NED frame."""
        self.body.set_pose(position_ned_m, attitude_q)

    def start_scenario(self) -> None:
        """Start scripted motion now, as the first arming would."""
        self._scenario_t0 = self.time_s

    def capture(self, camera: str) -> Frame:
        """Render a camera now, synchronously (whether or not it is active)."""
        return self.captures.capture_now(camera, self.data, self.time_s, self.body.motion())

    def prepare_cameras(self) -> None:
        """Make every camera's render context now (see :meth:`CameraRig.prepare`)."""
        self.rig.prepare(self.data, self.cameras.values())

    def camera_infos(self) -> dict[str, CameraInfo]:
        return {name: cam.info for name, cam in self.cameras.items()}

    def close(self) -> None:
        self.rig.close()
