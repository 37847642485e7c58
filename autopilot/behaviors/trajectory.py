"""Offboard steps that fly a planned trajectory: ``goto``, ``orbit`` (photos facing the centre)
and ``survey`` (lawnmower over a polygon, photos along the lines) — seed 004's action servers.

Each plans its path when it starts, from where the vehicle is then (:mod:`autopilot.planning`),
puts a speed law on it within ``control.trajectory``'s limits, and then streams the reference:
position, with velocity and acceleration as feed-forward, and heading with its rate. The
vehicle's position controller tracks the reference, not waypoints. When the vehicle falls
behind (a headwind), the reference waits for it instead of running away (it is slowed down as
the along-track lag passes ``lag_slowdown_m``), so the path is flown, not cut.

Photos are asked for where the vehicle actually passes each photo point (its progress along the
path, interpolated between ticks to the moment it crossed); the runtime takes that moment's
frame from the step's camera.

Positions are in a *frame*: ``world`` (the local NED frame; altitudes are heights above its
origin), ``home`` (north/east/altitude from where the vehicle armed) or ``rover`` (north/east
from the rover's deck and altitude above it, where the deck pipeline's estimate puts it when
the step starts — seed 004's rover frame; the step runs that pipeline). ``latlon`` forms give
WGS-84 latitude and longitude, with the altitude above home.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator
from shapely.geometry import Polygon

from autopilot import values
from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    PhotoRequest,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.planning.paths import PathPlan, goto_path, orbit_plan, survey_plan, wrap_pi
from autopilot.planning.trajectory import (
    Limits,
    Path,
    Reference,
    Trajectory,
    YawLaw,
    face_point,
)
from drivers.base import Setpoint

Frame = Literal["world", "home", "rover"]
Speed = Annotated[float, Field(gt=0, le=20)]
NorthEast = tuple[float, float]
LatLon = tuple[Annotated[float, Field(ge=-90, le=90)], Annotated[float, Field(ge=-180, le=180)]]

_NO_ROVER = ("frame: rover, but there is no estimate of the rover yet (no rover report, UWB "
             "range or deck tag heard): fly with frame world or home, or wait for the rover")
_ROVER_LATLON = "latitude/longitude are absolute: frame rover does not apply to them"


class PlanError(ValueError):
    """A step cannot be planned as asked (the frame unknown, the polygon empty, …)."""


def _finite(values, name: str):
    if values is not None and not all(math.isfinite(float(v)) for v in values):
        raise ValueError(f"{name}: every value must be a finite number")
    return values


class GotoParams(Params):
    position_m: tuple[float, float, float] | None = None  # north, east, altitude (in `frame`)
    latlon: tuple[Annotated[float, Field(ge=-90, le=90)],
                  Annotated[float, Field(ge=-180, le=180)], float] | None = None  # + alt over home
    frame: Frame = "world"
    speed_m_s: Speed = 2.0
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] | None = None  # None: keep the heading

    @model_validator(mode="after")
    def _one_target(self) -> GotoParams:
        if (self.position_m is None) == (self.latlon is None):
            raise ValueError("give exactly one of position_m [north, east, altitude] or latlon "
                             "[lat, lon, altitude]")
        _finite(self.position_m, "position_m")
        _finite(self.latlon, "latlon")
        return self


class OrbitParams(Params):
    center_m: NorthEast | None = None  # in `frame`
    center_latlon: LatLon | None = None
    frame: Frame = "world"
    radius_m: Annotated[float, Field(ge=1.0, le=500)] = 3.0
    altitude_m: Annotated[float, Field(gt=0.5, le=500)] = 8.0  # in `frame`
    speed_m_s: Speed = 2.0
    images: Annotated[int, Field(ge=0, le=1000)] = 8  # evenly spaced over all the laps
    laps: Annotated[float, Field(gt=0, le=100)] = 1.0
    direction: Literal["clockwise", "counterclockwise"] = "clockwise"  # seen from above
    start_bearing_deg: Annotated[float, Field(ge=-360, le=360)] | None = None  # entry point
    camera: str | None = None  # the photos' camera (None: photos.camera)
    center_altitude_m: Annotated[float, Field(ge=-100, le=500)] = 0.0  # what the photos are of

    @model_validator(mode="after")
    def _one_center(self) -> OrbitParams:
        if (self.center_m is None) == (self.center_latlon is None):
            raise ValueError("give exactly one of center_m [north, east] or center_latlon "
                             "[lat, lon]")
        _finite(self.center_m, "center_m")
        return self


class SurveyParams(Params):
    polygon_m: list[NorthEast] | None = None  # in `frame`
    polygon_latlon: list[LatLon] | None = None
    holes_m: list[list[NorthEast]] = Field(default_factory=list)  # areas not to cover
    frame: Frame = "world"
    altitude_m: Annotated[float, Field(gt=0.5, le=500)] = 10.0
    #: between lines; None: the camera's footprint across the lines × (1 − side_overlap)
    spacing_m: Annotated[float, Field(gt=0.2, le=500)] | None = None
    side_overlap: Annotated[float, Field(ge=0, lt=0.95)] = 0.6
    photo_spacing_m: Annotated[float, Field(gt=0.1, le=500)] | None = None  # None: spacing_m
    speed_m_s: Speed = 3.0
    angle_deg: Annotated[float, Field(ge=-360, le=360)] | None = None  # None: fewest lines
    smoothing: Literal["bspline", "none"] = "bspline"
    #: each line flown this far beyond its ends, to be level and at speed at its first and last
    #: photo (None: what braking from speed_m_s takes at control.trajectory.accel_m_s2)
    turnaround_m: Annotated[float, Field(ge=0, le=100)] | None = None
    camera: str | None = None  # None: photos.camera

    @model_validator(mode="after")
    def _area(self) -> SurveyParams:
        if (self.polygon_m is None) == (self.polygon_latlon is None):
            raise ValueError("give exactly one of polygon_m [[north, east], ...] or "
                             "polygon_latlon [[lat, lon], ...]")
        corners = self.polygon_m if self.polygon_m is not None else self.polygon_latlon
        if len(corners) < 3:
            raise ValueError(f"a polygon needs at least 3 corners, got {len(corners)}")
        for ring in [self.polygon_m or [], *self.holes_m]:
            for corner in ring:
                _finite(corner, "polygon_m")
        if self.polygon_m is not None:
            area = Polygon(self.polygon_m, self.holes_m)
            if not area.is_valid or area.area <= 0.0:
                from shapely.validation import explain_validity

                raise ValueError(f"polygon_m is not a simple polygon ({explain_validity(area)})")
        return self


@dataclass(frozen=True, slots=True)
class TrajectorySettings:
    limits: Limits  # (its speed_m_s is replaced by the step's)
    yaw_rate_rad_s: float
    rounding_m: float
    lag_slowdown_m: float
    arrival_tolerance_m: float
    settle_timeout_s: float
    #: "ours" (reference + feed-forward, waiting for the vehicle) or "seed004" (seed 004's
    #: tracker, a baseline: a PID on the position error to the time-indexed reference,
    #: commanding velocity, no feed-forward)
    tracker: str = "ours"
    pid: tuple[float, float, float] = (1.5, 0.0, 0.1)


# ------------------------------------------------------------------------------------------
# Frames
# ------------------------------------------------------------------------------------------


def _frame_offset(frame: str, inputs: BehaviorInputs) -> np.ndarray:
    """The NED position of the frame's origin in the local frame."""
    if frame == "rover":
        t = inputs.target
        if t is None or t.kind != "deck" or t.stale or \
                not np.all(np.isfinite(t.position_ned_m)):
            raise PlanError(_NO_ROVER)
        return np.asarray(t.position_ned_m, dtype=float)
    if frame == "home":
        if inputs.home_ned_m is None:
            raise PlanError("frame: home, but the vehicle has not said where home is "
                            "(no HOME_POSITION yet)")
        return np.asarray(inputs.home_ned_m, dtype=float)
    return np.zeros(3)


