"""Precision landing on a moving rover's deck (seed 004), flown in offboard on the relative-state
filter's estimate of the deck (:mod:`autopilot.perception.deck_pipeline`).

Every setpoint moves with the deck: its position is the deck's estimate (in the drone's own
frame) plus an offset, its velocity feed-forward the deck's velocity, its acceleration
feed-forward the deck's turn (ω × v); the heading follows the rover's.

Phases (each shown as the step's phase):

``waiting``
    No estimate of the deck yet (no rover report, no range, no tag): hold, up to
    ``wait_timeout_s``.
``approaching``
    To ``approach_distance_m`` behind the deck and ``approach_height_m`` above it, closing at
    up to ``approach_speed_m_s`` relative to the rover (a drone coming from behind is not in
    the rover's way and sees the deck's tag come into view).
``aligning``
    Over the deck at the approach height until within ``acceptance_radius_m`` of its centre,
    the estimate certain enough (below), for ``settle_s``.
``descending``
    Down at ``descent_speed_m_s`` (``final_speed_m_s`` below ``slow_height_m``), only while
    inside a cone over the deck (``acceptance_radius_m`` + ``cone_slope`` × height); below
    ``abort_height_m``, an error beyond ``abort_error_m``, an estimate whose horizontal 2σ
    exceeds ``abort_error_m``, or a stale estimate aborts.
``committed``
    Below ``commit_height_m``: on down at ``final_speed_m_s`` over the newest estimate, no
    more aborts (climbing out this close to a moving deck is the riskier choice).
``touching down``
    Contact (the rangefinder reads ``touchdown_height_m`` or less, or the descent stalls):
    the motors are cut at once (a forced disarm, as PX4's kill) so the deck carries the drone
    rather than the drone skating on it; done when the vehicle reports disarmed on the ground.
``aborting``
    Climb back to the approach height over the deck (still moving with it), then align again;
    after ``max_retries`` aborts the step fails and the mission's fallback takes over.

Height above the deck: the rangefinder's reading on the vertical while the filter is sure the
vehicle is over the deck, else the filter's relative height.
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
from autopilot.estimation.range_median import RangeMedian
from autopilot.estimation.target import TargetEstimate
from drivers.base import FlightMode, Setpoint, VehicleState
from drivers.geometry import quat_to_matrix
from drivers.geometry import rot_z as _yaw_matrix

Positive = Annotated[float, Field(gt=0)]


class LandOnRoverParams(Params):
    use_uwb: bool = True
    """Fuse the UWB ranges to the rover's anchors (seed 004's ``use_uwb``)."""
    use_marker: bool = True
    """Fuse the deck's tag seen by the down camera (seed 004's ``use_marker``)."""
    approach_height_m: Annotated[float, Field(gt=0.5, le=30)] = 3.0
    """Height above the deck to approach and align at."""
    approach_distance_m: Annotated[float, Field(ge=0, le=20)] = 2.0
    """How far behind the deck the approach aims for."""
    approach_speed_m_s: Annotated[float, Field(gt=0, le=15)] = 4.0
    """The fastest the approach closes in, relative to the rover."""
    acceptance_radius_m: Annotated[float, Field(gt=0, le=2)] = 0.1
    """Horizontal distance from the deck's centre within which the vehicle counts as aligned,
    and the width of the descent cone at the deck."""
    landing_margin_m: Annotated[float, Field(ge=0, le=2)] = 0.12
    """The skids' half-span: the body's centre must touch down this far inside the deck's
    edge."""
    settle_s: Annotated[float, Field(ge=0, le=10)] = 0.5
    """How long the vehicle must stay aligned (the estimate certain enough) before the descent
    starts."""
    cone_slope: Annotated[float, Field(ge=0, le=2)] = 0.15
    """How much wider the descent cone gets per metre of height (m/m): the descent goes on
    only inside it, and the room the error plus the estimate's 2σ may take grows with it."""
    descent_speed_m_s: Annotated[float, Field(gt=0, le=3)] = 0.8
    """Descent speed above ``slow_height_m``."""
    final_speed_m_s: Annotated[float, Field(gt=0, le=1.5)] = 0.4
    """Descent speed below ``slow_height_m``, and while committed."""
    slow_height_m: Annotated[float, Field(gt=0, le=20)] = 1.0
    """Height above the deck below which the descent slows to ``final_speed_m_s``."""
    abort_height_m: Annotated[float, Field(ge=0, le=10)] = 1.2
    """Below this height above the deck the abort checks apply (error, uncertainty, a stale
    estimate)."""
    abort_error_m: Annotated[float, Field(gt=0, le=2)] = 0.2
    """Below ``abort_height_m``, a horizontal error from the estimate's centre beyond this, or
    an estimate whose horizontal 2σ exceeds it, aborts: climb back and try again."""
    commit_height_m: Annotated[float, Field(ge=0, le=3)] = 0.35
    """Below this height the descent goes on over the newest estimate and never aborts."""
    touchdown_height_m: Annotated[float, Field(gt=0, le=1)] = 0.12
    """Contact: the rangefinder (at the body origin) this close to the deck (the skids' depth
    below it plus a little); the motors are cut."""
    max_retries: Annotated[int, Field(ge=0, le=10)] = 3
    """How many aborts (climb back, align again) before the step fails into the mission's
    fallback."""
    wait_timeout_s: Positive = 10.0
    """How long to hold waiting for a first estimate of the deck (no rover report, range or
    tag yet) before the step fails."""
    timeout_s: Positive = 180.0
    """The step fails if the vehicle has not landed this long after the step started."""
    face_rover_heading: bool = True
    """Turn with the rover's heading; false: keep the heading the vehicle had at the start."""
    strategy: Literal["ours", "seed004"] = "ours"
    """``ours``, or ``seed004``: seed 004's (a baseline for ``autopilot bench landing``): its
    fused filter (PX4 position, UWB, tag, rover compass, altimeter) and its gain-scheduled
    PID."""
    trim_gain_per_s: Annotated[float, Field(ge=0, le=5)] = 0.6
    """Gain of the integral trim on the offset the estimate shows over the deck (the position
    controller settles a little off a moving setpoint)."""
    max_trim_m: Annotated[float, Field(ge=0, le=1)] = 0.15
    """The largest that trim may grow."""


