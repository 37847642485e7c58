"""The Parrot AR.Drone 2.0 as the seed reports (001, 002, 003) commanded it, for their baselines.

**Commands.** The seeds publish a ``geometry_msgs/Twist`` on ``cmd_vel`` to ardrone_autonomy
(or its simulator), and each component is a *fraction* in [−1, 1] of one of the drone's
configured limits, not a velocity (ardrone_autonomy ``docs/commands.rst``; seed 001 found it the
hard way: "the /cmd_vel topic is used to control the drone tilt along the X and Y axes, but
velocity along the Z axis and a relative rotation rate for the yaw"):

* ``linear.x`` / ``linear.y``: pitch / roll as a fraction of ``euler_angle_max`` (+x forward,
  +y left);
* ``linear.z``: climb rate as a fraction of ``control_vz_max`` (+ up);
* ``angular.z``: yaw rate as a fraction of ``control_yaw``, + turning left (counter-clockwise
  seen from above): the driver hands ``-angular.z`` to the SDK, whose + is clockwise
  (``src/teleop_twist.cpp``; the docs' own "+angular.z: turn right" has it the wrong way round,
  and seed 001's yaw mode, which turns toward a ball on the left with a positive value, works);
* the driver clamps each to ±1 (``teleop_twist.cpp``);
* all six components zero: the firmware's *auto-hover* (it holds its position on the vertical
  camera's optical flow); ``angular.x`` / ``angular.y`` non-zero disable it, so that zero means
  "level, no command" (``docs/commands.rst``, "Hover Modes").

**Limits.** Unless a launch file sets them, ardrone_autonomy leaves the drone's own defaults
(``docs/parameters.rst``), which the SDK defines in ``ARDroneLib/Soft/Common/config_keys.h``:
indoor ``euler_angle_max`` 12° (0.21 rad; outdoor 20°), ``control_vz_max`` 700 mm/s (outdoor
1000), ``control_yaw`` 100°/s (1.75 rad/s; outdoor 200°/s). The seeds set none of them and fly
indoors or in Gazebo, so the indoor defaults are used. (Seed 001 writes that angular.z is "the
proportion of 95 degrees" per second; the documented default is 100°/s.)

**Dynamics.** A tilt θ with the thrust holding the height gives a horizontal acceleration
g·tan θ; the airframe's drag, linear in speed, bounds the speed. The drag figure is the one
tum_ardrone (Engel, Sturm & Cremers, "Camera-based navigation of a low-cost quadrocopter",
IROS 2012) identified for the AR.Drone from flight data and predicts with in its EKF
(``src/stateestimation/DroneKalmanFilter.cpp``): v̇ = c1·(c2·sin θ − v) with c1 = 0.58 s⁻¹,
c2 = 17.8 m/s — c1·c2 = 10.3 m/s² ≈ g, i.e. g·sin θ (≈ g·tan θ at these angles) less a linear
drag of 0.58 s⁻¹ × v. So the velocity settles with a time constant of 1/0.58 = 1.7 s, and full
tilt (12°) reaches g·tan 12°/0.58 = 3.6 m/s (at 20°, outdoors: 6.2 m/s; Parrot quotes 5 m/s).
The attitude's own response (tum_ardrone's c3 = 10 s⁻¹, 0.1 s) and the vertical loop's (c7 =
1.4 s⁻¹) are left to our vehicle's velocity loop, which lags its setpoint by about as much.
The AR.Drone firmware's auto-hover is not documented beyond "holds its position": it is
modelled as braking at the largest tilt it may use (``euler_angle_max``) until stopped, the
most it could do. Wind is not modelled: our vehicle rejects it (it tracks a velocity).

**Our vehicle.** A PX4 vehicle takes offboard velocity setpoints, so :class:`ArDroneTiltModel`
integrates the commanded tilt into the velocity the AR.Drone would have, and hands our vehicle
that velocity (with the acceleration as feed-forward), the climb rate and the yaw rate at every
control tick. Each setpoint also carries the command itself (``Setpoint.progressive``, as
ardrone_autonomy hands it to the SDK): an AR.Drone (``--driver ardrone``) flies that, so a seed
rule flies it in its own units, exactly. Synchronous; owned by a seed rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.ardrone.telemetry import GRAVITY_M_S2
from drivers.ardrone.telemetry import DroneLimits as ArDroneLimits
from drivers.base import ProgressiveCommand, Setpoint

__all__ = ["GRAVITY_M_S2", "ArDroneLimits", "ArDroneTiltModel", "Twist"]



@dataclass(frozen=True, slots=True)
class Twist:
    """An ardrone_autonomy ``cmd_vel`` message: fractions of the drone's limits (see the module
    docstring for the axes and signs)."""

    linear_x: float = 0.0  # pitch: + forward
    linear_y: float = 0.0  # roll: + left
    linear_z: float = 0.0  # climb: + up
    angular_z: float = 0.0  # yaw rate: + left (counter-clockwise from above)
    angular_x: float = 0.0  # non-zero (with angular_y): no auto-hover on a zero command
    angular_y: float = 0.0

    def progressive(self) -> ProgressiveCommand:
        """As ardrone_autonomy hands it to the drone (``AT*PCMD``): pitch is −linear.x, roll
        −linear.y, the yaw rate −angular.z (the SDK's + is right, nose up, clockwise), each
        clamped; all zero: the auto-hover."""
        t = self.clamped()
        if t.auto_hover:
            return ProgressiveCommand()
        return ProgressiveCommand(roll=-t.linear_y, pitch=-t.linear_x, gaz=t.linear_z,
                                  yaw=-t.angular_z, hover=False)

    @property
    def auto_hover(self) -> bool:
        return all(v == 0.0 for v in (self.linear_x, self.linear_y, self.linear_z,
                                      self.angular_x, self.angular_y, self.angular_z))

    def clamped(self) -> Twist:
        """As the driver passes it on: each component within ±1."""
        return Twist(*(max(-1.0, min(1.0, v)) for v in (
            self.linear_x, self.linear_y, self.linear_z, self.angular_z, self.angular_x,
            self.angular_y)))


class ArDroneTiltModel:
    """Turns each ``cmd_vel`` into the setpoint our vehicle flies: the AR.Drone's velocity,
    integrated from the commanded tilt.

    The horizontal velocity (NED north, east) is the model's state. It starts from the
    vehicle's measured velocity at the first command; then each call integrates the previous
    command (held until replaced, as the drone holds it) over the time since the last call —
    exactly, as the drag makes it a first-order system — and rotates the tilt by the vehicle's
    heading at that time.
    """

    def __init__(self, limits: ArDroneLimits | None = None) -> None:
        self.limits = limits or ArDroneLimits()
        self._velocity_ne = np.zeros(2)
        self._twist = Twist()
        self._yaw_rad = 0.0
        self._last_s: float | None = None

    @property
    def velocity_ne_m_s(self) -> np.ndarray:
        return self._velocity_ne.copy()

    def reset(self) -> None:
        self._last_s = None

    def step(self, twist: Twist, now_s: float, yaw_rad: float,
             velocity_ned_m_s: np.ndarray) -> Setpoint:
        """The setpoint at ``now_s`` with ``twist`` the command from now on; ``yaw_rad`` and
        ``velocity_ned_m_s`` are the vehicle's (telemetry), the latter read only at the first
        call after construction or :meth:`reset`."""
        twist = twist.clamped()
        if self._last_s is None:
            self._velocity_ne = np.array(velocity_ned_m_s[:2], dtype=float)
        else:
            dt = max(now_s - self._last_s, 0.0)  # a stalled loop: the drone flew on meanwhile
            self._velocity_ne = self._advance(self._velocity_ne, self._twist, self._yaw_rad, dt)
        self._last_s = now_s
        self._twist = twist
        self._yaw_rad = yaw_rad
        lim = self.limits
        acc = self._acceleration(self._velocity_ne, twist, yaw_rad)
        if twist.auto_hover:
            return Setpoint(velocity_m_s=(*self._velocity_ne, 0.0),
                            acceleration_m_s2=(*acc, math.nan), yaw_rate_rad_s=0.0,
                            time_s=now_s, progressive=twist.progressive())
        return Setpoint(
            velocity_m_s=(*self._velocity_ne, -twist.linear_z * lim.control_vz_max_m_s),
            acceleration_m_s2=(*acc, math.nan),
            yaw_rate_rad_s=-twist.angular_z * lim.control_yaw_rad_s,  # FRD: + is clockwise
            time_s=now_s, progressive=twist.progressive())

    # -- dynamics -------------------------------------------------------------------------

    def _tilt_acceleration_ne(self, twist: Twist, yaw_rad: float) -> np.ndarray:
        lim = self.limits
        forward = lim.acceleration_m_s2(twist.linear_x)
        right = -lim.acceleration_m_s2(twist.linear_y)
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        return np.array([c * forward - s * right, s * forward + c * right])

    def _acceleration(self, v: np.ndarray, twist: Twist, yaw_rad: float) -> np.ndarray:
        if twist.auto_hover:
            speed = float(np.hypot(*v))
            if speed < 1e-9:
                return np.zeros(2)
            return -(self.limits.acceleration_m_s2(1.0) + self.limits.drag_per_s * speed) \
                * v / speed
        return self._tilt_acceleration_ne(twist, yaw_rad) - self.limits.drag_per_s * v

    def _advance(self, v: np.ndarray, twist: Twist, yaw_rad: float, dt: float) -> np.ndarray:
        k = self.limits.drag_per_s
        if twist.auto_hover:
            # brake at full tilt, with the drag's help, until stopped: |v|' = −(a_max + k|v|)
            speed = float(np.hypot(*v))
            if speed < 1e-9:
                return np.zeros(2)
            a_max = self.limits.acceleration_m_s2(1.0)
            decay = math.exp(-k * dt)
            new_speed = max(0.0, (speed + a_max / k) * decay - a_max / k)
            return v * (new_speed / speed)
        v_inf = self._tilt_acceleration_ne(twist, yaw_rad) / k  # the speed the tilt settles at
        return v_inf + (v - v_inf) * math.exp(-k * dt)