def _latlon_ne(lat: float, lon: float, inputs: BehaviorInputs) -> np.ndarray:
    origin = inputs.global_origin
    if origin is None:
        raise PlanError("latitude/longitude given, but the vehicle's global origin is not known "
                        "(no GPS_GLOBAL_ORIGIN or HOME_POSITION yet)")
    n, e, _ = origin.to_ned(lat, lon, origin.alt_amsl_m)
    return np.array([n, e])


def _home_down(inputs: BehaviorInputs) -> float:
    return float(inputs.home_ned_m[2]) if inputs.home_ned_m is not None else 0.0


def resolve_point(inputs: BehaviorInputs, frame: str, north_east_alt=None, latlon_alt=None
                  ) -> np.ndarray:
    """A position given in a step's frame (or as lat/lon + altitude over home) in local NED."""
    if latlon_alt is not None:
        if frame == "rover":
            raise PlanError(_ROVER_LATLON)
        ne = _latlon_ne(latlon_alt[0], latlon_alt[1], inputs)
        return np.array([ne[0], ne[1], _home_down(inputs) - latlon_alt[2]])
    off = _frame_offset(frame, inputs)
    n, e, alt = north_east_alt
    return np.array([off[0] + n, off[1] + e, off[2] - alt])


def resolve_ne(inputs: BehaviorInputs, frame: str, north_east=None, latlon=None) -> np.ndarray:
    if latlon is not None:
        if frame == "rover":
            raise PlanError(_ROVER_LATLON)
        return _latlon_ne(latlon[0], latlon[1], inputs)
    off = _frame_offset(frame, inputs)
    return np.array([off[0] + north_east[0], off[1] + north_east[1]])