@dataclass(frozen=True, slots=True)
class LandOnRoverSettings:
    deck_size_m: tuple[float, float]
    deck_height_m: float


class LandOnRover(Behavior):
    name = "land_on_rover"

    def __init__(self, params: LandOnRoverParams, settings: LandOnRoverSettings) -> None:
        self.params = params
        self.settings = settings
        self.phase = "waiting"
        self.retries = 0
        self._start = 0.0
        self._phase_since = 0.0
        self._last_tick = 0.0
        self._yaw = math.nan
        self._height_ref = params.approach_height_m  # the height above the deck flown to
        self._aligned_since: float | None = None
        self._stalled_since: float | None = None
        self._trim = np.zeros(2)
        self._hold = np.zeros(3)
        self.abort_reasons: list[str] = []
        self._ranges = RangeMedian()  # the rangefinder, its outliers voted out
        self._range = math.nan

    # -- helpers -----------------------------------------------------------------------------

    def _set_phase(self, phase: str, now: float) -> None:
        if phase != self.phase:
            self.phase, self._phase_since = phase, now

    def _out(self, setpoint: Setpoint | None, status: Status = Status.RUNNING,
             requests=(), reason: str = "") -> BehaviorOutput:
        return BehaviorOutput(status, setpoint=setpoint, requests=requests, phase=self.phase,
                              reason=reason)

    @staticmethod
    def _usable(t: TargetEstimate | None) -> bool:
        return t is not None and not t.stale and bool(np.all(np.isfinite(t.position_ned_m)))

    @staticmethod
    def _now_position(s: VehicleState, now: float) -> np.ndarray:
        """The vehicle's position now (its newest telemetry carried forward to ``now``)."""
        dt = min(max(now - s.time_s, 0.0), 0.2)
        return np.asarray(s.position_ned_m, dtype=float) + np.asarray(s.velocity_ned_m_s) * dt

    def _height(self, s: VehicleState, t: TargetEstimate, position: np.ndarray) -> float:
        """Height of the body origin above the deck."""
        offset = position - np.asarray(t.position_ned_m)
        local = _yaw_matrix(t.heading_rad or 0.0).T @ offset
        half_l, half_w = (v / 2.0 for v in self.settings.deck_size_m)
        over = abs(local[0]) < half_l - 0.1 and abs(local[1]) < half_w - 0.1
        r = self._range
        if over and math.isfinite(r):
            tilt_cos = float(quat_to_matrix(s.attitude_q)[2, 2])
            if tilt_cos > 0.5:
                return float(r * tilt_cos)
        return float(-offset[2])

    def _setpoint(self, t: TargetEstimate, offset_body: np.ndarray, now: float, *,
                  position: np.ndarray, max_step_m: float = math.inf,
                  descent_m_s: float = 0.0) -> Setpoint:
        """A setpoint moving with the deck: its estimate + ``offset_body`` (rover axes, z
        down), with the deck's velocity (and turn) as feed-forward; the step towards it from
        ``position`` is at most ``max_step_m`` (which bounds the closing speed)."""
        psi = t.heading_rad if t.heading_rad is not None else 0.0
        goal = np.asarray(t.position_ned_m, dtype=float) + _yaw_matrix(psi) @ offset_body
        goal[:2] += self._trim
        step = goal - position
        dist = float(np.linalg.norm(step[:2]))
        if dist > max_step_m:
            goal[:2] = position[:2] + step[:2] * (max_step_m / dist)
        v = np.asarray(t.velocity_ned_m_s, dtype=float).copy()
        v[2] = descent_m_s
        w = t.heading_rate_rad_s
        acc = np.array(t.acceleration_ned_m_s2, dtype=float) \
            if t.acceleration_ned_m_s2 is not None else np.array([-w * v[1], w * v[0], 0.0])
        if self.params.face_rover_heading and t.heading_rad is not None:
            self._yaw = t.heading_rad
        return Setpoint(position_ned_m=goal, velocity_m_s=v, acceleration_m_s2=acc,
                        yaw_rad=self._yaw,
                        yaw_rate_rad_s=w if self.params.face_rover_heading else math.nan,
                        time_s=now)

    def _horizontal_error(self, t: TargetEstimate, position: np.ndarray) -> float:
        return float(np.hypot(*(position[:2] - np.asarray(t.position_ned_m)[:2])))

    def _room(self, height: float) -> float:
        """How far off the deck's centre the vehicle may be (error + 2σ) at ``height``: at
        touchdown, the deck's half-width less the skids' half-span; more higher up (a cone)."""
        p = self.params
        edge = min(self.settings.deck_size_m) / 2.0 - p.landing_margin_m
        return edge + p.cone_slope * max(height - p.commit_height_m, 0.0)

    @staticmethod
    def _sigma(t: TargetEstimate) -> float:
        return float(math.sqrt(max(t.covariance[0, 0], t.covariance[1, 1])))

    def _update_trim(self, t: TargetEstimate, position: np.ndarray, dt: float) -> None:
        """Integral action on the offset the estimate shows (the position controller settles a
        little off a moving setpoint)."""
        p = self.params
        offset = np.asarray(t.position_ned_m)[:2] - position[:2]
        if float(np.linalg.norm(offset)) < 2.0 * p.max_trim_m + p.acceptance_radius_m:
            self._trim = self._trim + p.trim_gain_per_s * offset * dt
            norm = float(np.linalg.norm(self._trim))
            if norm > p.max_trim_m:
                self._trim *= p.max_trim_m / norm

    # -- lifecycle ---------------------------------------------------------------------------

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        self._start = self._last_tick = self._phase_since = inputs.now_s
        self._yaw = s.yaw_rad
        self._hold = np.array(s.position_ned_m, dtype=float)
        return BehaviorOutput(Status.RUNNING, setpoint=Setpoint(
            position_ned_m=self._hold, yaw_rad=self._yaw, time_s=inputs.now_s),
            requests=(VehicleRequest(RequestKind.START_OFFBOARD),), phase=self.phase)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        dt = min(max(now - self._last_tick, 0.0), 0.5)
        self._last_tick = now
        self._range = self._ranges.add(s.time_s, s.distance_to_ground_m,
                                       float(s.velocity_ned_m_s[2]))
        if self.phase == "touching down":
            return self._touching_down(inputs)
        if now - self._start > p.timeout_s:
            return self._out(Setpoint(position_ned_m=self._now_position(s, now),
                                      yaw_rad=self._yaw, time_s=now), Status.FAILED,
                             reason=f"not landed within {p.timeout_s:g} s")
        t = inputs.target
        position = self._now_position(s, now)
        if not self._usable(t):
            return self._no_estimate(inputs, position)
        if self.phase == "waiting":
            self._set_phase("approaching", now)
        handler = {"approaching": self._approaching, "aligning": self._aligning,
                   "descending": self._descending, "committed": self._committed,
                   "aborting": self._aborting}[self.phase]
        return handler(inputs, t, position, dt)

    def _touching_down(self, inputs: BehaviorInputs) -> BehaviorOutput:
        """The motors are cut: done once the vehicle reports disarmed and rests on the deck
        (moving with it, as far as the estimate tells) for ``settle_s``."""
        s, now, t = inputs.state, inputs.now_s, inputs.target
        if s.armed:
            if now - self._phase_since > 3.0:
                return self._out(None, Status.FAILED,
                                 reason="still armed 3 s after the motors were cut")
            return self._out(None)
        # standing on something (the rangefinder reads the skids' depth, no vertical motion),
        # and that something is the deck, not the ground beside it (the estimate's height
        # above the deck: the ground is the deck's height lower)
        r = s.distance_to_ground_m
        resting = abs(float(s.velocity_ned_m_s[2])) < 0.1 and (
            not math.isfinite(r) or r <= self.params.touchdown_height_m + 0.05)
        if resting and t is not None and np.all(np.isfinite(t.position_ned_m)):
            above = float(t.position_ned_m[2] - self._now_position(s, now)[2])
            resting = -0.05 < above < 0.4
        if not resting:
            self._stalled_since = None
            if now - self._phase_since >= 3.0:
                return self._out(None, Status.FAILED,
                                 reason="the motors were cut but the vehicle did not come to "
                                        "rest on the deck")
            return self._out(None)
        self._stalled_since = self._stalled_since if self._stalled_since is not None else now
        if now - self._stalled_since >= min(self.params.settle_s, 0.5):
            return self._out(None, Status.SUCCEEDED)
        return self._out(None)

    def _no_estimate(self, inputs: BehaviorInputs, position: np.ndarray) -> BehaviorOutput:
        p, now = self.params, inputs.now_s
        if self.phase == "committed":
            # blind this close: keep going down where the deck was last seen to be
            return self._out(Setpoint(position_ned_m=(math.nan, math.nan, math.nan),
                                      velocity_m_s=(0.0, 0.0, p.final_speed_m_s),
                                      yaw_rad=self._yaw, time_s=now))
        if self.phase == "descending":
            self._abort("the deck's estimate went stale", now, inputs)
        if self.phase != "waiting" and self.phase != "aborting":
            self._set_phase("waiting", now)
        if self.phase == "waiting" and now - self._phase_since > p.wait_timeout_s:
            return self._out(Setpoint(position_ned_m=position, yaw_rad=self._yaw,
                                      time_s=now), Status.FAILED,
                             reason=f"no estimate of the rover's deck within "
                                    f"{p.wait_timeout_s:g} s (no rover report, UWB or tag)")
        if self.retries > p.max_retries:
            return self._out(None, Status.FAILED, reason=self._failure())
        hold = position.copy()
        if self.phase == "aborting":
            hold[2] = min(hold[2], self._hold[2])
        return self._out(Setpoint(position_ned_m=hold, velocity_m_s=(0.0, 0.0, 0.0),
                                  yaw_rad=self._yaw, time_s=now))

    def _failure(self) -> str:
        why = "; ".join(self.abort_reasons[-3:])
        return f"landing aborted {self.retries} times ({why})"

    def _abort(self, reason: str, now: float, inputs: BehaviorInputs) -> None:
        self.retries += 1
        self.abort_reasons.append(reason)
        self._hold = np.array(inputs.state.position_ned_m, dtype=float)
        self._hold[2] -= self.params.approach_height_m
        self._aligned_since = None
        self._set_phase("aborting", now)

    # -- phases ------------------------------------------------------------------------------

    def _approaching(self, inputs, t, position, dt) -> BehaviorOutput:
        p, now = self.params, inputs.now_s
        offset = np.array([-p.approach_distance_m, 0.0, -p.approach_height_m])
        sp = self._setpoint(t, offset, now, position=position,
                            max_step_m=p.approach_speed_m_s / 1.8)
        if float(np.linalg.norm(position - np.asarray(sp.position_ned_m))) < 0.4 or \
                self._horizontal_error(t, position) < p.approach_distance_m * 0.5:
            self._height_ref = p.approach_height_m
            self._set_phase("aligning", now)
        return self._out(sp)

    def _aligning(self, inputs, t, position, dt) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        error = self._horizontal_error(t, position)
        rel_speed = float(np.hypot(*(np.asarray(s.velocity_ned_m_s)[:2]
                                     - np.asarray(t.velocity_ned_m_s)[:2])))
        height = self._height(s, t, position)
        if error <= p.acceptance_radius_m and rel_speed < 0.3 and \
                error + 2.0 * self._sigma(t) <= self._room(height):
            self._aligned_since = self._aligned_since if self._aligned_since is not None \
                else now
            if now - self._aligned_since >= p.settle_s:
                self._set_phase("descending", now)
        else:
            self._aligned_since = None
        self._update_trim(t, position, dt)
        return self._out(self._setpoint(t, np.array([0.0, 0.0, -self._height_ref]), now,
                                        position=position, max_step_m=p.approach_speed_m_s / 1.8))

    def _descending(self, inputs, t, position, dt) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        height = self._height(s, t, position)
        if height <= p.commit_height_m:
            self._set_phase("committed", now)
            return self._committed(inputs, t, position, dt)
        error = self._horizontal_error(t, position)
        two_sigma = 2.0 * self._sigma(t)
        if height < p.abort_height_m:
            if error > p.abort_error_m:
                self._abort(f"{error:.2f} m off the deck's centre at {height:.2f} m", now,
                            inputs)
                return self._aborting(inputs, t, position, dt)
            if error + two_sigma > self._room(height) + 0.1:
                self._abort(f"estimate too uncertain (2σ {two_sigma:.2f} m) at "
                            f"{height:.2f} m", now, inputs)
                return self._aborting(inputs, t, position, dt)
        speed = p.descent_speed_m_s if height > p.slow_height_m else p.final_speed_m_s
        descent = 0.0
        if error <= p.acceptance_radius_m + p.cone_slope * height and \
                error + two_sigma <= self._room(height):
            descent = speed
            # the reference goes down, never far below the vehicle
            self._height_ref = max(min(self._height_ref, height + 0.3) - speed * dt, 0.0)
        self._update_trim(t, position, dt)
        return self._out(self._setpoint(t, np.array([0.0, 0.0, -self._height_ref]), now,
                                        position=position, descent_m_s=descent))

    def _committed(self, inputs, t, position, dt) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if (left := _left_offboard(s)) is not None:
            return self._out(None, Status.FAILED, reason=left)
        height = self._height(s, t, position)
        rel_vz = float(s.velocity_ned_m_s[2] - t.velocity_ned_m_s[2])
        if rel_vz < 0.05 and now - self._phase_since > 0.5:
            self._stalled_since = self._stalled_since if self._stalled_since is not None \
                else now
        else:
            self._stalled_since = None
        stalled = self._stalled_since is not None and now - self._stalled_since > 0.3
        if height <= p.touchdown_height_m or stalled:
            self._set_phase("touching down", now)
            self._stalled_since = None
            return self._out(None, requests=(VehicleRequest(RequestKind.DISARM, force=True),))
        self._height_ref = max(min(self._height_ref, height + 0.2) - p.final_speed_m_s * dt,
                               -0.3)
        self._update_trim(t, position, dt)
        return self._out(self._setpoint(t, np.array([0.0, 0.0, -self._height_ref]), now,
                                        position=position, descent_m_s=p.final_speed_m_s))

    def _aborting(self, inputs, t, position, dt) -> BehaviorOutput:
        p, s, now = self.params, inputs.state, inputs.now_s
        if self.retries > p.max_retries:
            return self._out(self._setpoint(t, np.array([0.0, 0.0, -p.approach_height_m]),
                                            now, position=position), Status.FAILED,
                             reason=self._failure())
        self._height_ref = p.approach_height_m
        height = self._height(s, t, position)
        if height > p.approach_height_m - 0.3:
            self._set_phase("aligning", now)
        return self._out(self._setpoint(t, np.array([0.0, 0.0, -p.approach_height_m]), now,
                                        position=position, max_step_m=p.approach_speed_m_s / 1.8))


