"""Following a tracked target with a camera, for any kind of target (ball, marker, …).

:class:`FollowTarget` flies :class:`~autopilot.control.follow.FollowController` on the step's
target estimate (``inputs.target``). When the track is lost it first coasts for
``lost_coast_s`` — follows where the target was going, its last estimate moved on at its
velocity, so that a target hidden for a moment (something passing in front of it) stays in
view — then stops (holds position) for ``lost_hold_s``, then searches — turning towards where
the target was last seen or is predicted to be, then sweeping on in that direction — and fails
after ``lost_timeout_s`` so that the mission's fallback takes over. A step kind may instead
fly a *rule* (a seed report's controller, kept as a baseline for the benchmarks): an object
whose ``command(inputs)`` returns the setpoint, acting on raw detections as the original did.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from autopilot import values
from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.control.follow import FollowController, FollowSettings
from drivers.base import CameraInfo, Setpoint
from drivers.geometry import wrap_pi

if TYPE_CHECKING:
    from autopilot.estimation.target import TargetEstimate


@dataclass(frozen=True, slots=True)
class LostTargetSettings:
    lost_after_s: float  # no accepted measurement for this long: the track is lost
    hold_s: float  # then hold this long
    search_yaw_rate_rad_s: float  # then search, turning at this rate
    timeout_s: float  # lost this long in all: the step fails
    #: first, follow where the target was going (its last estimate, at its velocity) this
    #: long: a target hidden for a moment (something passing in front of it) stays in view
    coast_s: float = 0.0


class Rule(Protocol):
    def command(self, inputs: BehaviorInputs) -> Setpoint: ...


class FollowTarget(Behavior):
    """Follow ``inputs.target`` for ``params.duration_s`` (``params`` has at least that)."""

    name = "follow"

    def __init__(self, params, follow: FollowSettings, lost: LostTargetSettings,
                 camera: CameraInfo, rule: Rule | None = None) -> None:
        self.params = params
        self.follow = follow
        self.lost = lost
        self.camera = camera
        self.controller = FollowController(follow, camera)
        self._rule = rule
        self._start = 0.0
        self._tracking = False
        self._lost_since: float | None = None
        self._hold_point = np.zeros(3)
        self._hold_yaw = 0.0
        self._search_dir = 1.0
        self._search_aimed = False
        self._last_good: TargetEstimate | None = None  # the last estimate flown on
        self._held = False  # holding (or searching) since the loss's coast ended

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        self._hold_here(inputs)
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase="starting")

    @property
    def follow_mode(self) -> str:
        return self.follow.mode

    def toggle_follow_mode(self) -> str:
        """Switch between lateral and yaw following while flying (seed 001's
        ``/toggle_lateral``); returns the new mode. (``face`` switches to lateral.)"""
        mode = "yaw" if self.follow.mode == "lateral" else "lateral"
        self.follow = dataclasses.replace(self.follow, mode=mode)
        self.controller.settings = self.follow
        if hasattr(self._rule, "lateral"):
            self._rule.lateral = mode == "lateral"
        return mode

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        values.publish("follow.mode", self.follow.mode)
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
            self._held = False
            self._last_good = target
            setpoint = self.controller.update(inputs.now_s, inputs.state, target)
            rel = target.position_ned_m - np.asarray(inputs.state.position_ned_m)
            values.publish("follow.lost_s", 0.0, "s")
            values.publish("follow.range_m", round(float(np.linalg.norm(rel)), 3), "m")
            values.publish("follow.bearing_deg", round(math.degrees(wrap_pi(
                math.atan2(rel[1], rel[0]) - inputs.state.yaw_rad)), 1), "deg")
            return BehaviorOutput(Status.RUNNING, setpoint=setpoint, phase="tracking")
        return self._lost(inputs)

    # -- target lost ------------------------------------------------------------------------

    def _lost(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now = inputs.now_s
        if self._lost_since is None:
            self._lost_since = now
        lost_for = now - self._lost_since
        values.publish("follow.lost_s", round(lost_for, 2), "s")
        last = self._last_good
        if last is not None and lost_for < self.lost.coast_s and not self._held and \
                lost_for < self.lost.timeout_s:
            # coast: follow where it was going (as extrapolated from its last estimate)
            dt = now - last.time_s
            predicted = dataclasses.replace(
                last, time_s=now, position_ned_m=last.position_ned_m + last.velocity_ned_m_s * dt,
                age_s=last.age_s + dt)
            return BehaviorOutput(Status.RUNNING, phase="coasting",
                                  setpoint=self.controller.update(now, inputs.state, predicted))
        if not self._held:
            self._held = True
            self._tracking = False
            self._search_aimed = False
            self._hold_here(inputs)
        if lost_for > self.lost.timeout_s:
            return BehaviorOutput(Status.FAILED, setpoint=self._hold_setpoint(now),
                                  phase="searching", reason=f"target lost for {lost_for:.1f} s")
        if lost_for < self.lost.hold_s + (self.lost.coast_s if last is not None else 0.0):
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