def resolve_down(inputs: BehaviorInputs, frame: str, altitude_m: float, latlon: bool) -> float:
    """The NED down of an altitude in the frame (over home for lat/lon forms)."""
    if latlon:
        return _home_down(inputs) - altitude_m
    return float(_frame_offset(frame, inputs)[2]) - altitude_m


# ------------------------------------------------------------------------------------------
# The common part: fly a trajectory, take photos on the way
# ------------------------------------------------------------------------------------------


def photo_arc_lengths(traj: Trajectory, points: np.ndarray, tolerance_m: float = 0.1
                      ) -> np.ndarray:
    """Where along the trajectory each photo point is, in order: the first time the path
    passes it after the previous one (an orbit of several laps passes each angle again)."""
    from scipy.spatial import cKDTree

    positions = traj.positions
    tree = cKDTree(positions)
    out = []
    start = 0
    for p in points:
        near = np.array(sorted(i for i in tree.query_ball_point(p, tolerance_m) if i >= start),
                        dtype=int)
        if len(near):  # the first pass by it, at its closest
            breaks = np.flatnonzero(np.diff(near) > 1)
            run = near[:breaks[0] + 1] if len(breaks) else near
            i = int(run[np.argmin(np.linalg.norm(positions[run] - p, axis=1))])
        else:
            i = start + int(np.argmin(np.linalg.norm(positions[start:] - p, axis=1)))
        out.append(float(traj.s_m[i]))
        start = i
    return np.array(out)


def blended_yaw(law: YawLaw, yaw0: float, start: np.ndarray, blend_m: float) -> YawLaw:
    """``law``, but starting from the heading ``yaw0`` and turning onto the law's heading
    smoothly over the first ``blend_m`` of the path."""
    delta = wrap_pi(yaw0 - float(law(np.zeros(1), start[None, :])[0]))

    def yaw(s: np.ndarray, p: np.ndarray) -> np.ndarray:
        base = np.unwrap(law(s, p))
        x = np.clip(1.0 - s / max(blend_m, 1e-6), 0.0, 1.0)
        return base + delta * x * x * (3.0 - 2.0 * x)  # smoothstep: no step in the rate

    return yaw


