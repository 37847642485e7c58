"""The simulated vehicle's autopilot: a PX4-equivalent flight stack.

Split as PX4 is: :class:`~drivers.sim.flight.commander.Commander` (arming, modes, failsafes),
:class:`~drivers.sim.flight.navigator.Navigator` (takeoff, hold, land, mission, return, geofence),
:class:`~drivers.sim.flight.params.Parameters`, and here the glue and the control cascade
position P → velocity PID → attitude P → rate PID → allocation. It knows nothing of MuJoCo: the
simulator calls :meth:`FlightStack.update_outer` at the position-loop rate and
:meth:`FlightStack.update_inner` at the rate-loop rate with the estimator's output (NED/FRD), and
applies the rotor thrusts that the latter returns.

Semantics follow PX4 (v1.14+) as MAVSDK sees it; where this differs from PX4 it says so here:

* OFFBOARD (PX4's offboardCheck): the offboard signal is present while the newest setpoint is
  younger than COM_OF_LOSS_T and the vehicle can fly what it controls (a valid local position
  for position and velocity setpoints). One setpoint is enough to switch in; "proof of life"
  streaming is the loss failsafe's business. Mode changes are always accepted while disarmed
  (PX4's user mode intention); arming then checks that the mode can run. In OFFBOARD on the
  ground, a setpoint above the vehicle takes off, as in PX4.
* Setpoint loss → COM_OBL_RC_ACT at once (no failsafe delay), and back to OFFBOARD when
  setpoints return unless the user changed mode meanwhile.
* Low-level differences: thrust is commanded in newtons directly (an ideal thrust curve), rate
  gains act on angular acceleration, and the hover thrust is known (a converged estimator).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drivers.base import FlightMode, Health, LandedState, Setpoint, SetpointFrame
from drivers.geo import GlobalOrigin
from drivers.geometry import rot_z, wrap_pi, yaw_from_quat
from drivers.mission import MissionItem, MissionType
from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.allocation import ControlAllocator
from drivers.sim.flight.attitude_control import AttitudeController
from drivers.sim.flight.commander import Commander, CommandRejected, Inputs
from drivers.sim.flight.land_detector import LandDetector
from drivers.sim.flight.navigator import Estimate, MissionStatus, NavEvent, Navigator
from drivers.sim.flight.params import Parameters
from drivers.sim.flight.position_control import (
    GRAVITY_M_S2,
    LEVEL_DOWN,
    AttitudeSetpoint,
    ControlSetpoint,
    PositionController,
    body_z_to_attitude,
)
from drivers.sim.flight.rate_control import RateController

__all__ = ["Airframe", "CommandRejected", "EstimatedState", "FlightStack"]

NAN = float("nan")
_TAKEOFF_TRIGGER_M = 0.2  # a setpoint this far above the vehicle means "take off"
_TAKEOFF_TRIGGER_M_S = 0.3
_LAND_THRUST_RAMP_S = 0.5  # thrust ramps to zero this fast once the ground is felt
_GCS_NEVER = -math.inf


@dataclass(frozen=True, slots=True)
class Airframe:
    """Physical parameters the controller is allowed to know (from the MJCF model)."""

    mass_kg: float
    inertia_frd_kg_m2: np.ndarray  # principal moments (x, y, z)
    rotor_positions_frd_m: np.ndarray  # n × 3
    yaw_coefficients_m: np.ndarray  # yaw torque per newton of thrust, FRD
    thrust_max_n: np.ndarray

    @property
    def hover_thrust(self) -> float:
        return self.mass_kg * GRAVITY_M_S2 / float(self.thrust_max_n.sum())


@dataclass(frozen=True, slots=True)
class EstimatedState:
    """The estimator's output, as the controller and the telemetry see it."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    q_ned_frd: np.ndarray
    rates_frd_rad_s: np.ndarray


