"""``follow_marker``: follow a fiducial marker at a standoff (seed 002: 1 m in front of it),
keeping it centred and facing it, in OFFBOARD.

With ``controller: estimator`` (ours) the behaviour is :class:`~autopilot.behaviors.follow.
FollowTarget` on the tracked marker in ``face`` mode: the standoff point lies in front of the
marker's face, and the vehicle turns to the marker. On loss it stops, then searches where the
marker is predicted to be, then the mission's fallback takes over — the seed's "stop and keep
looking", predicted rather than blind.

``controller: seed002`` is the student report's rule, kept as the baseline of ``autopilot bench
follow_marker``. It commands what the report's marker follower commanded (its listing 6.8): an
AR.Drone ``cmd_vel`` twist, proportional on the marker's translation in the camera frame
(metres) — linear.x = 0.1·(z − 1), linear.y = −0.2·x, linear.z = −2.0·y — whose components are
fractions of the drone's maximum tilt and climb rate (the report calls them m/s, but the driver
takes fractions), with no yaw control, flown through :class:`~autopilot.control.ardrone.
ArDroneTiltModel`. Its loop sends each twist for 0.1 s (listing 6.11) and then reads the newest
marker transform again; a twist equal to the previous one means no new sighting, and then it
sends a zero twist (listing 6.9), which puts the AR.Drone in its auto-hover. (The report's
marker size is given in tenths of metres and its translation multiplied by 10 — listing 6.6 —
so the translation is in metres, and 1 is its 1 m standoff.)
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


class FollowMarkerParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    """How long to follow, from the step's start; then the vehicle holds where it is and the
    step succeeds."""
    standoff_m: Annotated[float, Field(gt=0.3, le=20)] = 1.0
    """Distance kept from the marker (seed 002: 1 m)."""
    mode: Literal["face", "yaw", "lateral"] = "face"
    """``face``: stand in front of the marker, along its normal, facing it; ``yaw``: turn to
    face it from wherever the vehicle is; ``lateral``: keep the heading and translate."""
    controller: Literal["estimator", "seed002"] = "estimator"
    """``estimator``: ours, on the filtered estimate; ``seed002``: seed 002's proportional rule
    on the marker's camera translation, kept as a baseline."""


class FollowMarker(FollowTarget):
    name = "follow_marker"

    def __init__(self, params: FollowMarkerParams, follow: FollowSettings,
                 lost: LostTargetSettings, camera: CameraInfo) -> None:
        rule = Seed002Rule(params.standoff_m) if params.controller == "seed002" else None
        super().__init__(params, follow, lost, camera, rule)


class Seed002Rule:
    """Seed 002's three P controllers on the marker's camera-frame translation."""

    P_X, P_Y, P_Z = 0.1, 0.2, 2.0  # 1/m: twist fraction per metre (the report: "s^-1")
    DISPATCH_S = 0.1  # each twist is sent for 0.1 s before the transform is read again

    def __init__(self, standoff_m: float, limits: ArDroneLimits | None = None) -> None:
        self.standoff_m = standoff_m
        self.model = ArDroneTiltModel(limits)
        self._next_s = -math.inf
        self._twist_old: Twist | None = None
        self._twist = Twist()  # after takeoff, before a sighting: nothing sent, hovering

    def twist(self, position_cam_m) -> Twist:
        """Listing 6.8 on the marker's translation (x right, y down, z forward; metres)."""
        x, y, z = (float(c) for c in position_cam_m)
        return Twist(linear_x=(z - self.standoff_m) * self.P_X, linear_y=-x * self.P_Y,
                     linear_z=-y * self.P_Z)

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        now = inputs.now_s
        if now >= self._next_s - 1e-6:  # (a tick's rounding)
            self._next_s = now + self.DISPATCH_S
            det = inputs.last_detection  # the newest transform the detector broadcast
            if det is not None:  # none yet: lookupTransform throws, the loop sends nothing
                twist = self.twist(det.position_cam_m)
                if twist == self._twist_old:  # the same sighting again
                    twist = Twist()
                else:
                    self._twist_old = twist
                self._twist = twist
        return self.model.step(self._twist, now, inputs.state.yaw_rad,
                               inputs.state.velocity_ned_m_s)