class FollowTrajectory(Behavior):
    """Plan on activation (:meth:`plan`), then fly the trajectory, taking photos."""

    name = "trajectory"
    #: the photos' camera (None: a step that takes none)
    photo_camera: str | None = None

    def __init__(self, settings: TrajectorySettings) -> None:
        self.settings = settings
        self.trajectory: Trajectory | None = None
        self.plan_: PathPlan | None = None
        self._tau = 0.0
        self._last_tick = 0.0
        self._ended_s: float | None = None
        self._photo_s: np.ndarray = np.zeros(0)
        self._taken = 0
        self._progress_s = 0.0
        self._progress_time = 0.0
        self._pid_int = np.zeros(3)
        self._pid_prev: np.ndarray | None = None

    # -- what a kind says ---------------------------------------------------------------------

    def plan(self, inputs: BehaviorInputs) -> tuple[PathPlan, YawLaw, float]:
        """(the path and its photo points, the heading law, the cruise speed)."""
        raise NotImplementedError

    def phase_at(self, s_m: float) -> str:
        return "flying"

    # -- the lifecycle ------------------------------------------------------------------------

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        if not s.in_air:
            return BehaviorOutput(Status.FAILED, reason="not flying: take off first")
        try:
            plan, yaw_law, speed = self.plan(inputs)
        except ValueError as exc:  # PlanError, or geometry that cannot be flown
            return BehaviorOutput(Status.FAILED, reason=f"cannot plan: {exc}")
        start = np.asarray(s.position_ned_m, dtype=float)
        st = self.settings
        limits = Limits(speed, st.limits.accel_m_s2, st.limits.lateral_accel_m_s2,
                        st.limits.jerk_m_s3, st.limits.climb_speed_m_s,
                        st.limits.descent_speed_m_s)
        self.plan_ = plan
        if float(np.max(np.linalg.norm(plan.points - plan.points[0], axis=1))) < 0.01:
            return BehaviorOutput(Status.SUCCEEDED, reason="already there", progress=1.0)
        path = Path(plan.points)
        # turn onto the law's heading no faster than the yaw-rate limit allows at cruise
        turn = abs(wrap_pi(s.yaw_rad - float(yaw_law(np.zeros(1), start[None, :])[0])))
        blend_m = min(max(turn / st.yaw_rate_rad_s * speed * 1.5, 1.0), path.length_m)
        self.trajectory = Trajectory(path, limits, blended_yaw(yaw_law, s.yaw_rad, start,
                                                               blend_m))
        traj = self.trajectory
        self._photo_s = photo_arc_lengths(traj, plan.photo_points)
        self._tau = 0.0
        self._last_tick = inputs.now_s
        self._progress_s = 0.0
        self._progress_time = s.time_s
        return BehaviorOutput(Status.RUNNING,
                              setpoint=self._setpoint(inputs.now_s, 1.0, self.trajectory.at(0.0)),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase=self.phase_at(0.0), progress=0.0,
                              plan=self.plan_record(speed))

    def plan_record(self, speed: float) -> dict:
        """The plan as the flight log keeps it (what the metrics and the report score the
        flight against): the path every 5 cm, the photo points, the time law every 0.2 s."""
        traj, plan = self.trajectory, self.plan_
        every = max(round(0.2 / (traj.times_s[1] - traj.times_s[0])), 1) \
            if len(traj.times_s) > 1 else 1
        return {"points_ned_m": traj.path.polyline(0.05), "photo_points_ned_m": plan.photo_points,
                "look_at_ned_m": plan.look_at_ned_m,
                "lines": [[list(a), list(b)] for a, b in plan.lines],
                "angle_deg": plan.angle_deg, "speed_m_s": speed,
                "duration_s": traj.duration_s, "length_m": traj.length_m,
                "reference": {"time_s": traj.times_s[::every], "s_m": traj.s_m[::every],
                              "speed_m_s": traj.speed_m_s[::every]},
                **self.plan_extra()}

    def plan_extra(self) -> dict:
        return {}

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        traj, st = self.trajectory, self.settings
        now = inputs.now_s
        dt = min(max(now - self._last_tick, 0.0), 0.5)
        self._last_tick = now
        pos = np.asarray(inputs.state.position_ned_m, dtype=float)
        ref_s = traj.at(self._tau).s_m
        # the vehicle's progress along the path, and the reference waiting for it
        t_near, _ = traj.nearest_time(pos, ref_s, window_m=max(5.0, 3 * st.lag_slowdown_m))
        progress = float(np.interp(t_near, traj.times_s, traj.s_m))
        lag = ref_s - progress
        rate = float(np.clip(1.0 - (lag - st.lag_slowdown_m) / st.lag_slowdown_m, 0.2, 1.0))
        if st.tracker == "seed004":
            rate = 1.0  # (its reference runs on the clock, whatever the vehicle does)
        self._tau = min(self._tau + dt * rate, traj.duration_s)
        photos = self._photos(progress, inputs)
        ref = traj.at(self._tau)
        frac = ref.s_m / traj.length_m if traj.length_m > 0 else 1.0
        setpoint = self._setpoint(now, rate, ref) if st.tracker != "seed004" \
            else self._pid_setpoint(now, dt, pos, ref)
        soon = self._photo_soon(progress, inputs)
        values.publish("path.lag_m", round(lag, 2), "m")
        values.publish("path.off_reference_m",
                       round(float(np.linalg.norm(pos - ref.position_ned_m)), 2), "m")
        if self._tau >= traj.duration_s:
            if self._ended_s is None:
                self._ended_s = now
            miss = float(np.linalg.norm(pos - traj.end))
            if miss <= st.arrival_tolerance_m:
                return BehaviorOutput(Status.SUCCEEDED, setpoint=setpoint, phase="arrived",
                                      photos=photos, progress=1.0, photo_soon=soon)
            if now - self._ended_s > st.settle_timeout_s:
                return BehaviorOutput(Status.FAILED, setpoint=setpoint, photos=photos,
                                      reason=f"end not reached: {miss:.2f} m off after "
                                             f"{st.settle_timeout_s:g} s")
            return BehaviorOutput(Status.RUNNING, setpoint=setpoint, phase="arriving",
                                  photos=photos, progress=frac, photo_soon=soon)
        return BehaviorOutput(Status.RUNNING, setpoint=setpoint, phase=self.phase_at(ref.s_m),
                              photos=photos, progress=frac, photo_soon=soon)

    @staticmethod
    def _setpoint(now: float, rate: float, ref: Reference) -> Setpoint:
        return Setpoint.position_velocity(
            ref.position_ned_m, ref.velocity_ned_m_s * rate,
            acceleration_ned_m_s2=ref.acceleration_ned_m_s2 * rate * rate,
            yaw_rad=wrap_pi(ref.yaw_rad), yaw_rate_rad_s=ref.yaw_rate_rad_s * rate, time_s=now)

    def _pid_setpoint(self, now: float, dt: float, pos: np.ndarray, ref: Reference
                      ) -> Setpoint:
        """Seed 004's tracking: velocity = Kp·e + Ki·∫e + Kd·ė, e = reference − position."""
        kp, ki, kd = self.settings.pid
        err = ref.position_ned_m - pos
        self._pid_int += err * dt
        de = (err - self._pid_prev) / dt if self._pid_prev is not None and dt > 0 \
            else np.zeros(3)
        self._pid_prev = err
        v = kp * err + ki * self._pid_int + kd * de
        return Setpoint.velocity_ned(*v, yaw_rad=wrap_pi(ref.yaw_rad), time_s=now)

    def _photo_soon(self, progress: float, inputs: BehaviorInputs, lead_s: float = 0.6
                    ) -> bool:
        """The next photo point is less than ``lead_s`` away at the present speed (or the
        vehicle is nearly still within a metre of it)."""
        if not self.photo_camera or self._taken >= len(self._photo_s):
            return False
        ahead = float(self._photo_s[self._taken]) - progress
        speed = float(np.linalg.norm(inputs.state.velocity_ned_m_s))
        return ahead <= max(speed * lead_s, 1.0)

    def _photos(self, progress: float, inputs: BehaviorInputs) -> tuple[PhotoRequest, ...]:
        """Photo points the vehicle has passed since the last tick, at the moment it did."""
        t_state = inputs.state.time_s
        out = []
        prev_s, prev_t = self._progress_s, self._progress_time
        while self._taken < len(self._photo_s) and progress >= self._photo_s[self._taken]:
            target = self._photo_s[self._taken]
            f = (target - prev_s) / (progress - prev_s) if progress > prev_s else 1.0
            when = prev_t + float(np.clip(f, 0.0, 1.0)) * (t_state - prev_t)
            point = self.plan_.photo_points[self._taken]
            look = self.plan_.look_at_ned_m
            out.append(PhotoRequest(self._taken, when, self.photo_camera or "",
                                    tuple(float(v) for v in point),
                                    None if look is None else tuple(float(v) for v in look)))
            self._taken += 1
        if progress > self._progress_s:
            self._progress_s, self._progress_time = progress, t_state
        return tuple(out) if self.photo_camera else ()

    @property
    def photos_planned(self) -> int:
        return len(self._photo_s)