class FlightStack:
    def __init__(self, cfg: FlightStackConfig, airframe: Airframe, motor_idle_fraction: float,
                 params: Parameters | None = None,
                 origin: GlobalOrigin | None = None) -> None:
        self.cfg = cfg
        self.airframe = airframe
        self.params = params if params is not None else Parameters()
        self.origin = origin if origin is not None else GlobalOrigin(47.397742, 8.545594, 488.0)
        hover = cfg.position.hover_thrust or airframe.hover_thrust
        self.hover_thrust = hover
        self.position_ctrl = PositionController(cfg.position, hover)
        self.attitude_ctrl = AttitudeController(cfg.attitude)
        self.rate_ctrl = RateController(cfg.rates)
        self.allocator = ControlAllocator(airframe.rotor_positions_frd_m,
                                          airframe.yaw_coefficients_m, airframe.thrust_max_n)
        self.land_detector = LandDetector(cfg.land_detector, cfg.position.thrust_min, hover)
        self._idle_n = motor_idle_fraction * float(airframe.thrust_max_n.min())
        self._inertia = np.asarray(airframe.inertia_frd_kg_m2, dtype=float)
        self._thrust_total_max = float(airframe.thrust_max_n.sum())

        #: (time_s, text) of mode changes and failsafes, drained by the simulator.
        self.events: deque[tuple[float, str]] = deque(maxlen=256)
        self.commander = Commander(self.params, self._event)
        self.navigator = Navigator(self.params, self.origin, request_mode=self._auto_mode,
                                   complete=self.commander.complete, event=self._event)
        self.commander.on_mode_change = self._mode_changed
        self.commander.on_disarm = self._disarmed
        self.params.on_change(lambda name, value: self._apply_params())
        self._apply_params()
        self._now = 0.0
        self._est: EstimatedState | None = None
        self._health = Health(local_position_ok=False)
        self._battery_fraction = 1.0
        self._gcs_heard_s = _GCS_NEVER
        self._surface_velocity: np.ndarray | None = None
        #: why the vehicle is outside its geofence now (None: inside, or no fence)
        self.geofence_breach: str | None = None

        # offboard
        self._offboard_sp: tuple[np.ndarray, np.ndarray, float, float, np.ndarray] | None = None
        self._offboard_sp_s = -math.inf
        self._offboard_yaw = 0.0

        # control state
        self._phase = "ground"  # ground | ramp | flight
        self._ramp_start = 0.0
        self._land_thrust_scale = 1.0
        self._att_sp = AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), 0.0, 0.0)
        self._sat_pos: tuple[bool, ...] = (False, False, False)
        self._sat_neg: tuple[bool, ...] = (False, False, False)
        self._prev_gyro: list[float] | None = None
        self._ang_acc = [0.0, 0.0, 0.0]
        self._d_alpha = 0.0
        self._inertia_l = self._inertia.tolist()

    # ------------------------------------------------------------------------------------
    # Reported state
    # ------------------------------------------------------------------------------------

    @property
    def armed(self) -> bool:
        return self.commander.armed

    @property
    def mode(self) -> FlightMode:
        return self.commander.mode

    @property
    def failsafe(self) -> str | None:
        return self.commander.failsafe

    @property
    def landed(self) -> bool:
        return self.land_detector.landed

    @property
    def landed_state(self) -> LandedState:
        if self.land_detector.landed:
            return LandedState.ON_GROUND
        if self.mode is FlightMode.TAKEOFF:
            return LandedState.TAKING_OFF
        if self.mode is FlightMode.LAND or self._landing:
            return LandedState.LANDING
        return LandedState.IN_AIR

    _landing = False

    @property
    def takeoff_altitude_m(self) -> float:
        return self.params["MIS_TAKEOFF_ALT"]

    @property
    def home_ned_m(self) -> np.ndarray | None:
        return self.navigator.home

    @property
    def mission_status(self) -> MissionStatus:
        return self.navigator.status

    def nav_events(self) -> list[NavEvent]:
        """Mission and camera events since the last call (drained)."""
        events = list(self.navigator.events)
        self.navigator.events.clear()
        return events

    # ------------------------------------------------------------------------------------
    # Commands (MAVLink COMMAND_LONG equivalents). Raise CommandRejected to deny.
    # ------------------------------------------------------------------------------------

    def arm(self) -> None:
        if self.armed:
            return
        problem = self.commander.arming_problem(self._health, self.landed,
                                                self._battery_fraction)
        if problem is not None:
            raise CommandRejected(problem)
        problem = self._mode_problem(self.commander.user_mode, arming=True)
        if problem is not None:
            raise CommandRejected(f"arming denied in {self.commander.user_mode.value}: "
                                  f"{problem}")
        if int(self.params["NAV_DLL_ACT"]) > 0 and self._gcs_heard_s == _GCS_NEVER:
            raise CommandRejected("arming denied: no connection to the ground control station "
                                  "(NAV_DLL_ACT is set)")
        self.commander.arm(self._now)
        est = self._est
        self.navigator.home = est.position_ned_m.copy() if est is not None else np.zeros(3)
        if self.commander.user_mode in (FlightMode.HOLD, FlightMode.MISSION):
            # the hold point, the mission's takeoff: from where the vehicle stands now
            self.navigator.activate(self.mode, self._nav_estimate(), landed=True)

    def disarm(self, force: bool = False) -> None:
        if not self.armed:
            return
        if not self.landed and not force:
            raise CommandRejected("vehicle is in the air (force to stop the motors)")
        self.commander.disarm("disarmed" + (" (forced)" if force else ""))

    def takeoff(self, altitude_m: float | None = None) -> None:
        """TAKEOFF to ``altitude_m`` above home (this takeoff only; None: MIS_TAKEOFF_ALT)."""
        if altitude_m is not None and not altitude_m > 0:
            raise CommandRejected(f"takeoff altitude must be positive, got {altitude_m}")
        if not self.armed:
            raise CommandRejected("not armed")
        if not self._health.local_position_ok:
            raise CommandRejected("no valid local position")
        self.navigator.takeoff_altitude_override_m = altitude_m
        self._user_mode(FlightMode.TAKEOFF)

    def land(self) -> None:
        self._require_estimate()
        self._user_mode(FlightMode.LAND)

    def hold(self) -> None:
        self._user_mode(FlightMode.HOLD)

    def precision_land(self) -> None:
        """AUTO.PRECLAND: land on the reported landing target (:mod:`precland`)."""
        self._require_estimate()
        if not self.armed or self.landed:
            raise CommandRejected("precision landing needs the vehicle in the air")
        self._user_mode(FlightMode.PRECLAND)

    def landing_target(self, position_ned_m: Sequence[float], time_s: float) -> None:
        """LANDING_TARGET (MAV_FRAME_LOCAL_NED) for precision landing."""
        self.navigator.precland.landing_target(time_s, position_ned_m)

    def start_offboard(self) -> None:
        if self.mode is not FlightMode.OFFBOARD:
            self._offboard_yaw = yaw_from_quat(self._require_estimate().q_ned_frd)
        self._user_mode(FlightMode.OFFBOARD)

    def stop_offboard(self) -> None:
        self.hold()

    def start_mission(self) -> None:
        self._user_mode(FlightMode.MISSION)

    def return_to_launch(self) -> None:
        self._user_mode(FlightMode.RETURN)

    def set_mode(self, mode: FlightMode) -> None:
        """DO_SET_MODE to one of the modes the simulator flies."""
        actions = {FlightMode.HOLD: self.hold, FlightMode.LAND: self.land,
                   FlightMode.OFFBOARD: self.start_offboard, FlightMode.MISSION: self.start_mission,
                   FlightMode.RETURN: self.return_to_launch, FlightMode.TAKEOFF: self.takeoff,
                   FlightMode.PRECLAND: self.precision_land}
        action = actions.get(mode)
        if action is None:
            raise CommandRejected(f"{mode.value} mode is not available (no manual control "
                                  "in the simulation)")
        action()

    def reposition(self, target_ned_m: Sequence[float], yaw_rad: float = NAN,
                   speed_m_s: float = NAN) -> None:
        """DO_REPOSITION: HOLD, flying to ``target_ned_m`` first (NaN: keep that axis)."""
        if not self.armed or self.landed:
            raise CommandRejected("reposition needs the vehicle in the air")
        self.hold()
        self.navigator.reposition(np.asarray(target_ned_m, dtype=float), yaw_rad, speed_m_s,
                                  self._nav_estimate())

    def set_speed(self, speed_m_s: float) -> None:
        self.navigator.set_speed(speed_m_s)

    def set_mission(self, items: Sequence[MissionItem],
                    mission_type: int = MissionType.MISSION) -> None:
        self.navigator.set_items(items, mission_type)

    def set_mission_current(self, seq: int) -> None:
        try:
            self.navigator.set_current(seq)
        except ValueError as exc:
            raise CommandRejected(str(exc)) from None

    def take_photo(self) -> None:
        self.navigator.take_photo()

    def start_photos(self, interval_s: float, count: int) -> None:
        self.navigator.start_photos(interval_s, count)

    def stop_photos(self) -> None:
        self.navigator.stop_photos()

    def gcs_heartbeat(self) -> None:
        """A ground station's HEARTBEAT arrived (for the data-link loss failsafe)."""
        self._gcs_heard_s = self._now

    def push_setpoint(self, sp: Setpoint, now_s: float) -> None:
        """An offboard setpoint arrives at ``now_s``."""
        self._now = now_s
        vel = np.array(sp.velocity_m_s)
        if sp.frame is SetpointFrame.BODY_FRD:
            # PX4 rotates body-frame velocity by the heading at reception
            yaw = yaw_from_quat(self._est.q_ned_frd) if self._est is not None else 0.0
            vel = rot_z(yaw) @ vel
        self._offboard_sp = (np.array(sp.position_ned_m), vel, sp.yaw_rad, sp.yaw_rate_rad_s,
                             np.array(sp.acceleration_m_s2))
        self._offboard_sp_s = now_s

    # ------------------------------------------------------------------------------------
    # Mode plumbing
    # ------------------------------------------------------------------------------------

    def _user_mode(self, mode: FlightMode) -> None:
        problem = None if not self.armed else self._mode_problem(mode)
        before = self.mode
        self.commander.request_mode(mode, can_run=problem)
        if mode is FlightMode.TAKEOFF and self.mode is before is mode:
            self._mode_changed(mode, before)  # asked again: a new takeoff altitude

    def _auto_mode(self, mode: FlightMode) -> None:
        """A mode change the navigator asks for (a mission's RTL item)."""
        self.commander.request_mode(mode)

    def _mode_problem(self, mode: FlightMode, arming: bool = False) -> str | None:
        """Why ``mode`` cannot run now (PX4's mode requirements), None if it can."""
        h = self._health
        if mode is FlightMode.OFFBOARD:
            if self._now - self._offboard_sp_s > self.params["COM_OF_LOSS_T"]:
                return (f"no offboard setpoint within COM_OF_LOSS_T "
                        f"({self.params['COM_OF_LOSS_T']:g} s)")
            if not self._setpoint_flyable():
                return "offboard setpoint needs a valid local position"
        if mode in (FlightMode.HOLD, FlightMode.MISSION, FlightMode.RETURN,
                    FlightMode.TAKEOFF, FlightMode.PRECLAND) and not h.local_position_ok:
            return "no valid local position"
        if mode is FlightMode.MISSION:
            problem = self.navigator.mission_problem(landed=self.landed or arming)
            if problem is not None:
                return f"mission rejected: {problem}"
        if mode is FlightMode.RETURN and self.navigator.home is None and not arming:
            return "no home position"
        return None

    def _setpoint_flyable(self) -> bool:
        return self._health.local_position_ok

    def _mode_changed(self, mode: FlightMode, previous: FlightMode) -> None:
        if mode is FlightMode.OFFBOARD and self._est is not None and \
                previous is not FlightMode.OFFBOARD:
            self._offboard_yaw = yaw_from_quat(self._est.q_ned_frd)
        if self._est is not None and (self.armed or mode is not FlightMode.MISSION):
            # (a mission chosen on the ground is set up when the vehicle arms)
            self.navigator.activate(mode, self._nav_estimate(), self.landed)

    def _nav_estimate(self) -> Estimate:
        est = self._require_estimate()
        return Estimate(est.position_ned_m, est.velocity_ned_m_s, yaw_from_quat(est.q_ned_frd))

    def _apply_params(self) -> None:
        p, ctrl = self.params, self.position_ctrl
        ctrl.xy_vel_max_m_s = p["MPC_XY_VEL_MAX"]
        ctrl.z_vel_max_up_m_s = p["MPC_Z_VEL_MAX_UP"]
        ctrl.z_vel_max_down_m_s = p["MPC_Z_VEL_MAX_DN"]
        ctrl.tilt_max_rad = math.radians(p["MPC_TILTMAX_AIR"])

    # ------------------------------------------------------------------------------------
    # The loop
    # ------------------------------------------------------------------------------------

    def observe(self, now_s: float, est: EstimatedState, health: Health) -> None:
        """Take in the current estimate and health without running the controllers."""
        self._now = now_s
        self._est = est
        self._health = health
        self.navigator.set_time(now_s)

    def update_outer(self, now_s: float, dt_s: float, est: EstimatedState, health: Health,
                     height_agl_m: float, battery_fraction: float,
                     surface_velocity_ned_m_s: np.ndarray | None = None) -> None:
        """Position-loop tick: commander, mode logic, position/velocity control.
        ``surface_velocity_ned_m_s``: the velocity of the surface under the vehicle (a moving
        deck), which the land detector judges the vehicle's motion against."""
        self.observe(now_s, est, health)
        self._battery_fraction = battery_fraction
        self._surface_velocity = surface_velocity_ned_m_s
        self._outer(now_s, dt_s, est, height_agl_m)

    def _outer(self, now: float, dt: float, est: EstimatedState, height_agl: float) -> None:
        nav_est = Estimate(est.position_ned_m, est.velocity_ned_m_s, yaw_from_quat(est.q_ned_frd))
        if self.navigator.home is None and self._health.local_position_ok:
            # PX4 sets home when the position first becomes valid, and again at arming
            self.navigator.home = est.position_ned_m.copy()
        gcs_silent = now - self._gcs_heard_s if self._gcs_heard_s != _GCS_NEVER else 0.0
        self.geofence_breach = self.navigator.geofence_breach(est.position_ned_m)
        self.commander.update(Inputs(
            now_s=now, landed=self.landed, health=self._health,
            battery_fraction=self._battery_fraction,
            setpoint_age_s=now - self._offboard_sp_s, setpoint_flyable=self._setpoint_flyable(),
            gcs_silent_s=gcs_silent, geofence_breach=self.geofence_breach,
            has_home=self.navigator.home is not None))
        yaw_now = nav_est.yaw_rad
        if self.armed:
            self.navigator.camera_tick(now, nav_est)
        if not self.armed:
            self._phase = "ground"
            self._landing = False
            self._reset_controllers()
            self._att_sp = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, yaw_now), 0.0, 0.0)
            self.land_detector.update(now, False, self._relative_velocity(est),
                                      est.rates_frd_rad_s, 0.0, False, height_agl)
            return

        if self.mode is FlightMode.OFFBOARD and self._offboard_sp is not None:
            csp = self._offboard_setpoint(dt)
            wants_takeoff = self._offboard_takeoff(csp, est)
            landing = False
        else:
            nav = self.navigator.setpoint(now, dt, nav_est, height_agl, self.landed,
                                          flying=self._phase == "flight")
            csp, wants_takeoff, landing = nav.sp, nav.takeoff, nav.landing
        self._landing = landing
        if self._phase == "ground" and wants_takeoff:
            self._phase = "ramp" if self.cfg.commander.takeoff_ramp_s > 0 else "flight"
            self._ramp_start = now
            self._reset_controllers()
        if self._phase == "ramp":
            progress = (now - self._ramp_start) / self.cfg.commander.takeoff_ramp_s
            if progress >= 1.0:
                self._phase = "flight"
            else:
                # PX4's takeoff ramp: the climb-rate limit starts where thrust would be zero
                start = -GRAVITY_M_S2 / self.cfg.position.z_vel_p
                up = csp.z_vel_max_up_m_s
                if not math.isfinite(up):
                    up = self.position_ctrl.z_vel_max_up_m_s
                csp.z_vel_max_up_m_s = start + (up - start) * progress
                csp.z_vel_max_down_m_s = max(self.position_ctrl.z_vel_max_down_m_s,
                                             -csp.z_vel_max_up_m_s)

        if self._phase == "ground":
            self._reset_controllers()
            self._att_sp = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, yaw_now), 0.0, 0.0)
        else:
            if self._phase == "ramp":
                # as PX4: no integration before the vehicle is flying (on the ground the ramp's
                # velocity error would wind the integrators up)
                self.position_ctrl.reset_integral()
            att = self.position_ctrl.update(dt, est.position_ned_m.tolist(),
                                            est.velocity_ned_m_s.tolist(), csp)
            if landing and self.land_detector.ground_contact:
                # touching down: level out and spool the thrust down so that landing is detected
                self._land_thrust_scale = max(0.0, self._land_thrust_scale
                                              - dt / _LAND_THRUST_RAMP_S)
                self.position_ctrl.reset_xy_integral()
                att = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, csp.yaw_rad),
                                       att.thrust * self._land_thrust_scale, 0.0)
            else:
                self._land_thrust_scale = 1.0
            self._att_sp = att

        descent_commanded = self.position_ctrl.velocity_setpoint[2] > 0.1 and \
            self._phase != "ground"
        self.land_detector.update(now, True, self._relative_velocity(est), est.rates_frd_rad_s,
                                  self._att_sp.thrust, descent_commanded, height_agl)
        if self._phase == "flight" and self.land_detector.landed:
            self._phase = "ground"
            self._event("landed")

    def _relative_velocity(self, est: EstimatedState) -> np.ndarray:
        """The vehicle's velocity over the surface under it."""
        surface = self._surface_velocity
        return est.velocity_ned_m_s if surface is None else est.velocity_ned_m_s - surface

    def _offboard_setpoint(self, dt: float) -> ControlSetpoint:
        pos, vel, yaw, yaw_rate, acc = self._offboard_sp
        if math.isfinite(yaw):  # held, with the yaw rate (if any) as feed-forward, as PX4
            self._offboard_yaw = yaw
            yaw_rate_ff = yaw_rate
        elif math.isfinite(yaw_rate):
            self._offboard_yaw = wrap_pi(self._offboard_yaw + yaw_rate * dt)
            yaw_rate_ff = yaw_rate
        else:
            yaw_rate_ff = NAN
        return ControlSetpoint(pos.tolist(), vel.tolist(), self._offboard_yaw, yaw_rate_ff,
                               acc.tolist())

    @staticmethod
    def _offboard_takeoff(csp: ControlSetpoint, est: EstimatedState) -> bool:
        """An offboard setpoint above the vehicle (or climbing) on the ground: take off."""
        z_sp = csp.position_ned_m[2]
        if math.isfinite(z_sp):
            return z_sp < est.position_ned_m[2] - _TAKEOFF_TRIGGER_M
        vz = csp.velocity_ned_m_s[2]
        return math.isfinite(vz) and vz < -_TAKEOFF_TRIGGER_M_S

    def update_inner(self, dt: float, q: list[float], gyro: list[float]) -> list[float]:
        """Rate-loop tick: attitude and rate control, allocation. ``q`` and ``gyro`` are the
        estimated attitude (w, x, y, z) and body rates (FRD) as plain floats."""
        prev = self._prev_gyro
        if prev is not None:
            if not self._d_alpha:
                rc = 1.0 / (2.0 * math.pi * self.cfg.rates.d_cutoff_hz)
                self._d_alpha = dt / (dt + rc)
            a = self._d_alpha
            acc = self._ang_acc
            for i in range(3):
                acc[i] += a * ((gyro[i] - prev[i]) / dt - acc[i])
        self._prev_gyro = gyro

        n = len(self.airframe.thrust_max_n)
        if not self.armed:
            self.rate_ctrl.reset()
            return [0.0] * n
        if self._phase == "ground":
            self.rate_ctrl.reset()
            return [self._idle_n] * n
        rate_sp = self.attitude_ctrl.update(q, self._att_sp.q_ned_frd,
                                            self._att_sp.yaw_rate_ff_rad_s)
        acc_cmd = self.rate_ctrl.update(dt, gyro, rate_sp, self._ang_acc,
                                        self._sat_pos, self._sat_neg)
        j = self._inertia_l
        torque = (j[0] * acc_cmd[0], j[1] * acc_cmd[1], j[2] * acc_cmd[2])
        alloc = self.allocator.allocate(torque, self._att_sp.thrust * self._thrust_total_max,
                                        self._idle_n)
        self._sat_pos, self._sat_neg = alloc.saturated_positive, alloc.saturated_negative
        return alloc.thrust_n

    # ------------------------------------------------------------------------------------
    # Internals
    # ------------------------------------------------------------------------------------

    def _reset_controllers(self) -> None:
        self.position_ctrl.reset()
        self.rate_ctrl.reset()

    def _require_estimate(self) -> EstimatedState:
        if self._est is None:
            raise CommandRejected("flight stack not initialised")
        return self._est

    def _disarmed(self) -> None:
        self._phase = "ground"
        self._landing = False
        self._reset_controllers()
        self.navigator.disarmed()

    def _event(self, text: str) -> None:
        self.events.append((self._now, text))
