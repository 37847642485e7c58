"""Seed 001's own landing logic, as a baseline lander for ``land_pad`` (``lander: seed001``).

What the report says of its lander (§2.5; its ``lander.py`` itself is not printed):

* "The second node is for moving the drone, it initially sets up a subscriber to the topic the
  landing pad identifier publishes to in order to decide when the drone should land. The
  second node has to publish movement commands and wait until actions have been performed in
  order to land on the target effectively."
* The identifier publishes ``(center[0], center[1], max_val)`` — the pad's pixel position and
  score, nothing else — and "applies template matching ... to work out if it is below the
  drone or not"; "the /lander node publishes velocity commands back to the /gazebo node via
  the /cmd_vel topic".
* Landing is the AR.Drone's own: ``self.landPublisher.publish(self.emptyMessage)`` on
  ``/ardrone/land``, then ``rospy.sleep(1.)`` (§2.3), as after every action.
* The lander was written on February 12 (diary), with the stationary ball follower's rule of
  that time (§2.6.2): outside a dead band of ``IGNORE_DISTANCE = 20`` px a command of
  ``0.1 * self.getSign(difference)``, else 0 — before the report found (March 10) that
  ``/cmd_vel``'s linear x/y are a fraction of the maximum tilt, not m/s.

So, once the pad has been seen: per image axis, the pixel offset of the pad's centre from the
image centre outside ±20 px (rescaled from the report's 640 px wide image to this camera)
gives a command of 0.1 toward it, else 0; both zero — the pad below the drone — the lander
stops (hover) and waits 1 s for the action to be performed, and if the pad is still within
the dead band it lands (our LAND: PX4 descends vertically holding its position, as the
AR.Drone's land does); otherwise it goes on steering. It acts on the newest detection it had,
also when the pad is no longer seen, as the seed's nodes keep their last message. It never
descends under its own control: it lands from the height it found the pad at.

Commands are in the seed's units, applied through the AR.Drone tilt model the follow
baselines fly too (:mod:`autopilot.control.ardrone`, as tum_simulator and ardrone_autonomy
define ``/cmd_vel``): a linear x/y of ``c`` tilts the vehicle by ``c`` × the maximum tilt
(``euler_angle_max``, 12° by default), accelerating it by g·tan(tilt) against the AR.Drone's
identified linear drag; a zero command is the AR.Drone's hover mode (it brakes to a stop).
The modelled velocity is flown as a velocity setpoint, the height and heading kept.

Before the first detection, the search is ours (the same :class:`LandPad` search for both
landers), so that the comparison is of what each does once it sees the pad.
"""

from __future__ import annotations

import math

import numpy as np

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.behaviors.land_pad import LandPad, LandPadParams, LandPadSettings
from autopilot.control.ardrone import ArDroneTiltModel, Twist
from drivers.base import CameraInfo, Setpoint

#: the report's constants (§2.6.2, the stationary follower of the lander's time)
IGNORE_DISTANCE_PX = 20.0
COMMAND = 0.1
REPORT_IMAGE_WIDTH_PX = 640.0  # CENTER = (320, 180): a 640 x 360 image
WAIT_S = 1.0  # rospy.sleep(1.) after an action (§2.3)

def seed_command(center_px: tuple[float, float], camera: CameraInfo) -> np.ndarray:
    """The seed's command (body forward, right), as fractions of the maximum tilt, for the
    pad's centre at ``center_px``: 0.1 toward it per image axis outside the dead band."""
    intr = camera.intrinsics
    band = IGNORE_DISTANCE_PX * intr.width_px / REPORT_IMAGE_WIDTH_PX
    du, dv = center_px[0] - intr.cx, center_px[1] - intr.cy
    signs = np.array([0.0 if abs(du) < band else math.copysign(1.0, du),
                      0.0 if abs(dv) < band else math.copysign(1.0, dv), 0.0])
    # toward the pad: an image direction turned into the body frame (down camera: image
    # right is body right, image down is body back)
    body = camera.rotation_body_cam @ signs
    return COMMAND * np.sign(np.round(body[:2], 6))


class Seed001LandPad(Behavior):
    name = "land_pad"

    def __init__(self, params: LandPadParams, settings: LandPadSettings,
                 camera: CameraInfo) -> None:
        self.params = params
        self.camera = camera
        self._search = LandPad(params, settings)
        self.phase = "searching"
        self._tilt = ArDroneTiltModel()
        self._start = 0.0
        self._hover_since: float | None = None
        self._landing_since = 0.0

    def _out(self, setpoint, status=Status.RUNNING, requests=(), reason="") -> BehaviorOutput:
        return BehaviorOutput(status, setpoint=setpoint, requests=requests, phase=self.phase,
                              reason=reason)

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        return self._search.activate(inputs)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now, s = inputs.now_s, inputs.state
        if self.phase == "landing":
            if not s.armed and not s.in_air:
                return self._out(None, Status.SUCCEEDED)
            if now - self._landing_since > 60.0:
                return self._out(None, Status.FAILED, reason="no touchdown after LAND")
            return self._out(None)
        if now - self._start > self.params.timeout_s:
            return self._out(Setpoint.velocity_body(0.0, 0.0, 0.0, time_s=now), Status.FAILED,
                             reason=f"not landed within {self.params.timeout_s:g} s")
        det = inputs.last_detection  # the newest the lander was sent, seen now or not
        if det is None:
            return self._search.update(inputs)
        self.phase = "steering"
        command = seed_command(det.center_px, self.camera)
        if command.any():
            self._hover_since = None
        else:
            self.phase = "waiting"
            if self._hover_since is None:
                self._hover_since = now
            elif now - self._hover_since >= WAIT_S:
                self.phase, self._landing_since = "landing", now
                return self._out(None, requests=(VehicleRequest(RequestKind.LAND),))
        # cmd_vel: linear.x forward, linear.y LEFT (the command here is forward, right)
        twist = Twist(linear_x=float(command[0]), linear_y=-float(command[1]))
        return self._out(self._tilt.step(twist, now, s.yaw_rad, s.velocity_ned_m_s))
