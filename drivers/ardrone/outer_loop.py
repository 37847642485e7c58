"""The position and velocity control the AR.Drone does not have on board: setpoints to
``AT*PCMD`` fractions (:class:`OuterLoop`). Synchronous."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.ardrone.telemetry import GRAVITY_M_S2, HOVER, DroneLimits, clamp_fraction
from drivers.base import (
    ProgressiveCommand,
    Setpoint,
    SetpointFrame,
    VehicleState,
)
from drivers.geometry import (
    constrain_xy,
    euler_from_quat,
    wrap_pi,
)

# --------------------------------------------------------------------------------------------
# The outer loop: setpoints → PCMD
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class OuterLoopGains:
    """The driver's position and velocity control, tuned on the simulated AR.Drone 2.0
    (lockstep: the firmware, its 15 Hz navdata with its latency and the optical-flow
    estimator, this loop at 30 Hz; see the report in :class:`OuterLoop`)."""

    #: horizontal position error → velocity setpoint (1/s), and the speed that part may ask
    #: (a position goal is approached at this speed; a velocity fed forward comes first)
    position_p: float = 1.0
    position_speed_m_s: float = 1.0
    #: the share of the drone's terminal speed at ``euler_angle_max`` (``g·tan(θ)/drag``,
    #: :meth:`~drivers.ardrone.telemetry.DroneLimits.terminal_speed_m_s`) that a velocity
    #: setpoint may ask, the rest of the tilt left for control (12°, the default: 2.9 m/s)
    speed_share: float = 0.8
    #: vertical position error → vertical speed (1/s; limited by control_vz_max)
    position_z_p: float = 1.2
    #: horizontal velocity error → acceleration (1/s), its integral (1/s²) and that
    #: integral's limit (m/s²: what the feed-forward leaves of the drag at the top speed, wind)
    velocity_p: float = 3.0
    velocity_i: float = 0.6
    velocity_i_limit_m_s2: float = 2.0
    #: the velocity fed back is predicted this far ahead of the sample (s), on top of the
    #: sample's age, from the acceleration its attitude gives (``g·tan`` of its tilt): the
    #: lead that the tilt's own lag and the navdata's latency take away
    velocity_lead_s: float = 0.2
    velocity_lead_trim_s: float = 1.0
    #: the drag's share of a steady flight's tilt, as feed-forward: acceleration per m/s of
    #: the velocity setpoint (1/s); the integral supplies the rest of the drag, slowly (a
    #: 2.5 m/s step: 94 % after 6 s, 98 % after 12 s). Compensating the airframe's whole drag
    #: (0.58 /s) holds a step's speed to 1 %, but the follow missions fly worse on it
    #: (lockstep, seeds 2-4, range RMS: follow_ball 0.05-0.06 → 0.10-0.11 m, follow_marker
    #: 0.12-0.16 → 0.26-0.36 m, whether fed forward on the setpoint or cancelled on the
    #: velocity flown): the drag's damping is what the follow controller's camera loop leans on
    drag_feed_forward_per_s: float = 0.1
    #: heading error → yaw rate (1/s)
    yaw_p: float = 2.0
    #: a velocity setpoint below this (each axis) with nothing else asked is a hover
    hover_speed_m_s: float = 0.02
    #: ... and a heading setpoint within this of the heading
    hover_yaw_rad: float = 0.05


def _limited(v: np.ndarray, limit: float) -> np.ndarray:
    norm = float(np.hypot(*v))
    return v * (limit / norm) if norm > limit else v


class OuterLoop:
    """A :class:`~drivers.base.Setpoint` and the newest telemetry to a PCMD, as PX4's position
    controller would do it on a vehicle that takes tilt angles: position P → velocity setpoint
    (at most :attr:`max_speed_m_s`, the velocity asked kept first and the position error's share
    what fits: ``constrainXY``'s limit with PX4's priority reversed, since a follow step's
    velocity is its own closed-loop command and the position part is a position goal's approach,
    already limited to ``position_speed_m_s``) → velocity PI (+ acceleration feed-forward) →
    horizontal acceleration, limited to what ``euler_angle_max`` can give (``g·tan``) with its
    direction kept → tilt ``atan(a/g)`` in the heading frame → fractions of ``euler_angle_max``.
    Vertical: the vertical speed (position P on ``z``, or the setpoint's) as ``gaz = −v_down /
    control_vz_max`` (the drone holds a climb rate on its own). Yaw: P on the heading error
    (with the yaw rate as feed-forward), or the yaw-rate setpoint, as a fraction of
    ``control_yaw``. A setpoint that asks for no motion (a zero velocity, no position, no turn)
    is the drone's own hover (PCMD's progressive bit clear), which holds its velocity at zero
    with its optical flow better than a loop on 15 Hz navdata can; it resets the integral.

    The gains (:class:`OuterLoopGains`) were tuned on the simulated AR.Drone in lockstep
    (:class:`~drivers.sim.simulator.Simulator` with ``sim.firmware=ardrone``: its navdata
    built by the simulated drone's face at 15 Hz with 30 ± 10 ms latency, read back through
    :class:`NavdataTelemetry`, this loop at 30 Hz), from 1 m after the takeoff, mean (max) of
    seeds 1–4. The plant is nearly an integrator (the drag's time constant, 1.7 s, is long)
    behind ~0.3 s of tilt lag and latency; the lead trades rise for damping. With the
    ``ideal`` profile's navigation (the loop's own dynamics, the true speed): a velocity step
    0 → 0.5 m/s reaches 90 % in 1.2 s without overshoot, then 95 % of it after 8 s (the
    integral supplies the drag slowly); 0 → 2.5 m/s 90 % in 2.9 s (3.3 s), 94 % after 8 s,
    98 % after 14 s; a 2 m position step (approached at ``position_speed_m_s``) 90 % in 2.7 s,
    overshoot 0.5 % (2.1 %). With the optical-flow navigation (the ``realistic`` profile, the
    AR.Drone's): the 2 m step on the estimate 90 % in 2.8 s (2.9 s), overshoot 1.7 % (2.1 %),
    within 5 cm after 3.2 s (the true position is off by the estimate's drift). Vertical and
    heading: 1 m up 90 % in 1.7 s, overshoot 0.5 %; a 90° heading step 90 % in 1.1 s, no
    overshoot. (Measured by flying the simulated drone through
    :class:`~drivers.sim.ardrone_driver.SimArdroneDriver`;
    ``tests/integration/test_ardrone_outer_loop.py`` checks the fast cruise.)
    """

    def __init__(self, limits: DroneLimits | None = None,
                 gains: OuterLoopGains | None = None) -> None:
        self.limits = limits or DroneLimits()
        self.gains = gains or OuterLoopGains()
        self._integral = np.zeros(2)
        self._last_s: float | None = None
        self._trim: np.ndarray | None = None

    @property
    def max_speed_m_s(self) -> float:
        """The horizontal speed a velocity setpoint may ask: :attr:`OuterLoopGains.speed_share`
        of the terminal speed at the drone's ``euler_angle_max`` (read from its configuration,
        so a drone set to tilt further may fly faster)."""
        return self.gains.speed_share * self.limits.terminal_speed_m_s()

    def reset(self) -> None:
        """Forget the integral and the last update's time (a new flight, offboard again)."""
        self._integral = np.zeros(2)
        self._last_s = None
        self._trim = None

    def is_hover(self, setpoint: Setpoint, state: VehicleState) -> bool:
        """Does ``setpoint`` ask for no motion (see the class docstring)?"""
        g = self.gains
        if np.isfinite(setpoint.position_ned_m).any():
            return False
        if np.isfinite(setpoint.acceleration_m_s2).any() and \
                np.any(np.abs(np.nan_to_num(setpoint.acceleration_m_s2)) > 1e-3):
            return False
        if np.any(np.abs(setpoint.velocity_m_s) > g.hover_speed_m_s):
            return False
        rate = setpoint.yaw_rate_rad_s
        if math.isfinite(rate) and abs(rate) > 1e-3:
            return False
        yaw = setpoint.yaw_rad
        return not math.isfinite(yaw) or abs(wrap_pi(yaw - state.yaw_rad)) <= g.hover_yaw_rad

    def predicted(self, state: VehicleState, now_s: float,
                  dt_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The position and velocity ``state`` predicts for ``now_s`` plus the lead: the
        horizontal velocity advanced by the acceleration its tilt gives (``g·tan``) less that
        acceleration's slow part (low-passed over ``velocity_lead_trim_s``: what a steady
        flight's drag and the attitude's own bias take), the position by the velocity for
        the sample's age (vertical: as sampled). ``dt_s`` moves the low-pass on."""
        g = self.gains
        age = min(0.5, max(0.0, now_s - state.time_s))
        roll, pitch, yaw = euler_from_quat(state.attitude_q)
        a_forward = -GRAVITY_M_S2 * math.tan(pitch)
        a_right = GRAVITY_M_S2 * math.tan(roll) / max(0.5, math.cos(pitch))
        c, s = math.cos(yaw), math.sin(yaw)
        accel = np.array([c * a_forward - s * a_right, s * a_forward + c * a_right])
        if self._trim is None:
            self._trim = accel
        else:
            self._trim = self._trim + (accel - self._trim) * min(
                1.0, dt_s / g.velocity_lead_trim_s)
        velocity = np.array(state.velocity_ned_m_s, dtype=float)
        position = np.array(state.position_ned_m, dtype=float)
        position[:2] += velocity[:2] * age
        velocity[:2] += (accel - self._trim) * (age + g.velocity_lead_s)
        return position, velocity

    def update(self, setpoint: Setpoint, state: VehicleState, now_s: float) -> ProgressiveCommand:
        """The PCMD for ``setpoint`` given ``state``, at ``now_s`` (the integral's time)."""
        g, lim = self.gains, self.limits
        dt = 0.0 if self._last_s is None else min(0.1, max(0.0, now_s - self._last_s))
        self._last_s = now_s
        if self.is_hover(setpoint, state):
            self._integral = np.zeros(2)
            return HOVER
        yaw = state.yaw_rad
        c, s = math.cos(yaw), math.sin(yaw)
        sp_pos = setpoint.position_ned_m
        sp_vel = np.array(setpoint.velocity_m_s, dtype=float)
        if setpoint.frame is SetpointFrame.BODY_FRD:  # heading frame → NED
            forward, right = sp_vel[0], sp_vel[1]
            sp_vel[0], sp_vel[1] = c * forward - s * right, s * forward + c * right
        position, velocity = self.predicted(state, now_s, dt)
        # horizontal: velocity setpoint, then acceleration
        feed = np.nan_to_num(sp_vel[:2])
        toward = np.array([g.position_p * (sp_pos[i] - position[i])
                           if math.isfinite(sp_pos[i]) else 0.0 for i in (0, 1)])
        # (the velocity asked first: the reverse of PX4's priority, see the class docstring)
        v_sp = np.array(constrain_xy(feed, _limited(toward, g.position_speed_m_s),
                                     self.max_speed_m_s))
        error = v_sp - velocity[:2]
        feed_acc = np.nan_to_num(np.asarray(setpoint.acceleration_m_s2[:2], dtype=float))
        accel = g.velocity_p * error + self._integral + feed_acc + g.drag_feed_forward_per_s * v_sp
        a_max = lim.acceleration_m_s2()
        norm = float(np.hypot(*accel))
        if norm > a_max:
            accel *= a_max / norm
        else:  # (no integration while saturated: anti-windup)
            self._integral = _limited(self._integral + g.velocity_i * error * dt,
                                      g.velocity_i_limit_m_s2)
        a_forward = c * accel[0] + s * accel[1]
        a_right = -s * accel[0] + c * accel[1]
        pitch_rad = -math.atan(a_forward / GRAVITY_M_S2)
        roll_rad = math.atan(a_right * math.cos(pitch_rad) / GRAVITY_M_S2)
        # vertical
        if math.isfinite(sp_pos[2]):
            v_down = g.position_z_p * (sp_pos[2] - position[2]) + (
                sp_vel[2] if math.isfinite(sp_vel[2]) else 0.0)
        else:
            v_down = sp_vel[2]
        gaz = clamp_fraction(-v_down / lim.control_vz_max_m_s)
        # yaw
        rate = setpoint.yaw_rate_rad_s
        if math.isfinite(setpoint.yaw_rad):  # (the heading predicted for now, as above)
            age = min(0.5, max(0.0, now_s - state.time_s))
            heading = yaw + float(state.angular_velocity_frd_rad_s[2]) * age
            rate = g.yaw_p * wrap_pi(setpoint.yaw_rad - heading) + (
                rate if math.isfinite(rate) else 0.0)
        elif not math.isfinite(rate):
            rate = 0.0
        return ProgressiveCommand(clamp_fraction(roll_rad / lim.euler_angle_max_rad),
                    clamp_fraction(pitch_rad / lim.euler_angle_max_rad), gaz,
                    clamp_fraction(rate / lim.control_yaw_rad_s), hover=False)