@dataclass(frozen=True, slots=True)
class Seed004LandingSettings:
    """Seed 004's landing action's controller (``control.seed004_landing`` in config.yaml):
    the seed names a gain-scheduled PID and approach thresholds but prints no number."""

    approach_pid: tuple[float, float, float] = (1.5, 0.0, 0.1)  # Kp, Ki, Kd far from the deck
    near_pid: tuple[float, float, float] = (1.5, 0.5, 0.1)  # ... within near_distance_m
    near_distance_m: float = 1.0
    descent_threshold_m: float = 0.1  # the approach ends (descent starts) within this
    vertical_gain_per_s: float = 1.0  # vz = gain × (height − the phase's height)
    max_descent_speed_m_s: float = 0.5
    max_speed_m_s: float = 5.0


class Seed004LandOnRover(LandOnRover):
    """Seed 004's landing action (its Algorithm 9), as a baseline for ``autopilot bench
    landing``: every tick, the relative position from the seed's fused filter → velocity
    inputs from "the adaptive, or gain scheduled, PID controller" → offboard velocity
    setpoints; no feed-forward of the rover's motion, no abort. The phases of its figure 4.7:
    ``approaching`` at ``approach_height_m`` above the deck until the horizontal error is
    within ``descent_threshold_m`` (the seed's "thresholds associated to the approach"), then
    ``descending`` to the deck (the PID's vertical error: the height), for good. Gains
    scheduled on the horizontal distance: ``approach_pid`` beyond ``near_distance_m``,
    ``near_pid`` (with the integral that catches a moving deck) within it. At contact the
    motors are cut and the landing ends once resting on the deck, as ours does (the comparison
    is of estimation and control, not of the touchdown)."""

    name = "land_on_rover"

    def __init__(self, params: LandOnRoverParams, settings: LandOnRoverSettings,
                 control: Seed004LandingSettings = Seed004LandingSettings()) -> None:
        super().__init__(params, settings)
        self.control = control
        self.phase = "approaching"
        self._start = self._last = self._phase_since = 0.0
        self._integral = np.zeros(2)
        self._last_error: np.ndarray | None = None
        self._last_error_s = 0.0
        self._derivative = np.zeros(2)
        self._yaw = math.nan
        self._stalled_since: float | None = None

    def gains(self, distance_m: float) -> tuple[float, float, float]:
        """The gain schedule: (Kp, Ki, Kd) at this horizontal distance from the deck."""
        c = self.control
        return c.near_pid if distance_m <= c.near_distance_m else c.approach_pid

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        self._start = self._last = self._phase_since = inputs.now_s
        self._yaw = s.yaw_rad
        return BehaviorOutput(Status.RUNNING, setpoint=Setpoint(
            position_ned_m=np.array(s.position_ned_m, dtype=float), yaw_rad=self._yaw,
            time_s=inputs.now_s), requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
            phase=self.phase)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        p, c, s, now, t = self.params, self.control, inputs.state, inputs.now_s, inputs.target
        dt = min(max(now - self._last, 1e-3), 0.5)
        self._last = now
        out = lambda sp, status=Status.RUNNING, req=(), reason="": BehaviorOutput(  # noqa: E731
            status, setpoint=sp, requests=req, phase=self.phase, reason=reason)
        if self.phase == "touching down":
            return self._touching_down(inputs)
        if now - self._start > p.timeout_s:
            return out(None, Status.FAILED, reason=f"not landed within {p.timeout_s:g} s")
        if t is None or t.stale:
            return out(Setpoint.velocity_ned(0.0, 0.0, 0.0, yaw_rad=self._yaw, time_s=now))
        error = np.asarray(t.position_ned_m[:2], dtype=float) - \
            np.asarray(s.position_ned_m[:2], dtype=float)
        distance = float(np.linalg.norm(error))
        # the derivative over the filter's published estimates (5 Hz), not the control ticks
        if self._last_error is None:
            self._last_error, self._last_error_s = error, now
        elif not np.allclose(error, self._last_error, atol=1e-9, rtol=0.0):
            self._derivative = (error - self._last_error) / max(now - self._last_error_s, 1e-3)
            self._last_error, self._last_error_s = error, now
        kp, ki, kd = self.gains(distance)
        if ki > 0.0:  # anti-windup: the integral's share at most the top speed
            limit = c.max_speed_m_s / ki
            self._integral = np.clip(self._integral + error * dt, -limit, limit)
        else:
            self._integral[:] = 0.0
        v = kp * error + ki * self._integral + kd * self._derivative
        speed = float(np.linalg.norm(v))
        if speed > c.max_speed_m_s:
            v *= c.max_speed_m_s / speed
        height = float(t.position_ned_m[2] - s.position_ned_m[2])
        if self.phase == "approaching" and distance <= c.descent_threshold_m:
            self.phase, self._phase_since = "descending", now
        target_height = p.approach_height_m if self.phase == "approaching" else 0.0
        vz = float(np.clip(c.vertical_gain_per_s * (height - target_height),
                           -c.max_descent_speed_m_s, c.max_descent_speed_m_s))
        if self.phase == "descending":
            r = s.distance_to_ground_m
            contact = math.isfinite(r) and r <= p.touchdown_height_m
            if contact or self._stalled(s, now, height):
                self.phase, self._phase_since = "touching down", now
                self._stalled_since = None
                return out(None, req=(VehicleRequest(RequestKind.DISARM, force=True),))
        return out(Setpoint.velocity_ned(float(v[0]), float(v[1]), vz, yaw_rad=self._yaw,
                                         time_s=now))

    def _stalled(self, s: VehicleState, now: float, height: float) -> bool:
        if height < self.params.commit_height_m and abs(float(s.velocity_ned_m_s[2])) < 0.05:
            self._stalled_since = self._stalled_since if self._stalled_since is not None \
                else now
            return now - self._stalled_since > 0.5
        self._stalled_since = None
        return False


def _left_offboard(s: VehicleState) -> str | None:
    """Why the final descent may not cut the motors: the vehicle's own failsafe (or a pilot)
    took over, so it no longer follows the deck and a cut would drop it beside the rover."""
    if s.failsafe or s.mode is not FlightMode.OFFBOARD:
        return (f"the vehicle left offboard control during the final descent ({s.mode.value}"
                f"{', failsafe' if s.failsafe else ''}): motors not cut")
    return None
