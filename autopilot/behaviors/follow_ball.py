"""``follow_ball``: follow the ball with a camera for a while, in OFFBOARD.

With ``controller: estimator`` (ours) the behaviour is :class:`~autopilot.behaviors.follow.
FollowTarget` on the tracked ball (lost-target handling included).

``controller: seed001`` and ``seed003`` are the two student reports' rules, kept as baselines
for ``autopilot bench follow_ball``. They act on raw detections, as the originals did:

* seed 001 — proportional on pixel errors with dead bands: forward = (r* − r)/5,
  up = (c_y − v)/25, and either left = (c_x − u)/100 (lateral) or a yaw rate of (c_x − u)/100
  units (yaw), a unit being 1 m/s (95 °/s for yaw, the AR.Drone's); it keeps acting on the last
  detection when the ball disappears (it "flies toward stale detections").
* seed 003 — bang-bang bands, one axis at a time in priority order (range, height, side) at
  a fixed 1 m/s; it stops whenever the current frame has no ball.

Their pixel thresholds are rescaled to this camera: r* is the ball's apparent radius at the
standoff distance; image centres replace their hard-coded (320, 180) and (300, 250); seed 003's
radius band 20–40 px becomes r*/√2 … r*·√2, its ±50 px bands are kept. Speeds are limited like
ours.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field

from autopilot.behaviors.base import BehaviorInputs, Params
from autopilot.behaviors.follow import FollowTarget, LostTargetSettings
from autopilot.control.follow import FollowSettings
from drivers.base import CameraInfo, Setpoint

__all__ = ["FollowBall", "FollowBallParams", "LostTargetSettings", "Seed001Rule",
           "Seed003Rule"]

Controller = Literal["estimator", "seed001", "seed003"]


class FollowBallParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    mode: Literal["yaw", "lateral"] | None = None  # default: control.follow.mode
    standoff_m: Annotated[float, Field(gt=0.3, le=20)] | None = None  # control.follow
    controller: Controller = "estimator"


class FollowBall(FollowTarget):
    name = "follow_ball"

    def __init__(self, params: FollowBallParams, follow: FollowSettings,
                 lost: LostTargetSettings, camera: CameraInfo, ball_diameter_m: float) -> None:
        intr = camera.intrinsics
        alpha = math.asin(min(1.0, ball_diameter_m / 2.0 / follow.standoff_m))
        target_radius_px = intr.fx * math.tan(alpha)
        rule = None
        if params.controller == "seed001":
            rule = Seed001Rule(camera, target_radius_px, follow.mode == "lateral",
                               follow.max_speed_m_s)
        elif params.controller == "seed003":
            rule = Seed003Rule(camera, target_radius_px, follow.max_speed_m_s)
        super().__init__(params, follow, lost, camera, rule)
        self._target_radius_px = target_radius_px


class Seed001Rule:
    """Seed 001: proportional pixel rule with dead bands; keeps using the last detection."""

    YAW_UNIT_RAD_S = math.radians(95.0)  # AR.Drone: angular.z = 1 ≈ 95 °/s

    def __init__(self, camera: CameraInfo, target_radius_px: float, lateral: bool,
                 max_speed_m_s: float) -> None:
        self.cx, self.cy = camera.intrinsics.cx, camera.intrinsics.cy
        self.r_target = target_radius_px
        self.lateral = lateral
        self.limit = max_speed_m_s

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        det = inputs.last_detection  # stale or not: seed 001 flies on its last circle
        if det is None:
            return Setpoint.velocity_body(0.0, 0.0, 0.0, time_s=inputs.now_s)
        dx, dy, dr = self.cx - det.u_px, self.cy - det.v_px, self.r_target - det.radius_px
        forward = dr / 5.0 if abs(dr) >= 1.0 else 0.0
        up = dy / 25.0 if abs(dy) >= 5.0 else 0.0
        turn = dx / 100.0 if abs(dx) >= 5.0 else 0.0  # positive: the ball is to the left
        left = turn if self.lateral else 0.0
        yaw_rate = 0.0 if self.lateral else -turn * self.YAW_UNIT_RAD_S
        lim = self.limit
        return Setpoint.velocity_body(_clip(forward, lim), _clip(-left, lim), _clip(-up, lim),
                                      yaw_rate_rad_s=yaw_rate, time_s=inputs.now_s)


class Seed003Rule:
    """Seed 003: bang-bang bands, one axis at a time; stops when the frame has no ball."""

    SPEED_M_S = 1.0
    BAND_PX = 50.0

    def __init__(self, camera: CameraInfo, target_radius_px: float,
                 max_speed_m_s: float) -> None:
        self.cx, self.cy = camera.intrinsics.cx, camera.intrinsics.cy
        self.r_lo = target_radius_px / math.sqrt(2.0)
        self.r_hi = target_radius_px * math.sqrt(2.0)
        self.speed = min(self.SPEED_M_S, max_speed_m_s)

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        det = inputs.detection
        v = self.speed
        fwd = right = down = 0.0
        if det is not None:
            if det.radius_px < self.r_lo:
                fwd = v
            elif det.radius_px > self.r_hi:
                fwd = -v
            elif det.v_px < self.cy - self.BAND_PX:
                down = -v
            elif det.v_px > self.cy + self.BAND_PX:
                down = v
            elif det.u_px > self.cx + self.BAND_PX:
                right = v
            elif det.u_px < self.cx - self.BAND_PX:
                right = -v
        return Setpoint.velocity_body(fwd, right, down, yaw_rate_rad_s=0.0, time_s=inputs.now_s)


def _clip(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))
