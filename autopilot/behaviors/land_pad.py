"""Precision landing on a pad seen by the down camera (seed 001), flown in offboard.

Phases (each shown as the step's phase):

``searching``
    Not seen yet: the shared search (:mod:`autopilot.control.search`): climb (or stay) at
    ``search_altitude_m`` above the take-off point, then fly an expanding square around where
    the search began, out to ``search_radius_m``, its rings a camera footprint apart; then wait
    over the start. Not found within ``search_timeout_s``: the step fails (the mission's
    fallback lands where it is).
``aligning``
    Over the pad's estimate at the current height until within ``acceptance_radius_m`` for
    ``settle_s`` (PX4's ``PLD_HACC_RAD``).
``descending``
    Down over the pad at ``descent_speed_m_s``, slowing to ``final_speed_m_s`` below
    ``slow_height_m``; the descent pauses while the vehicle is outside a cone over the pad
    (``acceptance_radius_m`` plus ``cone_slope`` × height) and goes on when it is back inside.
``lost``
    No fresh estimate above the commit height: hold for ``lost_timeout_s`` (it may come back);
    then ``reacquiring``: climb ``reacquire_climb_m`` (up to the search altitude) over where the
    pad was and look again; after ``max_retries`` such climbs the step fails (PX4: ``PLD_BTOUT``,
    ``PLD_MAX_SRCH``).
``committed``
    Below ``commit_height_m`` the pad may overflow the frame: the descent goes on at
    ``final_speed_m_s`` over the newest estimate (updated while detections still come), without
    aborting on loss.
``touching down``
    At ``touchdown_height_m`` (or ground contact: the descent stalls), the vehicle's own LAND
    mode finishes: it holds the horizontal position, detects the touchdown and disarms.
``precision landing``
    ``method: vehicle_precland`` (or ``px4_precland``): once aligned, the descent is the
    vehicle's own precision landing — PX4's AUTO.PRECLAND, ArduCopter's LAND with PLND — the
    pad's estimate streaming to it as LANDING_TARGET while the pad is seen; PX4 approaches,
    descends, searches when it loses the target and falls back to a normal landing by its
    PLD_* parameters, ArduCopter retries and fails safe by its PLND_* ones. The step ends when
    the vehicle has landed and disarmed, and fails if the vehicle leaves that landing in the
    air. A vehicle that refuses the hand-over (ArduCopter with PLND_ENABLED 0, whose LAND would
    land anywhere: a mission is refused for it before it flies, a goal only here) is landed by
    this step's own descent, the refusal in the log.

Over the pad, the position setpoint is the pad's estimate plus a trim that integrates the
remaining horizontal offset between the vehicle's estimated position and the pad's
(``trim_gain_per_s``, at most ``max_trim_m``): the vehicle's velocity estimate is never quite
consistent with its position estimate, so a position controller settles a few centimetres off
its setpoint; integral action on the offset the camera sees removes that.

Height above the pad: the rangefinder's reading projected on the vertical while it reads, else
the height over the pad's estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

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
from autopilot.config import ColorName
from autopilot.control.search import Search, SearchSettings, ring_spacing_m
from autopilot.estimation.range_median import RangeMedian
from drivers.base import FlightMode, Setpoint, VehicleState
from drivers.geometry import quat_to_matrix

Positive = Annotated[float, Field(gt=0)]


class LandPadParams(Params):
    pad: Literal["circle", "markers"] = "circle"
    """``circle``: a coloured disc on a white square; ``markers``: the nested marker pad."""
    color: ColorName = "red"
    """``circle``: the disc's colour (seed 001: red = land here)."""
    size_m: Annotated[float, Field(gt=0.1, le=10)] = 0.8
    """``circle``: the disc's diameter; ``markers``: the square pad's side."""
    ids: tuple[int, int, int, int, int] = (0, 1, 2, 3, 4)
    """``markers``: the five markers' ids, the centre one first."""
    method: Literal["offboard", "vehicle_precland"] = "offboard"
    """``offboard``: this step flies the descent; ``vehicle_precland``: once aligned, the
    vehicle's own precision landing does, fed LANDING_TARGET (PX4's AUTO.PRECLAND, ArduCopter's
    LAND with PLND_ENABLED); ``px4_precland`` is taken for it (its first name)."""
    @field_validator("method", mode="before")
    @classmethod
    def _first_name(cls, value):
        return "vehicle_precland" if value == "px4_precland" else value

    lander: Literal["ours", "seed001"] = "ours"
    """``ours``, or ``seed001``: seed 001's own landing logic once the pad is seen (a baseline
    for ``autopilot bench land_pad``; :mod:`autopilot.behaviors.land_pad_seed001`)."""
    search_altitude_m: Annotated[float, Field(gt=0.5, le=100)] = 6.0
    """Height of the search above the take-off point (PX4: ``PLD_SRCH_ALT``)."""
    search_timeout_s: Positive = 40.0
    """The step fails (the mission's fallback lands) if the pad is not found this long after
    the search began (PX4: ``PLD_SRCH_TOUT``)."""
    search_radius_m: Annotated[float, Field(ge=0, le=100)] = 4.0
    """Half the side of the search's expanding square, around where the step began; 0: climb
    and look only."""
    search_speed_m_s: Annotated[float, Field(gt=0, le=10)] = 2.0
    """The search's setpoint is placed this × 1 s ahead of the vehicle, towards the next
    corner."""
    acceptance_radius_m: Annotated[float, Field(gt=0, le=5)] = 0.1
    """Horizontal distance from the pad's estimate within which the vehicle counts as aligned,
    and the width of the descent cone at the pad (PX4: ``PLD_HACC_RAD``)."""
    settle_s: Annotated[float, Field(ge=0, le=10)] = 1.0
    """How long the vehicle must stay aligned before the descent starts."""
    cone_slope: Annotated[float, Field(ge=0, le=2)] = 0.15
    """How much wider the descent cone gets per metre of height (m/m): the descent pauses
    while the vehicle is outside ``acceptance_radius_m`` + ``cone_slope`` × height."""
    descent_speed_m_s: Annotated[float, Field(gt=0, le=3)] = 1.0
    """Descent speed above ``slow_height_m``."""
    final_speed_m_s: Annotated[float, Field(gt=0, le=1.5)] = 0.35
    """Descent speed below ``slow_height_m``, and while committed."""
    slow_height_m: Annotated[float, Field(gt=0, le=20)] = 1.5
    """Height above the pad below which the descent slows to ``final_speed_m_s``."""
    commit_height_m: Annotated[float, Field(gt=0, le=5)] = 0.5
    """Below this height the pad may overflow the frame: the descent goes on over the newest
    estimate, and losing the pad no longer aborts."""
    touchdown_height_m: Annotated[float, Field(ge=0, le=2)] = 0.15
    """At this height (or on ground contact) the vehicle's own LAND mode finishes the landing
    and disarms."""
    lost_timeout_s: Annotated[float, Field(gt=0, le=60)] = 2.0
    """How long to hold without a fresh estimate (above the commit height) before climbing to
    look again (PX4: ``PLD_BTOUT``)."""
    reacquire_climb_m: Annotated[float, Field(gt=0, le=20)] = 1.5
    """How far to climb (up to the search altitude) over where the pad was, to look again."""
    max_retries: Annotated[int, Field(ge=0, le=20)] = 3
    """How many times to climb and look again after losing the pad; then the step fails
    (PX4: ``PLD_MAX_SRCH``)."""
    yaw_deg: float | None = None
    """``markers``: the heading to land at, from the direction the pad's top points; None:
    keep the heading."""
    trim_gain_per_s: Annotated[float, Field(ge=0, le=5)] = 0.6
    """Gain of the integral trim on the offset the camera sees over the pad (it removes the
    few centimetres a position controller settles off its setpoint)."""
    max_trim_m: Annotated[float, Field(ge=0, le=2)] = 0.3
    """The largest that trim may grow."""
    timeout_s: Positive = 180.0
    """The step fails if the vehicle has not landed this long after the step started."""


