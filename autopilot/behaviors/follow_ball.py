"""``follow_ball``: follow the ball with a camera for a while, in OFFBOARD.

With ``controller: estimator`` (ours) the behaviour is :class:`~autopilot.behaviors.follow.
FollowTarget` on the tracked ball (lost-target handling included).

``controller: seed001`` and ``seed003`` are the two student reports' rules, kept as baselines
for ``autopilot bench follow_ball``. They act on raw detections, as the originals did, and
command what the originals commanded: an AR.Drone ``cmd_vel`` twist whose components are
fractions of the drone's maximum tilt, climb rate and yaw rate, flown through
:class:`~autopilot.control.ardrone.ArDroneTiltModel` (the tilt integrated into the velocity our
vehicle is given):

* seed 001 (``follow_ball.py``, its final deliverable) — proportional on pixel errors with dead
  bands: linear.x = (RADIUS − r)/5, linear.z = (c_y − v)/25, and either linear.y =
  (c_x − u)/100 (lateral) or angular.z = (c_x − u)/100 (yaw); it acts on the last circle seen,
  so it keeps flying toward a stale detection when the ball disappears, and its twists disable
  the auto-hover (angular.x = angular.y = 1), so a zero command levels the drone and lets it
  coast.
* seed 003 (``main.cpp``) — bang-bang at full scale, one axis per frame in priority order
  (range, height, side): ±1 on linear.x, linear.z or linear.y, and a zero twist (the
  auto-hover) when the frame has no ball or the ball is within every band.

Their pixel thresholds are kept in pixels; what depends on the camera is moved to ours: the
image centre replaces their (320, 180) and seed 003's band centres (300, 250); seed 001's target
radius RADIUS = 20 px and the middle of seed 003's 20–40 px band become r*, the ball's apparent
radius at the standoff distance, so seed 003's band is r*/√2 … r*·√2.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field

from autopilot.behaviors.base import BehaviorInputs, Params
from autopilot.behaviors.follow import FollowTarget, LostTargetSettings
from autopilot.control.ardrone import ArDroneLimits, ArDroneTiltModel, Twist
from autopilot.control.follow import FollowSettings
from drivers.base import CameraInfo, Setpoint

__all__ = ["FollowBall", "FollowBallParams", "LostTargetSettings", "Seed001Rule",
           "Seed003Rule"]

Controller = Literal["estimator", "seed001", "seed003"]


class FollowBallParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    """How long to follow, from the step's start; then the vehicle holds where it is and the
    step succeeds."""
    mode: Literal["yaw", "lateral"] | None = None
    """``yaw``: turn to face the ball; ``lateral``: keep the heading and translate. None:
    ``control.follow.mode`` (config.yaml)."""
    standoff_m: Annotated[float, Field(gt=0.3, le=20)] | None = None
    """Distance kept from the ball along the camera's line of sight. None:
    ``control.follow.standoff_m`` (config.yaml)."""
    controller: Controller = "estimator"
    """``estimator``: ours, on the filtered estimate; ``seed001`` / ``seed003``: the seed
    reports' pixel rules, kept as baselines (flown as AR.Drone tilt commands)."""


class FollowBall(FollowTarget):
    name = "follow_ball"

    def __init__(self, params: FollowBallParams, follow: FollowSettings,
                 lost: LostTargetSettings, camera: CameraInfo, ball_diameter_m: float) -> None:
        intr = camera.intrinsics
        alpha = math.asin(min(1.0, ball_diameter_m / 2.0 / follow.standoff_m))
        target_radius_px = intr.fx * math.tan(alpha)
        rule = None
        if params.controller == "seed001":
            rule = Seed001Rule(camera, target_radius_px, follow.mode == "lateral")
        elif params.controller == "seed003":
            rule = Seed003Rule(camera, target_radius_px)
        super().__init__(params, follow, lost, camera, rule)
        self._target_radius_px = target_radius_px


