"""``follow_marker``: follow a fiducial marker at a standoff (seed 002: 1 m in front of it),
keeping it centred and facing it, in OFFBOARD.

With ``controller: estimator`` (ours) the behaviour is :class:`~autopilot.behaviors.follow.
FollowTarget` on the tracked marker in ``face`` mode: the standoff point lies in front of the
marker's face, and the vehicle turns to the marker. On loss it stops, then searches where the
marker is predicted to be, then the mission's fallback takes over — the seed's "stop and keep
looking", predicted rather than blind.

``controller: seed002`` is the student report's rule, kept as the baseline of ``autopilot bench
follow_marker``: proportional on the marker's translation in the camera frame (metres) — forward
0.1·(z − 1), right 0.2·x, down 2.0·y, in m/s (the AR.Drone's command units) — with no yaw
control; a command equal to the previous one means no new sighting, and then it commands zero
(its "twist == twist_old" loss check): here, a new frame without the marker.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from autopilot.behaviors.base import BehaviorInputs, Params
from autopilot.behaviors.follow import FollowTarget, LostTargetSettings
from autopilot.control.follow import FollowSettings
from drivers.base import CameraInfo, Setpoint


class FollowMarkerParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    standoff_m: Annotated[float, Field(gt=0.3, le=20)] = 1.0  # seed 002: 1 m
    mode: Literal["face", "yaw", "lateral"] = "face"
    controller: Literal["estimator", "seed002"] = "estimator"


class FollowMarker(FollowTarget):
    name = "follow_marker"

    def __init__(self, params: FollowMarkerParams, follow: FollowSettings,
                 lost: LostTargetSettings, camera: CameraInfo) -> None:
        rule = Seed002Rule(params.standoff_m, follow.max_speed_m_s) \
            if params.controller == "seed002" else None
        super().__init__(params, follow, lost, camera, rule)


class Seed002Rule:
    """Seed 002's three P controllers on the marker's camera-frame translation."""

    P_FORWARD, P_LATERAL, P_VERTICAL = 0.1, 0.2, 2.0

    def __init__(self, standoff_m: float, max_speed_m_s: float) -> None:
        self.standoff_m = standoff_m
        self.limit = max_speed_m_s
        self._seq = -1
        self._command = (0.0, 0.0, 0.0)

    def command(self, inputs: BehaviorInputs) -> Setpoint:
        if inputs.frame_seq != self._seq:  # a new frame: a new sighting, or none
            self._seq = inputs.frame_seq
            det = inputs.detection
            if det is None:
                self._command = (0.0, 0.0, 0.0)
            else:
                x, y, z = det.position_cam_m
                lim = self.limit
                self._command = (_clip(self.P_FORWARD * (z - self.standoff_m), lim),
                                 _clip(self.P_LATERAL * x, lim),
                                 _clip(self.P_VERTICAL * y, lim))
        return Setpoint.velocity_body(*self._command, yaw_rate_rad_s=0.0, time_s=inputs.now_s)


def _clip(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))
