"""Hovering over a known image on the ground (seed 000), seen by the down camera.

The hover point is fixed to the image: ``offset_m`` (forward along the image's top, right) from
its centre, ``altitude_m`` above it, heading ``yaw_deg`` from its top. It is flown as PX4
position setpoints (PX4's own position controller holds it, with its limits), moved as the
estimate of the image improves. Before the image is first seen, and while it is lost, the
vehicle holds where it is (seed 000's auto-hover); lost longer than ``lost_timeout_s`` (or never
found), the step fails and the mission's fallback runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field, field_validator

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    RequestKind,
    Status,
    VehicleRequest,
)
from drivers.base import Setpoint


class HoverImageParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    image: str = "default"  # the reference image: "default" (generated) or an image file
    size_m: Annotated[float, Field(gt=0.05, le=50)] = 1.0  # its printed width
    altitude_m: Annotated[float, Field(gt=0.3, le=50)] = 2.0  # above the image
    offset_m: tuple[float, float] = (0.0, 0.0)  # forward (towards its top), right
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0  # heading from its top

    @field_validator("image")
    @classmethod
    def _readable(cls, image: str) -> str:
        if image != "default":
            from autopilot.perception.image_target import load_target_image

            load_target_image(image)  # raises with what is wrong with it
        return image


@dataclass(frozen=True, slots=True)
class HoverSettings:
    lost_after_s: float  # no fresh estimate this long: lost → hold
    lost_timeout_s: float  # lost (or not yet found) this long: the step fails


def hover_point(centre_ned_m, heading_rad: float, params: HoverImageParams) -> np.ndarray:
    """Where the vehicle hovers for an image centred at ``centre_ned_m`` whose top points to
    ``heading_rad``."""
    forward, right = params.offset_m
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    return np.array([centre_ned_m[0] + forward * c - right * s,
                     centre_ned_m[1] + forward * s + right * c,
                     centre_ned_m[2] - params.altitude_m])


class HoverImage(Behavior):
    name = "hover_image"

    def __init__(self, params: HoverImageParams, settings: HoverSettings) -> None:
        self.params = params
        self.settings = settings
        self._start = 0.0
        self._hold = np.zeros(3)
        self._hold_yaw = 0.0
        self._seen_at: float | None = None

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        self._hold_here(inputs)
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase="searching")

    def _hold_here(self, inputs: BehaviorInputs) -> None:
        self._hold = np.array(inputs.state.position_ned_m, dtype=float)
        self._hold_yaw = inputs.state.yaw_rad

    def _hold_setpoint(self, now_s: float) -> Setpoint:
        return Setpoint.position(*self._hold, yaw_rad=self._hold_yaw, time_s=now_s)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now = inputs.now_s
        if now - self._start >= self.params.duration_s:
            return BehaviorOutput(Status.SUCCEEDED, setpoint=self._hold_setpoint(now),
                                  phase="done")
        target = inputs.target
        fresh = target is not None and not target.stale and target.heading_rad is not None \
            and target.age_s <= self.settings.lost_after_s
        if fresh:
            self._seen_at = now
            point = hover_point(target.position_ned_m, target.heading_rad, self.params)
            yaw = target.heading_rad + math.radians(self.params.yaw_deg)
            self._hold, self._hold_yaw = point, math.remainder(yaw, 2.0 * math.pi)
            return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(now),
                                  phase="hovering")
        since = self._seen_at if self._seen_at is not None else self._start
        if now - since >= self.settings.lost_timeout_s:
            what = "lost" if self._seen_at is not None else "not found"
            return BehaviorOutput(Status.FAILED, setpoint=self._hold_setpoint(now),
                                  reason=f"image {what} for {now - since:.1f} s")
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(now),
                              phase="lost" if self._seen_at is not None else "searching")