class Seed001Rule:
    """Seed 001's navigator: proportional on pixel errors with dead bands, on the last circle."""

    # the seed's constants (pixels of its camera, as it gives them)
    IGNORE_DISTANCE_PX = 5.0  # dead band of the image-position errors
    IGNORE_RADIUS_PX = 1.0  # dead band of the radius error
    MAX_X_SPEED_DIFF_PX = 5.0  # radius error at full pitch
    MAX_Y_SPEED_DIFF_PX = 100.0  # horizontal error at full roll (lateral mode)
    MAX_Z_ROTATION_DIFF_PX = 100.0  # horizontal error at full yaw rate (yaw mode)
    SCALAR_Z_SPEED_PX = 25.0  # vertical error at full climb rate

    def __init__(self, camera: CameraInfo, target_radius_px: float, lateral: bool,
                 limits: ArDroneLimits | None = None) -> None:
        self.cx, self.cy = camera.intrinsics.cx, camera.intrinsics.cy
        self.r_target = target_radius_px  # the seed's RADIUS
        self.lateral = lateral
        self.model = ArDroneTiltModel(limits)

    def twist(self, u_px: float, v_px: float, radius_px: float) -> Twist:
        """The seed's ``navigate`` on one circle."""
        image_diff_x = self.cx - u_px  # positive: the drone must move left
        image_diff_y = self.cy - v_px  # positive: up
        radius_diff = self.r_target - radius_px  # positive: forward
        x = _scaled(radius_diff, self.IGNORE_RADIUS_PX, self.MAX_X_SPEED_DIFF_PX)
        z = _scaled(image_diff_y, self.IGNORE_DISTANCE_PX, self.SCALAR_Z_SPEED_PX)
        y = yaw = 0.0
        if self.lateral:
            y = _scaled(image_diff_x, self.IGNORE_DISTANCE_PX, self.MAX_Y_SPEED_DIFF_PX)
        else:
            yaw = _scaled(image_diff_x, self.IGNORE_DISTANCE_PX, self.MAX_Z_ROTATION_DIFF_PX)
        # getCleanTwist: angular.x = angular.y = 1 "Disable hover mode"
        return Twist(x, y, z, yaw, angular_x=1.0, angular_y=1.0)

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        det = inputs.last_detection  # stale or not: seed 001 flies on its last circle
        # before any circle: its initial lastCircle, Circle(320, 180, 20) — the target itself
        twist = self.twist(self.cx, self.cy, self.r_target) if det is None else \
            self.twist(det.u_px, det.v_px, det.radius_px)
        return self.model.step(twist, inputs.now_s, inputs.state.yaw_rad,
                               inputs.state.velocity_ned_m_s)


class Seed003Rule:
    """Seed 003's callback: bang-bang bands, one axis at a time; the auto-hover when the frame
    has no ball or the ball sits within every band.

    Each frame publishes a twist (the last one published in the callback is the one the drone
    flies). The seed's ``temp1`` / ``temp2`` extra stops are left out: they read uninitialised
    locals, and any stop they publish is superseded by the next twist of the same callback.
    """

    FULL = 1.0  # changeTwist(±1, …): full scale
    BAND_PX = 50.0  # y < 200, y > 300, x > 350, x < 250 around the centre (300, 250)

    def __init__(self, camera: CameraInfo, target_radius_px: float,
                 limits: ArDroneLimits | None = None) -> None:
        self.cx, self.cy = camera.intrinsics.cx, camera.intrinsics.cy
        self.r_lo = target_radius_px / math.sqrt(2.0)  # the seed's r < 20: too far
        self.r_hi = target_radius_px * math.sqrt(2.0)  # r > 40: too close
        self.model = ArDroneTiltModel(limits)
        self._seq = -1
        self._twist = Twist()  # after takeoff: changeTwist(0,0,0,0), hovering

    def twist(self, circle: tuple[float, float, float] | None) -> Twist | None:
        """The twist the seed publishes last for one frame's circle ``(x, y, r)`` (None: no
        circle in the frame); None if it publishes nothing (a value exactly on a band's edge)."""
        if circle is None:
            return Twist()  # stop()
        x, y, r = circle
        v, band = self.FULL, self.BAND_PX
        published = None
        if r < self.r_lo:
            published = Twist(linear_x=v)  # forwardx()
        if r > self.r_hi:
            published = Twist(linear_x=-v)  # backx()
        if self.r_lo < r < self.r_hi:
            if y < self.cy - band:
                published = Twist(linear_z=v)  # up()
            if y > self.cy + band:
                published = Twist(linear_z=-v)  # down()
            if self.cy - band < y < self.cy + band:
                if x > self.cx + band:
                    published = Twist(linear_y=-v)  # backy(): right
                if x < self.cx - band:
                    published = Twist(linear_y=v)  # forwardy(): left
                if self.cx - band < x < self.cx + band:
                    published = Twist()  # stop()
        return published

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        if inputs.frame_seq != self._seq:  # the seed acts in its image callback
            self._seq = inputs.frame_seq
            det = inputs.detection
            published = self.twist(None if det is None else
                                   (det.u_px, det.v_px, det.radius_px))
            if published is not None:
                self._twist = published
        return self.model.step(self._twist, inputs.now_s, inputs.state.yaw_rad,
                               inputs.state.velocity_ned_m_s)


def _scaled(difference: float, ignore: float, full_scale: float) -> float:
    """Seed 001's get*Reaction: 0 within the dead band, else difference / full_scale."""
    if abs(difference) < ignore:
        return 0.0
    return difference / full_scale
