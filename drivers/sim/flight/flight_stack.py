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

from drivers.base import Battery, FlightMode, Health, LandedState, Setpoint
from drivers.geo import GlobalOrigin
from drivers.geometry import yaw_from_quat
from drivers.mission import MissionItem, MissionType
from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.commander import Commander, CommandRejected, Inputs
from drivers.sim.flight.mode_requirements import mode_problem
from drivers.sim.flight.navigator import Estimate, Navigator
from drivers.sim.flight.offboard import OffboardInput
from drivers.sim.flight.params import Parameters
from drivers.sim.flight.position_control import (
    GRAVITY_M_S2,
)
from drivers.sim.flight.position_loop import PositionLoop
from drivers.sim.flight.range_gate import RangeGate
from drivers.sim.flight.rate_loop import RateLoop

__all__ = ["Airframe", "CommandRejected", "EstimatedState", "FlightStack"]

NAN = float("nan")
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
                 params: Parameters | None = None, origin: GlobalOrigin | None = None) -> None:
        self.cfg = cfg
        self.airframe = airframe
        self.params = params if params is not None else Parameters()
        self.origin = origin if origin is not None else GlobalOrigin(47.397742, 8.545594, 488.0)
        hover = cfg.position.hover_thrust or airframe.hover_thrust
        self.hover_thrust = hover
        #: (time_s, text) of mode changes and failsafes, drained by the simulator.
        self.events: deque[tuple[float, str]] = deque(maxlen=256)
        self.rate_loop = RateLoop(cfg, airframe, motor_idle_fraction)
        self.position_loop = PositionLoop(cfg, hover, self.rate_loop, self._event)
        self.land_detector = self.position_loop.land_detector
        self.range_gate = RangeGate()  # the rangefinder as the estimator takes it
        self.offboard = OffboardInput()
        self.commander = Commander(self.params, self._event)
        self.navigator = Navigator(self.params, self.origin, request_mode=self._auto_mode,
                                   complete=self.commander.complete, event=self._event)
        self.nav_events = self.navigator.events  # missions' and the camera's, drained by the sim
        self.commander.on_mode_change = self._mode_changed
        self.commander.on_disarm = self._disarmed
        self.params.on_change(lambda name, value: self._apply_params())
        self._apply_params()
        self._now = 0.0
        self._est: EstimatedState | None = None
        self.health = Health(local_position_ok=False)  # as last observed
        self._battery_fraction, self._gcs_heard_s = 1.0, _GCS_NEVER
        self._surface_velocity: np.ndarray | None = None
        #: why the vehicle is outside its geofence now (None: inside, or no fence)
        self.geofence_breach: str | None = None

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
        if self.mode is FlightMode.LAND or self.position_loop.landing:
            return LandedState.LANDING
        return LandedState.IN_AIR

    # ------------------------------------------------------------------------------------
    # Commands (MAVLink COMMAND_LONG equivalents). Raise CommandRejected to deny.
    # ------------------------------------------------------------------------------------

    def arm(self) -> None:
        if self.armed:
            return
        problem = self.commander.arming_problem(self.health, self.landed,
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
        if not self.health.local_position_ok:
            raise CommandRejected("no valid local position")
        self.navigator.takeoff_altitude_override_m = altitude_m
        self._user_mode(FlightMode.TAKEOFF)

    def land(self) -> None:
        self.require_estimate()
        self._user_mode(FlightMode.LAND)

    def hold(self) -> None:
        self._user_mode(FlightMode.HOLD)

    def precision_land(self) -> None:
        """AUTO.PRECLAND: land on the reported landing target (:mod:`precland`)."""
        self.require_estimate()
        if not self.armed or self.landed:
            raise CommandRejected("precision landing needs the vehicle in the air")
        self._user_mode(FlightMode.PRECLAND)

    def landing_target(self, position_ned_m: Sequence[float], time_s: float) -> None:
        """LANDING_TARGET (MAV_FRAME_LOCAL_NED) for precision landing."""
        self.navigator.precland.landing_target(time_s, position_ned_m)

    def start_offboard(self) -> None:
        if self.mode is not FlightMode.OFFBOARD:
            self.offboard.yaw_rad = yaw_from_quat(self.require_estimate().q_ned_frd)
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

    def set_mission(self, items: Sequence[MissionItem],
                    mission_type: int = MissionType.MISSION) -> None:
        self.navigator.set_items(items, mission_type)

    def set_mission_current(self, seq: int) -> None:
        try:
            self.navigator.set_current(seq)
        except ValueError as exc:
            raise CommandRejected(str(exc)) from None

    def gcs_heartbeat(self) -> None:
        """A ground station's HEARTBEAT arrived (for the data-link loss failsafe)."""
        self._gcs_heard_s = self._now

    def push_setpoint(self, sp: Setpoint, now_s: float) -> None:
        """An offboard setpoint arrives at ``now_s``."""
        self._now = now_s
        yaw = yaw_from_quat(self._est.q_ned_frd) if self._est is not None else 0.0
        self.offboard.push(sp, now_s, yaw)

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
        return mode_problem(mode, health=self.health, navigator=self.navigator,
                            setpoint_age_s=self._now - self.offboard.received_s,
                            offboard_loss_s=self.params["COM_OF_LOSS_T"], landed=self.landed,
                            arming=arming)

    def _mode_changed(self, mode: FlightMode, previous: FlightMode) -> None:
        if mode is FlightMode.OFFBOARD and self._est is not None and \
                previous is not FlightMode.OFFBOARD:
            self.offboard.yaw_rad = yaw_from_quat(self._est.q_ned_frd)
        if self._est is not None and (self.armed or mode is not FlightMode.MISSION):
            # (a mission chosen on the ground is set up when the vehicle arms)
            self.navigator.activate(mode, self._nav_estimate(), self.landed)

    def _nav_estimate(self) -> Estimate:
        est = self.require_estimate()
        return Estimate(est.position_ned_m, est.velocity_ned_m_s, yaw_from_quat(est.q_ned_frd))

    def _apply_params(self) -> None:
        p, ctrl = self.params, self.position_loop.position_ctrl
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
        self.health = health
        self.navigator.set_time(now_s)

    def update_outer(self, now_s: float, dt_s: float, est: EstimatedState, health: Health,
                     height_agl_m: float, battery: Battery,
                     surface_velocity_ned_m_s: np.ndarray | None = None) -> None:
        """Position-loop tick: commander, mode logic, position/velocity control, on the range
        gated (:mod:`~drivers.sim.flight.range_gate`). ``surface_velocity_ned_m_s``: the
        surface's under the vehicle (a moving deck), for the land detector."""
        self.observe(now_s, est, health)
        self._battery_fraction = battery.remaining_fraction
        self._surface_velocity = surface_velocity_ned_m_s
        self._outer(now_s, dt_s, est, self.range_gate.height(now_s, height_agl_m, est,
                                                             self.navigator.home))

    def _outer(self, now: float, dt: float, est: EstimatedState, height_agl: float) -> None:
        nav_est = Estimate(est.position_ned_m, est.velocity_ned_m_s, yaw_from_quat(est.q_ned_frd))
        if self.navigator.home is None and self.health.local_position_ok:
            # PX4 sets home when the position first becomes valid, and again at arming
            self.navigator.home = est.position_ned_m.copy()
        gcs_silent = now - self._gcs_heard_s if self._gcs_heard_s != _GCS_NEVER else 0.0
        self.geofence_breach = self.navigator.geofence_breach(est.position_ned_m)
        self.commander.update(Inputs(
            now_s=now, landed=self.landed, health=self.health,
            battery_fraction=self._battery_fraction,
            setpoint_age_s=now - self.offboard.received_s,
            setpoint_flyable=self.health.local_position_ok, gcs_silent_s=gcs_silent,
            geofence_breach=self.geofence_breach, has_home=self.navigator.home is not None))
        yaw_now = nav_est.yaw_rad
        if self.armed:
            self.navigator.camera_tick(now, nav_est)
        loop = self.position_loop
        if not self.armed:
            loop.disarmed(now, est, yaw_now, self._relative_velocity(est), height_agl)
            return
        if self.mode is FlightMode.OFFBOARD and self.offboard.setpoint is not None:
            csp = self.offboard.control_setpoint(dt)
            wants_takeoff = self.offboard.wants_takeoff(csp, est.position_ned_m)
            landing = False
        else:
            nav = self.navigator.setpoint(now, dt, nav_est, height_agl, self.landed,
                                          flying=loop.phase == "flight")
            csp, wants_takeoff, landing = nav.sp, nav.takeoff, nav.landing
        loop.update(now, dt, est, yaw_now, csp, wants_takeoff, landing,
                    self._relative_velocity(est), height_agl)

    def _relative_velocity(self, est: EstimatedState) -> np.ndarray:
        """The vehicle's velocity over the surface under it."""
        surface = self._surface_velocity
        return est.velocity_ned_m_s if surface is None else est.velocity_ned_m_s - surface

    def update_inner(self, dt: float, q: list[float], gyro: list[float]) -> list[float]:
        """Rate-loop tick (:class:`RateLoop`): the rotor thrusts. ``q`` and ``gyro`` are the
        estimated attitude (w, x, y, z) and body rates (FRD) as plain floats."""
        return self.rate_loop.update(dt, q, gyro, self.position_loop.att_sp, armed=self.armed,
                                     on_ground=self.position_loop.phase == "ground")

    # ------------------------------------------------------------------------------------
    # Internals
    # ------------------------------------------------------------------------------------

    def require_estimate(self) -> EstimatedState:
        if self._est is None:
            raise CommandRejected("flight stack not initialised")
        return self._est

    def _disarmed(self) -> None:
        self.position_loop.phase = "ground"
        self.position_loop.landing = False
        self.position_loop.reset_controllers()
        self.navigator.disarmed()

    def _event(self, text: str) -> None:
        self.events.append((self._now, text))