# ------------------------------------------------------------------------------------------
# The kinds
# ------------------------------------------------------------------------------------------


class Goto(FollowTrajectory):
    """Fly to a position along a straight line (seed 004's go-to-target)."""

    name = "goto"

    def __init__(self, params: GotoParams, settings: TrajectorySettings) -> None:
        super().__init__(settings)
        self.params = params

    def plan(self, inputs: BehaviorInputs) -> tuple[PathPlan, YawLaw, float]:
        p = self.params
        target = resolve_point(inputs, p.frame, p.position_m, p.latlon)
        start = np.asarray(inputs.state.position_ned_m, dtype=float)
        yaw = inputs.state.yaw_rad if p.yaw_deg is None else math.radians(p.yaw_deg)
        return (PathPlan(goto_path(start, target)),
                lambda s, pts: np.full(len(s), yaw), p.speed_m_s)

    def phase_at(self, s_m: float) -> str:
        return "flying"


class Orbit(FollowTrajectory):
    """Circle a point facing it, taking ``images`` photos at evenly spaced angles (seed 004's
    get-images: ω = v/r, heading = tangent + π/2)."""

    name = "orbit"

    def __init__(self, params: OrbitParams, settings: TrajectorySettings, camera: str) -> None:
        super().__init__(settings)
        self.params = params
        self.photo_camera = camera if params.images > 0 else None
        self._circle = (0.0, 0.0)

    def plan(self, inputs: BehaviorInputs) -> tuple[PathPlan, YawLaw, float]:
        p = self.params
        latlon = p.center_latlon is not None
        center = resolve_ne(inputs, p.frame, p.center_m, p.center_latlon)
        down = resolve_down(inputs, p.frame, p.altitude_m, latlon)
        look_down = resolve_down(inputs, p.frame, p.center_altitude_m, latlon)
        start = np.asarray(inputs.state.position_ned_m, dtype=float)
        bearing = None if p.start_bearing_deg is None else math.radians(p.start_bearing_deg)
        plan = orbit_plan(start, (float(center[0]), float(center[1])), p.radius_m, down,
                          laps=p.laps, clockwise=p.direction == "clockwise", images=p.images,
                          start_bearing_rad=bearing, rounding_m=self.settings.rounding_m)
        plan = PathPlan(plan.points, plan.photo_points,
                        np.array([center[0], center[1], look_down]))
        # where the circle is along the path (for the phase): from the first point on it
        r = np.hypot(plan.points[:, 0] - center[0], plan.points[:, 1] - center[1])
        on = np.flatnonzero(np.abs(r - p.radius_m) < 0.05)
        seg = np.linalg.norm(np.diff(plan.points, axis=0), axis=1)
        s = np.concatenate(([0.0], np.cumsum(seg)))
        self._circle = (float(s[on[0]]), float(s[on[-1]])) if len(on) else (0.0, s[-1])
        return plan, face_point(float(center[0]), float(center[1])), p.speed_m_s

    def plan_extra(self) -> dict:
        return {"radius_m": self.params.radius_m, "altitude_m": self.params.altitude_m}

    def phase_at(self, s_m: float) -> str:
        if s_m < self._circle[0]:
            return "entering"
        return "orbiting" if s_m <= self._circle[1] else "leaving"


