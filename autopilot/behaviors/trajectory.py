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
WGS-84 latitude and longitude, with the altitude above home. The parameters, frames and
plan bounds are :mod:`autopilot.behaviors.trajectory_plan`'s.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from concurrent.futures import Future

import numpy as np
from shapely.geometry import Polygon

from autopilot import values
from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    PhotoRequest,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.behaviors.trajectory_plan import (
    GotoParams,
    Offload,
    OrbitParams,
    PlanError,
    Reach,
    SurveyParams,
    TrajectorySettings,
    check_reach,
    from_here,
    goto_reach,
    orbit_reach,
    resolve_down,
    resolve_ne,
    resolve_point,
    survey_reach,
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


def photo_arc_lengths(traj: Trajectory, points: np.ndarray, tolerance_m: float = 0.1
                      ) -> np.ndarray:
    """Where along the trajectory each photo point is, in order: the first time the path
    passes it after the previous one (an orbit of several laps passes each angle again)."""
    from scipy.spatial import cKDTree

    positions = traj.positions
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(points):
        return np.zeros(0)
    tree = cKDTree(positions)
    out = []
    start = 0
    for p, ball in zip(points, tree.query_ball_point(points, tolerance_m), strict=True):
        near = sorted(i for i in ball if i >= start)
        if near:  # the first pass by it, at its closest
            end = 1
            while end < len(near) and near[end] == near[end - 1] + 1:
                end += 1
            run = near[:end]
            i = run[int(np.argmin(np.sum((positions[run] - p) ** 2, axis=1)))]
        else:
            i = start + int(np.argmin(np.sum((positions[start:] - p) ** 2, axis=1)))
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
    #: what planning sets on the behaviour besides the plan (brought back from a worker)
    _plan_state: tuple[str, ...] = ()

    def __init__(self, settings: TrajectorySettings, offload: Offload | None = None) -> None:
        self.settings = settings
        #: plans off the control loop (real time); None: at once, on the caller's thread
        #: (lockstep: the same plan at the same simulated moment, every run)
        self._offload = offload
        self._pending: Future | None = None
        self._hold: Setpoint | None = None
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

    def reach(self, inputs: BehaviorInputs) -> Reach:
        """Where it would fly, before planning (checked against the bounds first)."""
        raise NotImplementedError

    def phase_at(self, s_m: float) -> str:
        return "flying"

    # -- the lifecycle ------------------------------------------------------------------------

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        if not s.in_air:
            return BehaviorOutput(Status.FAILED, reason="not flying: take off first")
        if self._offload is None:
            try:
                prepared = self._prepare(inputs)
            except ValueError as exc:  # PlanError, or geometry that cannot be flown
                return BehaviorOutput(Status.FAILED, reason=f"cannot plan: {exc}")
            return self._begin(prepared, inputs)
        # planned by a worker: the vehicle holds where it is meanwhile (the control loop
        # never waits for a plan, however long)
        self._hold = Setpoint.position_velocity(
            np.asarray(s.position_ned_m, dtype=float), np.zeros(3), yaw_rad=s.yaw_rad,
            time_s=inputs.now_s)
        # (a worker process gets a copy of the behaviour and what planning reads of inputs)
        self._pending = self._offload(functools.partial(
            self._prepare, dataclasses.replace(inputs, percept=None, percepts=())))
        return BehaviorOutput(Status.RUNNING, setpoint=self._hold,
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase="planning", progress=0.0)

    def _prepare(self, inputs: BehaviorInputs) -> tuple:
        """The bounds checked, then the plan, its trajectory, its photos' places and its record
        (all of the planning's work: a worker may run it)."""
        st = self.settings
        reach = self.reach(inputs)
        check_reach(reach, st.bounds, inputs.home_ned_m)
        plan, yaw_law, speed = self.plan(inputs)
        # ... and the plan itself (the way in and the turns as planned)
        pts = np.asarray(plan.points, dtype=float)
        length = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
        check_reach(Reach(np.vstack([pts[::max(len(pts) // 5000, 1)], pts[-1:]]),
                          reach.place_key, reach.altitude_key, length, reach.path_key,
                          len(plan.photo_points), reach.photos_key),
                    from_here(st.bounds, pts[0], inputs.home_ned_m), inputs.home_ned_m)
        state = {name: getattr(self, name) for name in self._plan_state}
        if float(np.max(np.linalg.norm(pts - pts[0], axis=1))) < 0.01:
            return plan, None, np.zeros(0), None, state
        start = np.asarray(inputs.state.position_ned_m, dtype=float)
        limits = Limits(speed, st.limits.accel_m_s2, st.limits.lateral_accel_m_s2,
                        st.limits.jerk_m_s3, st.limits.climb_speed_m_s,
                        st.limits.descent_speed_m_s)
        path = Path(pts)
        # turn onto the law's heading no faster than the yaw-rate limit allows at cruise
        yaw0 = inputs.state.yaw_rad
        turn = abs(wrap_pi(yaw0 - float(yaw_law(np.zeros(1), start[None, :])[0])))
        blend_m = min(max(turn / st.yaw_rate_rad_s * speed * 1.5, 1.0), path.length_m)
        traj = Trajectory(path, limits, blended_yaw(yaw_law, yaw0, start, blend_m))
        photo_s = photo_arc_lengths(traj, plan.photo_points)
        return plan, traj, photo_s, self._plan_record(plan, traj, speed), state

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()  # (to a worker: not its executor, nor a pending plan)
        state.update(_offload=None, _pending=None)
        return state

    def _begin(self, prepared: tuple, inputs: BehaviorInputs) -> BehaviorOutput:
        plan, traj, photo_s, record, state = prepared
        for name, value in state.items():
            setattr(self, name, value)
        self.plan_ = plan
        if traj is None:
            return BehaviorOutput(Status.SUCCEEDED, reason="already there", progress=1.0)
        self.trajectory = traj
        self._photo_s = photo_s
        self._tau = 0.0
        self._last_tick = inputs.now_s
        self._progress_s = 0.0
        self._progress_time = inputs.state.time_s
        return BehaviorOutput(Status.RUNNING,
                              setpoint=self._setpoint(inputs.now_s, 1.0, traj.at(0.0)),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase=self.phase_at(0.0), progress=0.0, plan=record)

    def _waiting(self, inputs: BehaviorInputs) -> BehaviorOutput:
        """While the worker plans: hold, and begin once the plan is there."""
        if not self._pending.done():
            return BehaviorOutput(Status.RUNNING, setpoint=dataclasses.replace(
                self._hold, time_s=inputs.now_s), phase="planning", progress=0.0)
        pending, self._pending = self._pending, None
        try:
            prepared = pending.result()
        except ValueError as exc:
            return BehaviorOutput(Status.FAILED, setpoint=self._hold,
                                  reason=f"cannot plan: {exc}")
        return self._begin(prepared, inputs)

    def plan_record(self, speed: float) -> dict:
        return self._plan_record(self.plan_, self.trajectory, speed)

    def _plan_record(self, plan: PathPlan, traj: Trajectory, speed: float) -> dict:
        """The plan as the flight log keeps it (what the metrics and the report score the
        flight against): the path every 5 cm (at most 20,000 points: a longer path less
        densely), the photo points, the time law every 0.2 s."""
        every = max(round(0.2 / (traj.times_s[1] - traj.times_s[0])), 1,
                    len(traj.times_s) // 5000) if len(traj.times_s) > 1 else 1
        step_m = max(0.05, traj.length_m / 20_000)
        return {"points_ned_m": traj.path.polyline(step_m),
                "photo_points_ned_m": plan.photo_points,
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
        if self._pending is not None:
            return self._waiting(inputs)
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

    def __init__(self, params: GotoParams, settings: TrajectorySettings,
                 offload: Offload | None = None) -> None:
        super().__init__(settings, offload)
        self.params = params

    def reach(self, inputs: BehaviorInputs) -> Reach:
        return goto_reach(self.params, inputs)

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
    _plan_state = ("_circle",)

    def __init__(self, params: OrbitParams, settings: TrajectorySettings, camera: str,
                 offload: Offload | None = None) -> None:
        super().__init__(settings, offload)
        self.params = params
        self.photo_camera = camera if params.images > 0 else None
        self._circle = (0.0, 0.0)

    def reach(self, inputs: BehaviorInputs) -> Reach:
        return orbit_reach(self.params, inputs)

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
    _plan_state = ("_lines_s", "_area")

    def __init__(self, params: SurveyParams, settings: TrajectorySettings, camera: str,
                 spacing_m: float, offload: Offload | None = None) -> None:
        super().__init__(settings, offload)
        self.params = params
        self.photo_camera = camera
        self.spacing_m = spacing_m
        self._lines_s: list[tuple[float, float]] = []
        self._area: Polygon | None = None

    @property
    def turnaround_m(self) -> float:
        p = self.params
        return p.turnaround_m if p.turnaround_m is not None else \
            p.speed_m_s ** 2 / (2.0 * self.settings.limits.accel_m_s2)

    def reach(self, inputs: BehaviorInputs) -> Reach:
        return survey_reach(self.params, inputs, self.spacing_m, self.turnaround_m)

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
        plan = survey_plan(start, area, down, self.spacing_m,
                           p.photo_spacing_m or self.spacing_m, angle_deg=p.angle_deg,
                           smoothing=p.smoothing, turnaround_m=self.turnaround_m)
        # one heading for the whole survey (the footprints stay aligned with the lines): the
        # line direction nearer the present heading
        line_yaw = math.radians(plan.angle_deg)
        if abs(wrap_pi(inputs.state.yaw_rad - line_yaw)) > math.pi / 2:
            line_yaw = wrap_pi(line_yaw + math.pi)
        traj_pts = plan.points
        seg = np.linalg.norm(np.diff(traj_pts, axis=0), axis=1)
        s = np.concatenate(([0.0], np.cumsum(seg)))
        self._lines_s = []
        if plan.lines:
            from scipy.spatial import cKDTree

            ends = np.array([[a, b] for a, b in plan.lines], dtype=float).reshape(-1, 2)
            _, nearest = cKDTree(traj_pts[:, :2]).query(ends)
            self._lines_s = [(float(s[ia]), float(s[ib]))
                             for ia, ib in nearest.reshape(-1, 2).tolist()]
        return plan, lambda ss, pts: np.full(len(ss), line_yaw), p.speed_m_s

    def phase_at(self, s_m: float) -> str:
        for i, (a, b) in enumerate(self._lines_s):
            if a <= s_m <= b:
                return f"line {i + 1}/{len(self._lines_s)}"
        return "turning" if self._lines_s and s_m > self._lines_s[0][0] else "transit"