@dataclass(frozen=True, slots=True)
class LandPadSettings:
    lost_after_s: float  # no fresh estimate this long: lost
    #: the width of ground the down camera sees per metre of height
    #: (:func:`~autopilot.planning.footprint.footprint_width_per_m`)
    footprint_per_m: float = 1.2


def height_above(state: VehicleState, pad_down_m: float | None,
                 range_m: float | None = None) -> float:
    """Height above the ground under the vehicle: the rangefinder's reading (``range_m``, by
    default the state's) on the vertical while it reads; else above the pad's estimate (else
    the take-off point)."""
    r = state.distance_to_ground_m if range_m is None else range_m
    if math.isfinite(r):
        tilt_cos = float(quat_to_matrix(state.attitude_q)[2, 2])
        if tilt_cos > 0.5:
            return r * tilt_cos
    ground = pad_down_m if pad_down_m is not None else 0.0
    return ground - float(state.position_ned_m[2])


class LandPad(Behavior):
    name = "land_pad"

    def __init__(self, params: LandPadParams, settings: LandPadSettings) -> None:
        self.params = params
        self.settings = settings
        self.phase = "searching"
        self.retries = 0
        self._start = 0.0
        self._phase_since = 0.0
        self._search = Search(self._search_settings())
        self._hold = np.zeros(3)
        self._yaw = 0.0
        self._z_ref = 0.0
        self._last_tick = 0.0
        self._pad: np.ndarray | None = None  # the pad's newest estimate (NED)
        self._aligned_since: float | None = None
        self._stalled_since: float | None = None
        self._trim = np.zeros(2)
        self._ranges = RangeMedian()  # the rangefinder, its outliers voted out
        self._range = math.nan

    # -- helpers -------------------------------------------------------------------------

    def _set_phase(self, phase: str, now: float) -> None:
        if phase != self.phase:
            self.phase, self._phase_since = phase, now

    def _setpoint(self, position, now: float, vz: float = math.nan) -> Setpoint:
        vel = (math.nan, math.nan, vz) if math.isfinite(vz) else (math.nan,) * 3
        return Setpoint(position_ned_m=position, velocity_m_s=vel, yaw_rad=self._yaw,
                        time_s=now)

    def _out(self, setpoint: Setpoint | None, status: Status = Status.RUNNING,
             requests=(), reason: str = "") -> BehaviorOutput:
        return BehaviorOutput(status, setpoint=setpoint, requests=requests, phase=self.phase,
                              reason=reason)

    def _fresh(self, inputs: BehaviorInputs) -> bool:
        t = inputs.target
        return t is not None and not t.stale and t.confirmed \
            and t.age_s <= self.settings.lost_after_s

    def _search_settings(self) -> SearchSettings:
        p = self.params
        spacing = ring_spacing_m(self.settings.footprint_per_m, p.search_altitude_m, p.size_m)
        return SearchSettings(p.search_altitude_m, p.search_radius_m, spacing,
                              p.search_speed_m_s, p.search_timeout_s)

    def _start_search(self, inputs: BehaviorInputs, centre_ne) -> None:
        self._search.start(inputs.now_s, centre_ne)
        self._set_phase("searching", inputs.now_s)

    # -- lifecycle -----------------------------------------------------------------------

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        self._start = self._last_tick = inputs.now_s
        self._hold = np.array(s.position_ned_m, dtype=float)
        self._yaw = s.yaw_rad
        self._z_ref = float(s.position_ned_m[2])
        self._start_search(inputs, s.position_ned_m[:2])
        return BehaviorOutput(Status.RUNNING, setpoint=self._setpoint(self._hold, inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase=self.phase)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        dt = min(max(now - self._last_tick, 0.0), 0.5)
        self._last_tick = now
        self._range = self._ranges.add(s.time_s, s.distance_to_ground_m,
                                       float(s.velocity_ned_m_s[2]))
        if self.phase == "touching down":
            if not s.armed and not s.in_air:
                return self._out(None, Status.SUCCEEDED)
            if now - self._phase_since > 30.0:
                return self._out(None, Status.FAILED, reason="no touchdown after LAND")
            return self._out(None)
        fresh = self._fresh(inputs)
        if fresh:
            t = inputs.target
            self._pad = np.array(t.position_ned_m, dtype=float)
            if p.yaw_deg is not None and t.heading_rad is not None:
                self._yaw = math.remainder(t.heading_rad + math.radians(p.yaw_deg),
                                           2.0 * math.pi)
        if self.phase == "precision landing":
            return self._precision_landing(inputs, fresh)
        if now - self._start > p.timeout_s:
            return self._out(self._setpoint(self._hold_here(s), now), Status.FAILED,
                             reason=f"not landed within {p.timeout_s:g} s")
        handler = {"searching": self._searching, "aligning": self._aligning,
                   "descending": self._descending, "lost": self._lost,
                   "reacquiring": self._reacquiring, "committed": self._committed}[self.phase]
        return handler(inputs, fresh, dt)

    def _hold_here(self, s: VehicleState) -> np.ndarray:
        return np.array(s.position_ned_m, dtype=float)

    # -- phases --------------------------------------------------------------------------

    def _searching(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if fresh:
            return self._start_aligning(inputs, dt)
        command = self._search.update(now, s.position_ned_m)
        if command.timed_out:
            return self._out(self._setpoint(self._hold_here(s), now), Status.FAILED,
                             reason=f"pad not found in {p.search_timeout_s:g} s")
        return self._out(self._setpoint(command.position_ned_m, now))

    def _start_aligning(self, inputs: BehaviorInputs, dt: float) -> BehaviorOutput:
        """The pad is seen (first, or again): over it at this height."""
        self._z_ref = float(inputs.state.position_ned_m[2])
        self._aligned_since = None
        self._set_phase("aligning", inputs.now_s)
        return self._aligning(inputs, True, dt)

    def _aligning(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if not fresh:
            return self._go_lost(inputs)
        error = float(np.hypot(*(s.position_ned_m[:2] - self._pad[:2])))
        speed = float(np.hypot(*s.velocity_ned_m_s[:2]))
        if error <= p.acceptance_radius_m and speed < 0.3:
            if self._aligned_since is None:
                self._aligned_since = now
            if now - self._aligned_since >= p.settle_s:
                self._z_ref = float(s.position_ned_m[2])
                if p.method == "vehicle_precland":
                    self._set_phase("precision landing", now)
                    return self._out(None, requests=(self._landing_target(inputs),
                                                     VehicleRequest(RequestKind.PRECISION_LAND)))
                self._set_phase("descending", now)
        else:
            self._aligned_since = None
        xy = self._over_pad(s, dt)
        # the vehicle's own precision landing gets the pad from the first aligned sight on, so
        # that its estimator has settled at the hand-over (ArduCopter's takes 2 s)
        early = (self._landing_target(inputs),) if p.method == "vehicle_precland" else ()
        return self._out(self._setpoint((xy[0], xy[1], self._z_ref), now), requests=early)

    def _over_pad(self, s: VehicleState, dt: float) -> np.ndarray:
        """The horizontal setpoint over the pad: its estimate plus the integrated offset."""
        p = self.params
        offset = self._pad[:2] - np.asarray(s.position_ned_m[:2], dtype=float)
        if float(np.linalg.norm(offset)) < 2.0 * p.max_trim_m:
            self._trim = self._trim + p.trim_gain_per_s * offset * dt
            norm = float(np.linalg.norm(self._trim))
            if norm > p.max_trim_m:
                self._trim *= p.max_trim_m / norm
        return self._pad[:2] + self._trim

    def _descent_speed(self, height: float) -> float:
        p = self.params
        return p.descent_speed_m_s if height > p.slow_height_m else p.final_speed_m_s

    def _lower(self, s: VehicleState, speed: float, dt: float) -> float:
        """Move the height reference down by ``speed`` × dt, never far below the vehicle."""
        self._z_ref = min(self._z_ref + speed * dt, float(s.position_ned_m[2]) + 0.6)
        return speed

    def _descending(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if not fresh:
            return self._go_lost(inputs)
        height = height_above(s, self._pad[2], self._range)
        if height <= p.commit_height_m:
            self._set_phase("committed", now)
            return self._committed(inputs, fresh, dt)
        error = float(np.hypot(*(s.position_ned_m[:2] - self._pad[:2])))
        vz = math.nan
        if error <= p.acceptance_radius_m + p.cone_slope * height:
            vz = self._lower(s, self._descent_speed(height), dt)
        xy = self._over_pad(s, dt)
        return self._out(self._setpoint((xy[0], xy[1], self._z_ref), now, vz))

    def _go_lost(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._hold = self._hold_here(inputs.state)
        self._set_phase("lost", inputs.now_s)
        return self._out(self._setpoint(self._hold, inputs.now_s))

    def _lost(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if fresh:
            return self._start_aligning(inputs, dt)
        if now - self._phase_since < p.lost_timeout_s:
            return self._out(self._setpoint(self._hold, now))
        if self.retries >= p.max_retries:
            return self._out(self._setpoint(self._hold, now), Status.FAILED,
                             reason=f"pad lost, {self.retries} retries used")
        self.retries += 1
        where = self._pad[:2] if self._pad is not None else s.position_ned_m[:2]
        z = float(s.position_ned_m[2])
        # up by reacquire_climb_m, but not above the search altitude (unless already there)
        up = max(z - p.reacquire_climb_m, min(z, -p.search_altitude_m))
        self._hold = np.array([where[0], where[1], up])
        self._set_phase("reacquiring", now)
        return self._out(self._setpoint(self._hold, now))

    def _reacquiring(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if fresh:
            return self._start_aligning(inputs, dt)
        arrived = np.linalg.norm(s.position_ned_m - self._hold) < 0.3
        waited = now - self._phase_since
        if (arrived and waited > p.lost_timeout_s + 2.0) or waited > 15.0:
            self._start_search(inputs, self._hold[:2])
            return self._searching(inputs, fresh, dt)
        return self._out(self._setpoint(self._hold, now))

    def _landing_target(self, inputs: BehaviorInputs) -> VehicleRequest:
        return VehicleRequest(RequestKind.LANDING_TARGET,
                              position_ned_m=tuple(float(v) for v in self._pad),
                              time_s=inputs.now_s)

    def request_failed(self, request: VehicleRequest, reason: str) -> BehaviorOutput:
        """The vehicle refused its precision landing (ArduCopter with PLND_ENABLED 0, named in
        the refusal, which the log keeps): it is still hovering over the pad under this step's
        setpoints, so this step flies the descent itself. Any other refusal fails the step."""
        if request.kind is RequestKind.PRECISION_LAND and self.phase == "precision landing":
            self._set_phase("descending", self._phase_since)
            return self._out(None)  # (the next tick's setpoint descends)
        return super().request_failed(request, reason)

    def _precision_landing(self, inputs: BehaviorInputs, fresh: bool) -> BehaviorOutput:
        """PX4 lands; the pad's estimate goes to it while the pad is seen."""
        s, now = inputs.state, inputs.now_s
        if not s.armed and not s.in_air:
            return self._out(None, Status.SUCCEEDED)
        if now - self._start > self.params.timeout_s:
            return self._out(None, Status.FAILED,
                             reason=f"not landed within {self.params.timeout_s:g} s")
        grace_s = 1.5  # the mode change shows in telemetry a little later
        # the firmware's own: PX4's PRECLAND, ArduCopter's LAND (with PLND)
        if s.in_air and now - self._phase_since > grace_s and \
                s.mode not in (FlightMode.PRECLAND, FlightMode.LAND):
            return self._out(None, Status.FAILED,
                             reason=f"precision landing interrupted: the vehicle is in "
                                    f"{s.mode.value}")
        if fresh:
            return self._out(None, requests=(self._landing_target(inputs),))
        return self._out(None)

    def _committed(self, inputs: BehaviorInputs, fresh: bool, dt: float) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        height = height_above(s, self._pad[2], self._range)
        descending = float(s.velocity_ned_m_s[2])
        if descending < 0.05 and now - self._phase_since > 1.0:
            self._stalled_since = self._stalled_since or now
        else:
            self._stalled_since = None
        stalled = self._stalled_since is not None and now - self._stalled_since > 1.0
        if height <= p.touchdown_height_m or stalled:
            self._set_phase("touching down", now)
            return self._out(None, requests=(VehicleRequest(RequestKind.LAND),))
        vz = self._lower(s, p.final_speed_m_s, dt)
        xy = self._over_pad(s, dt)
        return self._out(self._setpoint((xy[0], xy[1], self._z_ref), now, vz))
