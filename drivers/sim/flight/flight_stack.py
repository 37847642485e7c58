"""The simulated vehicle's autopilot: a PX4-equivalent flight stack.

Commander (arming and its checks, modes, failsafes, auto-disarm), the navigator's TAKEOFF / HOLD /
LAND behaviour, OFFBOARD setpoint handling, and the control cascade
position P → velocity PID → attitude P → rate PID → allocation. It knows nothing of MuJoCo: the
simulator calls :meth:`FlightStack.update_outer` at the position-loop rate and
:meth:`FlightStack.update_inner` at the rate-loop rate with the estimator's output (NED/FRD), and
applies the rotor thrusts that the latter returns.

Semantics follow PX4 (v1.14+) as MAVSDK sees it; where this differs from PX4 it says so here:

* OFFBOARD is accepted only while setpoints stream (more than ``offboard_min_rate_hz`` over the
  last second, the newest younger than ``offboard_loss_timeout_s``). It is allowed disarmed or on
  the ground; a setpoint above the vehicle then takes off, as in PX4.
* Setpoint loss for ``offboard_loss_timeout_s`` → HOLD (failsafe). If setpoints return within
  ``offboard_loss_land_s`` the vehicle goes back to OFFBOARD, otherwise it LANDs. (PX4's
  COM_OBL_RC_ACT offers hold *or* land; this sequence is what the project specifies.)
* TAKEOFF climbs to ``takeoff_altitude_m`` above home (the arming position), then HOLDs there.
* LAND descends, detects touchdown, and disarms after ``disarm_after_land_s``.
* Low-level differences: thrust is commanded in newtons directly (an ideal thrust curve), rate
  gains act on angular acceleration, and the hover thrust is known (a converged estimator).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from drivers.base import FlightMode, Health, LandedState, Setpoint, SetpointFrame
from drivers.geometry import rot_z, wrap_pi, yaw_from_quat
from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.allocation import ControlAllocator
from drivers.sim.flight.attitude_control import AttitudeController
from drivers.sim.flight.land_detector import LandDetector
from drivers.sim.flight.position_control import (
    GRAVITY_M_S2,
    LEVEL_DOWN,
    AttitudeSetpoint,
    ControlSetpoint,
    PositionController,
    body_z_to_attitude,
)
from drivers.sim.flight.rate_control import RateController

NAN = float("nan")
_TAKEOFF_TRIGGER_M = 0.2  # a setpoint this far above the vehicle means "take off"
_TAKEOFF_TRIGGER_M_S = 0.3
_TAKEOFF_DONE_M = 0.1  # TAKEOFF hands over to HOLD this close to its altitude (profile done)
_LAND_THRUST_RAMP_S = 0.5  # thrust ramps to zero this fast once the ground is felt


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


class CommandRejected(Exception):
    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class FlightStack:
    def __init__(self, cfg: FlightStackConfig, airframe: Airframe,
                 motor_idle_fraction: float, battery_critical_fraction: float = 0.0) -> None:
        self.cfg = cfg
        self.airframe = airframe
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

        # commander state
        self.armed = False
        self.mode = FlightMode.HOLD
        self.failsafe: str | None = None
        self.takeoff_altitude_m = cfg.commander.takeoff_altitude_m
        #: (time_s, text) of mode changes and failsafes, drained by the simulator.
        self.events: deque[tuple[float, str]] = deque(maxlen=256)
        self._now = 0.0
        self._est: EstimatedState | None = None
        self._health = Health(local_position_ok=False)
        self._battery_fraction = 1.0
        self._battery_critical = battery_critical_fraction
        self._home = np.zeros(3)
        self._armed_at = 0.0
        self._ever_airborne = False
        self._landed_since: float | None = None
        self._loss_since = 0.0

        # mode state
        self._hold_pos = np.zeros(3)
        self._hold_yaw = 0.0
        self._takeoff_target = np.zeros(3)
        self._takeoff_profile: _Profile | None = None
        self._land_xy = np.zeros(2)
        self._offboard_sp: tuple[np.ndarray, np.ndarray, float, float] | None = None
        self._sp_times: deque[float] = deque(maxlen=512)
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
    def landed(self) -> bool:
        return self.land_detector.landed

    @property
    def landed_state(self) -> LandedState:
        if self.land_detector.landed:
            return LandedState.ON_GROUND
        if self.mode is FlightMode.TAKEOFF:
            return LandedState.TAKING_OFF
        if self.mode is FlightMode.LAND:
            return LandedState.LANDING
        return LandedState.IN_AIR

    # ------------------------------------------------------------------------------------
    # Commands (MAVLink COMMAND_LONG equivalents). Raise CommandRejected to deny.
    # ------------------------------------------------------------------------------------

    def arm(self) -> None:
        if self.armed:
            return
        if not self._health.armable:
            raise CommandRejected("preflight checks failed: " + ", ".join(self._health.problems()))
        if not self.landed:
            raise CommandRejected("not landed")
        self.armed = True
        self._armed_at = self._now
        self._ever_airborne = False
        self._landed_since = self._now
        self._home = self._est.position_ned_m.copy() if self._est is not None else np.zeros(3)
        if self.mode is not FlightMode.OFFBOARD:
            self._enter_hold()
        self._event("armed")

    def disarm(self, force: bool = False) -> None:
        if not self.armed:
            return
        if not self.landed and not force:
            raise CommandRejected("vehicle is in the air (force to stop the motors)")
        self._disarm("disarmed" + (" (forced)" if force else ""))

    def takeoff(self) -> None:
        if not self.armed:
            raise CommandRejected("not armed")
        if not self._health.local_position_ok:
            raise CommandRejected("no valid local position")
        est = self._require_estimate()
        target = est.position_ned_m.copy()
        target[2] = min(target[2], self._home[2] - self.takeoff_altitude_m)
        self._takeoff_target = target
        self._takeoff_profile = None  # starts from the vehicle's state once it flies
        self._hold_yaw = yaw_from_quat(est.q_ned_frd)
        self._set_mode(FlightMode.TAKEOFF)

    def land(self) -> None:
        est = self._require_estimate()
        self._land_xy = self._stopping_point(est)[:2]
        self._hold_yaw = yaw_from_quat(est.q_ned_frd)
        self._set_mode(FlightMode.LAND)

    def hold(self) -> None:
        self._enter_hold()
        self._set_mode(FlightMode.HOLD)

    def start_offboard(self) -> None:
        if not self._offboard_streaming():
            raise CommandRejected(
                f"no offboard setpoints streaming (need more than "
                f"{self.cfg.commander.offboard_min_rate_hz:g} Hz)"
            )
        if not self._health.local_position_ok:
            raise CommandRejected("no valid local position")
        if self.mode is not FlightMode.OFFBOARD:
            self._offboard_yaw = yaw_from_quat(self._require_estimate().q_ned_frd)
        self._set_mode(FlightMode.OFFBOARD)

    def stop_offboard(self) -> None:
        self.hold()

    def push_setpoint(self, sp: Setpoint, now_s: float) -> None:
        """An offboard setpoint arrives at ``now_s``."""
        self._now = now_s
        vel = np.array(sp.velocity_m_s)
        if sp.frame is SetpointFrame.BODY_FRD:
            # PX4 rotates body-frame velocity by the heading at reception
            yaw = yaw_from_quat(self._est.q_ned_frd) if self._est is not None else 0.0
            vel = rot_z(yaw) @ vel
        self._offboard_sp = (np.array(sp.position_ned_m), vel, sp.yaw_rad, sp.yaw_rate_rad_s)
        self._sp_times.append(self._now)

    # ------------------------------------------------------------------------------------
    # The loop
    # ------------------------------------------------------------------------------------

    def observe(self, now_s: float, est: EstimatedState, health: Health) -> None:
        """Take in the current estimate and health without running the controllers."""
        self._now = now_s
        self._est = est
        self._health = health

    def update_outer(self, now_s: float, dt_s: float, est: EstimatedState, health: Health,
                     height_agl_m: float, battery_fraction: float) -> None:
        """Position-loop tick: commander, mode logic, position/velocity control."""
        self.observe(now_s, est, health)
        self._battery_fraction = battery_fraction
        self._outer(now_s, dt_s, est, height_agl_m)

    def _outer(self, now: float, dt: float, est: EstimatedState, height_agl: float) -> None:
        self._commander(now, est)
        yaw_now = yaw_from_quat(est.q_ned_frd)
        if not self.armed:
            self._phase = "ground"
            self._reset_controllers()
            self._att_sp = AttitudeSetpoint(body_z_to_attitude(LEVEL_DOWN, yaw_now), 0.0, 0.0)
            self.land_detector.update(now, False, est.velocity_ned_m_s, est.rates_frd_rad_s,
                                      0.0, False, height_agl)
            return

        csp = self._mode_setpoint(now, dt, est, height_agl)
        if self._phase == "ground" and self._wants_takeoff(csp, est):
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
                    up = self.cfg.position.z_vel_max_up_m_s
                csp.z_vel_max_up_m_s = start + (up - start) * progress
                csp.z_vel_max_down_m_s = max(self.cfg.position.z_vel_max_down_m_s,
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
            if self.mode is FlightMode.LAND and self.land_detector.ground_contact:
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
        self.land_detector.update(now, True, est.velocity_ned_m_s, est.rates_frd_rad_s,
                                  self._att_sp.thrust, descent_commanded, height_agl)
        if self._phase == "flight" and self.land_detector.landed:
            self._phase = "ground"
            self._event("landed")

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
    # Commander internals
    # ------------------------------------------------------------------------------------

    def _commander(self, now: float, est: EstimatedState) -> None:
        c = self.cfg.commander
        if self.armed:
            if self.landed:
                if self._landed_since is None:
                    self._landed_since = now
                if self._ever_airborne and now - self._landed_since >= c.disarm_after_land_s:
                    self._disarm("auto-disarmed after landing")
                elif not self._ever_airborne and now - self._armed_at >= c.disarm_preflight_s:
                    self._disarm("auto-disarmed: no takeoff")
            else:
                self._landed_since = None
                self._ever_airborne = True
        if not self.armed:
            return

        in_air = not self.landed
        if in_air and not self._health.local_position_ok and self.mode is not FlightMode.LAND:
            self._failsafe_land("local position lost")
        elif (in_air and self._battery_fraction <= self._battery_critical
              and self.mode is not FlightMode.LAND):
            self._failsafe_land("battery critical")

        if self.mode is FlightMode.OFFBOARD:
            last = self._sp_times[-1] if self._sp_times else -math.inf
            if now - last > c.offboard_loss_timeout_s:
                self._enter_hold()
                self._set_mode(FlightMode.HOLD, failsafe="offboard setpoints lost")
                self._loss_since = now
        elif self.failsafe == "offboard setpoints lost" and self.mode is FlightMode.HOLD:
            if self._offboard_streaming():
                self._set_mode(FlightMode.OFFBOARD)
                self._event("offboard setpoints back: resuming OFFBOARD")
            elif now - self._loss_since >= c.offboard_loss_land_s:
                self._failsafe_land("offboard setpoints lost")

    def _failsafe_land(self, reason: str) -> None:
        est = self._require_estimate()
        self._land_xy = self._stopping_point(est)[:2]
        self._hold_yaw = yaw_from_quat(est.q_ned_frd)
        self._set_mode(FlightMode.LAND, failsafe=reason)

    def _offboard_streaming(self) -> bool:
        c = self.cfg.commander
        if not self._sp_times or self._now - self._sp_times[-1] > c.offboard_loss_timeout_s:
            return False
        recent = sum(1 for t in self._sp_times if t > self._now - 1.0)
        return recent > c.offboard_min_rate_hz

    def _mode_setpoint(self, now: float, dt: float, est: EstimatedState,
                       height_agl: float) -> ControlSetpoint:
        p = self.cfg.position
        c = self.cfg.commander
        if self.mode is FlightMode.TAKEOFF:
            target = self._takeoff_target
            if self._phase != "flight":
                # on the ground / ramping up: aim straight at the target, the ramp limits the climb
                return ControlSetpoint(target.tolist(), [0.0, 0.0, 0.0], self._hold_yaw,
                                       xy_vel_max_m_s=p.xy_cruise_m_s,
                                       z_vel_max_up_m_s=c.takeoff_speed_m_s)
            if self._takeoff_profile is None:
                self._takeoff_profile = _Profile(float(est.position_ned_m[2]),
                                                 float(est.velocity_ned_m_s[2]))
            prof = self._takeoff_profile
            prof.step(float(target[2]), c.takeoff_speed_m_s, c.takeoff_accel_m_s2, dt)
            if prof.done and abs(est.position_ned_m[2] - target[2]) < _TAKEOFF_DONE_M:
                self._hold_pos = target.copy()
                self._set_mode(FlightMode.HOLD)
            else:
                return ControlSetpoint([target[0], target[1], prof.position],
                                       [0.0, 0.0, prof.velocity], self._hold_yaw,
                                       acceleration_ned_m_s2=[0.0, 0.0, prof.acceleration],
                                       xy_vel_max_m_s=p.xy_cruise_m_s)
        if self.mode is FlightMode.LAND:
            height = height_agl if math.isfinite(height_agl) \
                else self._home[2] - est.position_ned_m[2]
            slow = c.land_slow_altitude_m
            blend = min(max((height - slow) / slow, 0.0), 1.0)
            speed = c.land_speed_m_s + blend * (c.descent_speed_m_s - c.land_speed_m_s)
            return ControlSetpoint([float(self._land_xy[0]), float(self._land_xy[1]), NAN],
                                   [NAN, NAN, speed], self._hold_yaw,
                                   xy_vel_max_m_s=p.xy_cruise_m_s,
                                   z_vel_max_down_m_s=max(speed, p.z_vel_max_down_m_s))
        if self.mode is FlightMode.OFFBOARD and self._offboard_sp is not None:
            pos, vel, yaw, yaw_rate = self._offboard_sp
            if math.isfinite(yaw):
                self._offboard_yaw = yaw
                yaw_rate_ff = NAN
            elif math.isfinite(yaw_rate):
                self._offboard_yaw = wrap_pi(self._offboard_yaw + yaw_rate * dt)
                yaw_rate_ff = yaw_rate
            else:
                yaw_rate_ff = NAN
            return ControlSetpoint(pos.tolist(), vel.tolist(), self._offboard_yaw, yaw_rate_ff)
        # HOLD (and any mode the simulator does not fly)
        return ControlSetpoint(self._hold_pos.tolist(), [NAN, NAN, NAN], self._hold_yaw,
                               xy_vel_max_m_s=p.xy_cruise_m_s)

    def _wants_takeoff(self, csp: ControlSetpoint, est: EstimatedState) -> bool:
        if self.mode is FlightMode.TAKEOFF:
            return True
        if self.mode is not FlightMode.OFFBOARD:
            return False
        z_sp = csp.position_ned_m[2]
        if math.isfinite(z_sp):
            return z_sp < est.position_ned_m[2] - _TAKEOFF_TRIGGER_M
        vz = csp.velocity_ned_m_s[2]
        return math.isfinite(vz) and vz < -_TAKEOFF_TRIGGER_M_S

    def _stopping_point(self, est: EstimatedState) -> np.ndarray:
        """Where the vehicle comes to rest braking at MPC_ACC_HOR (PX4's loiter brake)."""
        vel = est.velocity_ned_m_s
        pos = est.position_ned_m.copy()
        if self.landed:
            return pos
        a = self.cfg.position.brake_accel_m_s2
        speed = float(np.linalg.norm(vel[:2]))
        pos[:2] += vel[:2] * speed / (2.0 * a)
        return pos

    def _enter_hold(self) -> None:
        est = self._est
        if est is None:
            return
        self._hold_pos = self._stopping_point(est)
        self._hold_yaw = yaw_from_quat(est.q_ned_frd)

    def _set_mode(self, mode: FlightMode, failsafe: str | None = None) -> None:
        if failsafe is not None:
            self._event(f"failsafe: {failsafe} → {mode.value}")
        elif mode is not self.mode:
            self._event(f"mode {self.mode.value} → {mode.value}")
        self.failsafe = failsafe
        self.mode = mode

    def _disarm(self, why: str) -> None:
        self.armed = False
        self._phase = "ground"
        self._reset_controllers()
        self._event(why)

    def _reset_controllers(self) -> None:
        self.position_ctrl.reset()
        self.rate_ctrl.reset()

    def _require_estimate(self) -> EstimatedState:
        if self._est is None:
            raise CommandRejected("flight stack not initialised")
        return self._est

    def _event(self, text: str) -> None:
        self.events.append((self._now, text))


class _Profile:
    """1-D trapezoidal setpoint profile (velocity- and acceleration-limited), the auto modes'
    trajectory smoothing in its simplest form."""

    def __init__(self, position: float, velocity: float) -> None:
        self.position = position
        self.velocity = velocity
        self.acceleration = 0.0
        self.done = False

    def step(self, target: float, v_max: float, a_max: float, dt: float) -> None:
        err = target - self.position
        v_des = math.copysign(min(v_max, math.sqrt(2.0 * a_max * abs(err))), err)
        dv = min(max(v_des - self.velocity, -a_max * dt), a_max * dt)
        self.acceleration = dv / dt
        self.velocity += dv
        self.position += self.velocity * dt
        if abs(target - self.position) < 0.005 and abs(self.velocity) < 0.1:
            self.position, self.velocity, self.acceleration = target, 0.0, 0.0
            self.done = True