class Survey(FollowTrajectory):
    """Lawnmower over a polygon at a height, photos every ``photo_spacing_m`` along the lines
    (seed 004's area coverage, with its B-spline smoothing)."""

    name = "survey"

    def __init__(self, params: SurveyParams, settings: TrajectorySettings, camera: str,
                 spacing_m: float) -> None:
        super().__init__(settings)
        self.params = params
        self.photo_camera = camera
        self.spacing_m = spacing_m
        self._lines_s: list[tuple[float, float]] = []
        self._area: Polygon | None = None

    def plan_extra(self) -> dict:
        area = self._area
        return {"polygon": [list(area.exterior.coords),
                            *[list(h.coords) for h in area.interiors]] if area is not None
                else None, "spacing_m": self.spacing_m, "altitude_m": self.params.altitude_m}

    def area(self, inputs: BehaviorInputs) -> Polygon:
        p = self.params
        if p.polygon_latlon is not None:
            corners = [resolve_ne(inputs, p.frame, latlon=c) for c in p.polygon_latlon]
            holes = [[resolve_ne(inputs, p.frame, c) for c in h] for h in p.holes_m]
        else:
            corners = [resolve_ne(inputs, p.frame, c) for c in p.polygon_m]
            holes = [[resolve_ne(inputs, p.frame, c) for c in h] for h in p.holes_m]
        area = Polygon([tuple(c) for c in corners], [[tuple(c) for c in h] for h in holes])
        if not area.is_valid or area.area <= 0:
            raise PlanError("the survey polygon is not a simple polygon with an area")
        return area

    def plan(self, inputs: BehaviorInputs) -> tuple[PathPlan, YawLaw, float]:
        p = self.params
        area = self.area(inputs)
        self._area = area
        down = resolve_down(inputs, p.frame, p.altitude_m, p.polygon_latlon is not None)
        start = np.asarray(inputs.state.position_ned_m, dtype=float)
        turnaround = p.turnaround_m if p.turnaround_m is not None else \
            p.speed_m_s ** 2 / (2.0 * self.settings.limits.accel_m_s2)
        plan = survey_plan(start, area, down, self.spacing_m,
                           p.photo_spacing_m or self.spacing_m, angle_deg=p.angle_deg,
                           smoothing=p.smoothing, turnaround_m=turnaround)
        # one heading for the whole survey (the footprints stay aligned with the lines): the
        # line direction nearer the present heading
        line_yaw = math.radians(plan.angle_deg)
        if abs(wrap_pi(inputs.state.yaw_rad - line_yaw)) > math.pi / 2:
            line_yaw = wrap_pi(line_yaw + math.pi)
        traj_pts = plan.points
        seg = np.linalg.norm(np.diff(traj_pts, axis=0), axis=1)
        s = np.concatenate(([0.0], np.cumsum(seg)))
        self._lines_s = []
        for a, b in plan.lines:
            ia = int(np.argmin(np.linalg.norm(traj_pts[:, :2] - a, axis=1)))
            ib = int(np.argmin(np.linalg.norm(traj_pts[:, :2] - b, axis=1)))
            self._lines_s.append((float(s[ia]), float(s[ib])))
        return plan, lambda ss, pts: np.full(len(ss), line_yaw), p.speed_m_s

    def phase_at(self, s_m: float) -> str:
        for i, (a, b) in enumerate(self._lines_s):
            if a <= s_m <= b:
                return f"line {i + 1}/{len(self._lines_s)}"
        return "turning" if self._lines_s and s_m > self._lines_s[0][0] else "transit"

