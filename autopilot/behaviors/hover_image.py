"""Hovering over a known image on the ground (seed 000), seen by the down camera.

The hover point is fixed to the image: ``offset_m`` (forward along the image's top, right) from
its centre, ``altitude_m`` above it, heading ``yaw_deg`` from its top. It is flown as PX4
position setpoints (PX4's own position controller holds it, with its limits), moved as the
estimate of the image improves; the hover lasts ``duration_s`` from when the image is first
found (ending over it, not while searching for it again).

Until the image is found the vehicle searches for it (``searching``): the shared search
(:mod:`autopilot.control.search`, as land_pad's) climbs to ``search_altitude_m`` over where the
step began, flies an expanding square out to ``search_radius_m``, its rings a camera footprint
(less the image's size) apart, then waits over the start; not found within
``search_timeout_s``, the step fails and the mission's fallback runs. Lost while hovering
(``lost``), the vehicle holds the hover point (seed 000's auto-hover: it may come back); lost
longer than ``lost_timeout_s`` it searches again around where the image was, at most
``max_retries`` times, then the step fails.
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
from autopilot.control.search import Search, SearchSettings, ring_spacing_m
from drivers.base import Setpoint


class HoverImageParams(Params):
    duration_s: Annotated[float, Field(gt=0)]
    """How long to hover, from when the image is first found."""
    image: str = "default"
    """The reference image: ``default`` (the project's generated target) or an image file."""
    size_m: Annotated[float, Field(gt=0.05, le=50)] = 1.0
    """The image's printed width."""
    altitude_m: Annotated[float, Field(gt=0.3, le=50)] = 2.0
    """Height of the hover point above the image."""
    offset_m: tuple[float, float] = (0.0, 0.0)
    """Where to hover from the image's centre: [forward (towards its top), right]."""
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0
    """The vehicle's heading while hovering, from the direction the image's top points."""
    search_altitude_m: Annotated[float, Field(gt=0.5, le=100)] = 4.0
    """Height of the search above the take-off point (the search is land_pad's). The default
    1 m image is found wholly in view from 4 m (about 4 × ``size_m``; from 8 m never)."""
    search_timeout_s: Annotated[float, Field(gt=0, le=600)] = 40.0
    """The step fails (the mission's fallback lands) if the image is not found this long after
    the search began."""
    search_radius_m: Annotated[float, Field(ge=0, le=100)] = 4.0
    """Half the side of the search's expanding square, around where the step began; 0: climb
    and look only."""
    search_speed_m_s: Annotated[float, Field(gt=0, le=10)] = 2.0
    """The search's setpoint is placed this × 1 s ahead of the vehicle, towards the next
    corner (on the simulated vehicle's position gain, 2 gives about 3 m/s)."""
    max_retries: Annotated[int, Field(ge=0, le=20)] = 2
    """How many times to search again around the image after losing it for
    ``control.follow.lost_timeout_s``; then the step fails."""

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
    lost_timeout_s: float  # lost this long: search again
    #: the width of ground the down camera sees per metre of height
    #: (:func:`~autopilot.planning.footprint.footprint_width_per_m`)
    footprint_per_m: float = 1.2


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
        self.phase = "searching"
        self.retries = 0
        self._hold = np.zeros(3)
        self._hold_yaw = 0.0
        self._image: np.ndarray | None = None  # the image's newest estimate (NED)
        self._seen_at: float | None = None
        self._found_at: float | None = None
        spacing = ring_spacing_m(settings.footprint_per_m, params.search_altitude_m,
                                 params.size_m)
        self._search = Search(SearchSettings(params.search_altitude_m, params.search_radius_m,
                                             spacing, params.search_speed_m_s,
                                             params.search_timeout_s))

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._hold_here(inputs)
        self._search.start(inputs.now_s, self._hold[:2])
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold_setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase=self.phase)

    def _hold_here(self, inputs: BehaviorInputs) -> None:
        self._hold = np.array(inputs.state.position_ned_m, dtype=float)
        self._hold_yaw = inputs.state.yaw_rad

    def _hold_setpoint(self, now_s: float) -> Setpoint:
        return Setpoint.position(*self._hold, yaw_rad=self._hold_yaw, time_s=now_s)

    def _out(self, now_s: float, status: Status = Status.RUNNING,
             reason: str = "") -> BehaviorOutput:
        return BehaviorOutput(status, setpoint=self._hold_setpoint(now_s), phase=self.phase,
                              reason=reason)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now = inputs.now_s
        target = inputs.target
        fresh = target is not None and not target.stale and target.heading_rad is not None \
            and target.age_s <= self.settings.lost_after_s
        if fresh:
            self._seen_at = now
            self._found_at = now if self._found_at is None else self._found_at
            self._image = np.array(target.position_ned_m, dtype=float)
            point = hover_point(target.position_ned_m, target.heading_rad, self.params)
            yaw = target.heading_rad + math.radians(self.params.yaw_deg)
            self._hold, self._hold_yaw = point, math.remainder(yaw, 2.0 * math.pi)
            self.phase = "hovering"
            return self._done_or_on(now)
        if self.phase == "searching":
            return self._searching(inputs)
        # lost: hold the hover point (it may come back), then search again around the image
        self.phase = "lost"
        if now - self._seen_at < self.settings.lost_timeout_s:
            return self._done_or_on(now)
        if self.retries >= self.params.max_retries:
            return self._out(now, Status.FAILED,
                             reason=f"image lost for {now - self._seen_at:.1f} s "
                                    f"({self.retries} searches again)")
        self.retries += 1
        self._search.start(now, self._image[:2])
        self.phase = "searching"
        return self._searching(inputs)

    def _done_or_on(self, now_s: float) -> BehaviorOutput:
        """Over the image (or holding over it): the hover ends ``duration_s`` after the image
        was first found; searching for it again, it goes on."""
        if now_s - self._found_at >= self.params.duration_s:
            self.phase = "done"
            return self._out(now_s, Status.SUCCEEDED)
        return self._out(now_s)

    def _searching(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now = inputs.now_s
        command = self._search.update(now, inputs.state.position_ned_m)
        if command.timed_out:
            self._hold_here(inputs)
            what = "not found" if self._found_at is None else "lost and not found again"
            return self._out(now, Status.FAILED,
                             reason=f"image {what} in {self.params.search_timeout_s:g} s")
        self._hold = np.array(command.position_ned_m)
        return self._out(now)
