"""``follow_ball``: follow the ball with a camera for a while, in OFFBOARD.

With ``controller: estimator`` (ours) the behaviour flies :class:`FollowController` on the
tracked target. When the track is lost it holds position for ``lost_hold_s``, then searches —
turning towards where the target was last seen or is predicted to be, then sweeping on in that
direction — and fails after ``lost_timeout_s`` so that the mission's fallback takes over.

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
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.control.follow import FollowController, FollowSettings
from drivers.base import CameraInfo, Setpoint
from drivers.geometry import wrap_pi

Controller = Literal["estimator", "seed001", "seed003"]


class FollowBallParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    mode: Literal["yaw", "lateral"] | None = None  # default: control.follow.mode
    standoff_m: Annotated[float, Field(gt=0.3, le=20)] | None = None  # control.follow
    controller: Controller = "estimator"


@dataclass(frozen=True, slots=True)
class LostTargetSettings:
    lost_after_s: float  # no accepted measurement for this long: the track is lost
    hold_s: float  # then hold this long
    search_yaw_rate_rad_s: float  # then search, turning at this rate
    timeout_s: float  # lost this long in all: the step fails


class FollowBall(Behavior):
    name = "follow_ball"

    def __init__(self, params: FollowBallParams, follow: FollowSettings,
                 lost: LostTargetSettings, camera: CameraInfo, ball_diameter_m: float) -> None:
        self.params = params
        self.follow = follow
        self.lost = lost
        self.camera = camera
        self.controller = FollowController(follow, camera)
        intr = camera.intrinsics
        alpha = math.asin(min(1.0, ball_diameter_m / 2.0 / follow.standoff_m))
        self._target_radius_px = intr.fx * math.tan(alpha)
        if params.controller == "seed001":
            self._rule = Seed001Rule(camera, self._target_radius_px, follow.mode == "lateral",
                                     follow.max_speed_m_s)
        elif params.controller == "seed003":
            self._rule = Seed003Rule(camera, self._target_radius_px, follow.max_speed_m_s)
        else:
            self._rule = None
        self._start = 0.0
        self._tracking = False
        self._lost_since: float | None = None
        self._hold_point = np.zeros(3)
        self._hold_yaw = 0.0
        self._search_dir = 1.0
        self._search_aimed = False

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        self._hold_here(inputs)
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase="starting")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        if inputs.now_s - self._start >= self.params.duration_s:
            self._hold_here(inputs)
            return BehaviorOutput(Status.SUCCEEDED, setpoint=self._hold_setpoint(inputs.now_s),
                                  phase="done")
        if self._rule is not None:
            return BehaviorOutput(Status.RUNNING, setpoint=self._rule.command(inputs),
                                  phase="tracking")
        target = inputs.target
        if (target is not None and target.confirmed and not target.stale
                and target.age_s <= self.lost.lost_after_s):
            if not self._tracking:
                self.controller.reset(inputs.state)
                self._tracking = True
            self._lost_since = None
            setpoint = self.controller.update(inputs.now_s, inputs.state, target)
            return BehaviorOutput(Status.RUNNING, setpoint=setpoint, phase="tracking")
        return self._lost(inputs)

    # -- target lost ------------------------------------------------------------------------

    def _lost(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now = inputs.now_s
        if self._lost_since is None:
            self._lost_since = now
            self._tracking = False
            self._search_aimed = False
            self._hold_here(inputs)
        lost_for = now - self._lost_since
        if lost_for > self.lost.timeout_s:
            return BehaviorOutput(Status.FAILED, setpoint=self._hold_setpoint(now),
                                  phase="searching", reason=f"target lost for {lost_for:.1f} s")
        if lost_for < self.lost.hold_s:
            return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(now),
                                  phase="holding")
        # search: first face where the target should be, then keep turning that way
        yaw = inputs.state.yaw_rad
        if not self._search_aimed:
            bearing = self._predicted_bearing(inputs)
            if bearing is not None and abs(wrap_pi(bearing - yaw)) > math.radians(10):
                self._search_dir = 1.0 if wrap_pi(bearing - yaw) > 0 else -1.0
                pos = self._hold_point
                return BehaviorOutput(Status.RUNNING, phase="searching", setpoint=Setpoint.position(
                    *pos, yaw_rad=bearing, time_s=now))
            self._search_aimed = True
        pos = self._hold_point
        setpoint = Setpoint(position_ned_m=pos, velocity_m_s=np.zeros(3),
                            yaw_rate_rad_s=self._search_dir * self.lost.search_yaw_rate_rad_s,
                            time_s=now)
        return BehaviorOutput(Status.RUNNING, setpoint=setpoint, phase="searching")

    def _predicted_bearing(self, inputs: BehaviorInputs) -> float | None:
        target = inputs.target
        if target is None:
            return None
        rel = target.position_ned_m - np.asarray(inputs.state.position_ned_m)
        if math.hypot(rel[0], rel[1]) < 0.3:
            return None
        return math.atan2(rel[1], rel[0])

    def _hold_here(self, inputs: BehaviorInputs) -> None:
        self._hold_point = np.array(inputs.state.position_ned_m)
        self._hold_yaw = inputs.state.yaw_rad

    def _hold_setpoint(self, now_s: float) -> Setpoint:
        return Setpoint.position(*self._hold_point, yaw_rad=self._hold_yaw, time_s=now_s)


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
