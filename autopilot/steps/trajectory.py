"""The ``goto``, ``orbit`` and ``survey`` step kinds (seed 004's offboard missions).

Their behaviours are in :mod:`autopilot.behaviors.trajectory`. They need no perception; orbit
and survey keep a camera's frames for their photos. Their metrics score the flight against the
plan it logged (``/planning/path``) with the simulator's ground truth:

* ``metrics.path`` (every one): cross-track error — the true position's distance from the
  planned path — RMS, 95th percentile and maximum (3D, and horizontal), the speed along the
  path where the plan cruises, the time flown against the time planned; and ``*_nav_*`` the
  same cross-track error as the vehicle's own navigation saw it (its telemetry positions: the
  tracking the autopilot delivers, which the navigation's error — ``rms_navigation_error_m``,
  telemetry against truth — then moves as a whole);
* ``metrics.orbit``: the radius flown, the photos (how many of ``images``), and where the orbit's
  centre lies in each photo (pixels from the image centre, from the true pose and the camera's
  calibration);
* ``metrics.survey``: ``coverage`` — the share of the polygon's area inside at least one photo's
  footprint (the true poses, the camera's intrinsics and lens, laid on the ground) — the overlap
  between neighbouring photos along a line and between neighbouring lines, the photos.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree
from shapely.geometry import Polygon
from shapely.ops import unary_union

from autopilot.behaviors.base import BehaviorInputs
from autopilot.behaviors.trajectory import Goto, Orbit, Survey
from autopilot.behaviors.trajectory_plan import (
    GotoParams,
    OrbitParams,
    PlanBounds,
    SurveyParams,
    TrajectorySettings,
    check_reach,
    goto_reach,
    orbit_reach,
    survey_reach,
)
from autopilot.config import AppConfig
from autopilot.estimation.pose_history import slerp
from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import camera_intrinsics, project_target, scoring_camera
from autopilot.flightlog.truth import truth_table
from autopilot.planning.footprint import ground_footprint
from autopilot.planning.trajectory import Limits, cross_track_m, resample
from autopilot.status import register_status
from autopilot.steps.registry import Figure, StepContext, StepKind, register
from drivers.camera_model import pinhole

Records = Mapping[str, Sequence[Mapping]]


def plan_bounds(config: AppConfig) -> PlanBounds:
    """What one goto, orbit or survey may plan: control.trajectory's max_path_m and
    max_photos, and failsafe.geofence's distances and heights from home."""
    t, gf = config.control.trajectory, config.failsafe.geofence
    return PlanBounds(t.max_path_m, t.max_photos, gf.max_distance_m or None,
                      gf.max_altitude_m or None, gf.min_altitude_m,
                      tuple(tuple(p) for p in gf.polygon_m) if gf.polygon_m else None)


def trajectory_settings(config: AppConfig) -> TrajectorySettings:
    t = config.control.trajectory
    return TrajectorySettings(bounds=plan_bounds(config),
        limits=Limits(t.max_speed_m_s, t.accel_m_s2, t.lateral_accel_m_s2, t.jerk_m_s3,
                      t.climb_speed_m_s, t.descent_speed_m_s),
        yaw_rate_rad_s=math.radians(t.yaw_rate_deg_s), rounding_m=t.rounding_m,
        lag_slowdown_m=t.lag_slowdown_m, arrival_tolerance_m=t.arrival_tolerance_m,
        settle_timeout_s=t.settle_timeout_s, tracker=t.tracker, pid=tuple(t.seed004_pid))


def _photo_camera(params, config: AppConfig) -> str:
    return params.camera or config.photos.camera


def footprint_m(params, config: AppConfig) -> tuple[float, float]:
    """(across, along) the ground the step's photo camera (its nominal intrinsics, level,
    looking down) sees from the step's altitude: its image's width and height on the ground."""
    cam = config.vehicle.cameras[_photo_camera(params, config)]
    intr = pinhole(cam.width_px, cam.height_px, cam.hfov_deg)
    return (params.altitude_m * intr.width_px / intr.fx,
            params.altitude_m * intr.height_px / intr.fy)


def survey_spacing_m(params: SurveyParams, config: AppConfig) -> float:
    """The survey's line spacing: as given, or the camera's footprint across the lines at the
    survey's height × (1 − side_overlap)."""
    if params.spacing_m is not None:
        return params.spacing_m
    return footprint_m(params, config)[0] * (1.0 - params.side_overlap)


def _check_speed(speed: float, config: AppConfig) -> None:
    top = config.control.trajectory.max_speed_m_s
    if speed > top:
        raise ValueError(f"speed_m_s {speed:g} is above control.trajectory.max_speed_m_s "
                         f"({top:g})")


def _check_frame(frame: str) -> None:
    """Every frame can be planned in; ``rover`` needs the rover's estimate when the step
    starts (the step fails then, clearly, without one)."""


def _frame_pipelines(params, config: AppConfig):
    """frame: rover runs the deck pipeline (the rover's estimate is the frame's origin)."""
    if getattr(params, "frame", "world") != "rover":
        return ()
    from autopilot.perception.deck_pipeline import deck_spec

    return (deck_spec(config),)


def _check_camera(params, config: AppConfig) -> None:
    name = _photo_camera(params, config)
    cam = config.vehicle.cameras.get(name)
    if cam is None or not cam.enabled:
        known = ", ".join(n for n, c in config.vehicle.cameras.items() if c.enabled) or "none"
        raise ValueError(f"camera {name!r} for the photos is not an enabled camera of "
                         f"vehicle.cameras (enabled: {known})")


def _turnaround_m(params: SurveyParams, config: AppConfig) -> float:
    return params.turnaround_m if params.turnaround_m is not None else \
        params.speed_m_s ** 2 / (2.0 * config.control.trajectory.accel_m_s2)


def _goto_reach(params: GotoParams, config: AppConfig, inputs: BehaviorInputs | None) -> None:
    check_reach(goto_reach(params, inputs), plan_bounds(config),
                None if inputs is None else inputs.home_ned_m)


def _orbit_reach(params: OrbitParams, config: AppConfig, inputs: BehaviorInputs | None
                 ) -> None:
    check_reach(orbit_reach(params, inputs), plan_bounds(config),
                None if inputs is None else inputs.home_ned_m)


def _survey_reach(params: SurveyParams, config: AppConfig, inputs: BehaviorInputs | None
                  ) -> None:
    check_reach(survey_reach(params, inputs, survey_spacing_m(params, config),
                             _turnaround_m(params, config)),
                plan_bounds(config), None if inputs is None else inputs.home_ned_m)


def _check_goto(params: GotoParams, config: AppConfig) -> None:
    _check_speed(params.speed_m_s, config)
    _check_frame(params.frame)


def _check_orbit(params: OrbitParams, config: AppConfig) -> None:
    _check_speed(params.speed_m_s, config)
    _check_frame(params.frame)
    if params.images:
        _check_camera(params, config)
    lateral = config.control.trajectory.lateral_accel_m_s2
    need = params.speed_m_s ** 2 / params.radius_m
    if need > lateral * 1.001:
        raise ValueError(
            f"speed_m_s {params.speed_m_s:g} on a {params.radius_m:g} m radius needs "
            f"{need:.2f} m/s² towards the centre, more than control.trajectory."
            f"lateral_accel_m_s2 ({lateral:g}): at most "
            f"{math.sqrt(lateral * params.radius_m):.2f} m/s on this radius")
    _orbit_reach(params, config, None)  # its laps and photos (where: when it flies)
    yaw_rate = config.control.trajectory.yaw_rate_deg_s
    turning = math.degrees(params.speed_m_s / params.radius_m)
    if turning > yaw_rate * 1.001:
        raise ValueError(
            f"speed_m_s {params.speed_m_s:g} on a {params.radius_m:g} m radius turns the "
            f"heading (facing the centre) at {turning:.0f}°/s, more than control.trajectory."
            f"yaw_rate_deg_s ({yaw_rate:g}): at most "
            f"{math.radians(yaw_rate) * params.radius_m:.2f} m/s on this radius")


def centre_in_image(params: OrbitParams, config: AppConfig) -> tuple[float, float] | None:
    """Where the orbit's centre falls in its photos' camera (pixels, on the nominal pinhole),
    the vehicle level and facing it from ``radius_m`` out and its height above the centre;
    None if it is behind the camera."""
    cam = config.vehicle.cameras[_photo_camera(params, config)]
    intr = pinhole(cam.width_px, cam.height_px, cam.hfov_deg)
    pitch, yaw = math.radians(cam.pitch_deg), math.radians(cam.yaw_deg)
    ahead = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                      -math.sin(pitch)])  # the boresight, body FRD
    right = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    down = np.cross(ahead, right)
    centre = np.array([params.radius_m, 0.0, params.altitude_m - params.center_altitude_m])
    z = float(centre @ ahead)
    if z <= 1e-6:
        return None
    return (intr.cx + intr.fx * float(centre @ right) / z,
            intr.cy + intr.fy * float(centre @ down) / z)


def _orbit_warnings(params: OrbitParams, config: AppConfig) -> tuple[str, ...]:
    if not params.images:
        return ()
    camera = _photo_camera(params, config)
    cam = config.vehicle.cameras[camera]
    where = centre_in_image(params, config)
    inside = where is not None and 0 <= where[0] < cam.width_px and 0 <= where[1] < cam.height_px
    if inside:
        return ()
    seen = "behind the camera" if where is None else \
        f"at pixel ({where[0]:.0f}, {where[1]:.0f}) of {cam.width_px}×{cam.height_px}"
    height = params.altitude_m - params.center_altitude_m
    return (f"the centre will not be in the photos: the {camera} camera (pitch "
            f"{cam.pitch_deg:g}°) sees it {seen} from {height:g} m above it at "
            f"{params.radius_m:g} m out; change altitude_m, radius_m or camera "
            "(center_altitude_m: the height of what the photos are of)",)


def _check_survey(params: SurveyParams, config: AppConfig) -> None:
    _check_speed(params.speed_m_s, config)
    _check_frame(params.frame)
    _check_camera(params, config)
    spacing = survey_spacing_m(params, config)
    across, along = footprint_m(params, config)
    if spacing > across:
        raise ValueError(f"spacing_m {spacing:g} is wider than the camera sees across the lines "
                         f"from {params.altitude_m:g} m ({across:.1f} m): the photos would "
                         "leave strips uncovered; lower spacing_m or fly higher")
    photo = params.photo_spacing_m or spacing
    if photo > along:
        raise ValueError(f"photo_spacing_m {photo:g} is longer than the camera sees along the "
                         f"lines from {params.altitude_m:g} m ({along:.1f} m): the photos "
                         "would leave gaps; lower photo_spacing_m (or spacing_m) or fly higher")
    _survey_reach(params, config, None)  # its lines and photos (where: when it flies)


# ------------------------------------------------------------------------------------------
# Metrics
# ------------------------------------------------------------------------------------------


def _plan_record(log: Records, step: Mapping) -> Mapping | None:
    return next((r for r in log.get(ch.PLANNED_PATH, [])
                 if r.get("step_index") == step["index"]), None)


class _Truth:
    def __init__(self, log: Records, start: float, end: float) -> None:
        table = truth_table(log)
        rows = (table.t >= start) & (table.t <= end)
        self.t, self.p, self.v, self.q = table.t[rows], table.p[rows], table.v[rows], \
            table.q[rows]

    def __len__(self) -> int:
        return len(self.t)

    def pose(self, time_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        t = self.t
        if len(t) < 2 or time_s < t[0] or time_s > t[-1]:
            return None
        i = min(int(np.searchsorted(t, time_s, side="right")) - 1, len(t) - 2)
        f = (time_s - t[i]) / (t[i + 1] - t[i]) if t[i + 1] > t[i] else 0.0
        return self.p[i] + f * (self.p[i + 1] - self.p[i]), slerp(self.q[i], self.q[i + 1], f)


def _rms(x) -> float | None:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else None


def path_metrics(log: Records, intervals: list[tuple[float, float]], step: Mapping
                 ) -> tuple[dict, Mapping | None, _Truth | None]:
    plan = _plan_record(log, step)
    if plan is None or not intervals:
        return {}, None, None
    start, end = float(plan["time_s"]), intervals[-1][1]
    truth = _Truth(log, start, end)
    if len(truth) < 2:
        return {}, plan, None
    path = resample(np.array(plan["points_ned_m"], dtype=float), 0.02)
    err3 = cross_track_m(path, truth.p)
    err2 = cross_track_m(path[:, :2], truth.p[:, :2])
    # speed along the path where the plan cruises (the nearest path point's tangent)
    tangents = np.gradient(path, axis=0)
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-9)
    _, nearest = cKDTree(path).query(truth.p)
    along = np.einsum("ij,ij->i", truth.v, tangents[nearest])
    ref = plan.get("reference") or {}
    speed = float(plan.get("speed_m_s") or 0.0)
    cruise = np.zeros(len(truth), dtype=bool)
    if ref.get("s_m") and speed > 0:
        s_ref = np.asarray(ref["s_m"], dtype=float)
        v_ref = np.asarray(ref["speed_m_s"], dtype=float)
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        s_path = np.concatenate(([0.0], np.cumsum(seg)))
        v_at = np.interp(s_path[nearest], s_ref, v_ref)
        cruise = v_at >= 0.95 * speed
    nav = _navigation(log, start, end)
    nav_metrics = {}
    if len(nav[0]) >= 2:
        nav3 = cross_track_m(path, nav[1])
        nav2 = cross_track_m(path[:, :2], nav[1][:, :2])
        true_at = np.stack([np.interp(nav[0], truth.t, truth.p[:, i]) for i in range(3)], axis=1)
        nav_err = np.linalg.norm(nav[1] - true_at, axis=1)
        nav_metrics = {
            "rms_cross_track_nav_m": _rms(nav3),
            "p95_cross_track_nav_m": float(np.percentile(nav3, 95)),
            "max_cross_track_nav_m": float(nav3.max()),
            "rms_horizontal_cross_track_nav_m": _rms(nav2),
            "rms_navigation_error_m": _rms(nav_err),
        }
    out = {
        "rms_cross_track_m": _rms(err3),
        "p95_cross_track_m": float(np.percentile(err3, 95)),
        "max_cross_track_m": float(err3.max()),
        "rms_horizontal_cross_track_m": _rms(err2),
        "max_horizontal_cross_track_m": float(err2.max()),
        "planned_speed_m_s": speed,
        "along_track_speed_mean_m_s": float(along[cruise].mean()) if cruise.any() else None,
        "along_track_speed_std_m_s": float(along[cruise].std()) if cruise.any() else None,
        "flight_time_s": end - start,
        "planned_time_s": plan.get("duration_s"),
        "path_length_m": plan.get("length_m"),
        **nav_metrics,
    }
    return out, plan, truth


def _navigation(log: Records, start: float, end: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, positions) the vehicle reported between ``start`` and ``end`` (finite ones)."""
    times, points = [], []
    for r in log.get(ch.VEHICLE_STATE, []):
        t = r["time_s"]
        p = r.get("position_ned_m")
        if start <= t <= end and p is not None and all(
                v is not None and math.isfinite(v) for v in p):
            times.append(t)
            points.append(p)
    return np.array(times, dtype=float), np.array(points, dtype=float).reshape(-1, 3)


def _photos_of(log: Records, step: Mapping) -> list[Mapping]:
    return [r for r in log.get(ch.PHOTOS, []) if r.get("step_index") == step["index"]]


def _camera(log: Records, name: str) -> Mapping | None:
    return scoring_camera(log, name)


def orbit_metrics(log: Records, intervals: list[tuple[float, float]], step: Mapping) -> dict:
    path, plan, truth = path_metrics(log, intervals, step)
    if plan is None or truth is None:
        return {}
    params = step["params"]
    photos = _photos_of(log, step)
    look = plan.get("look_at_ned_m")
    offsets, in_frame = [], 0  # per photo: pixels from the image centre (inf: behind)
    for photo in photos:
        cam = _camera(log, photo["camera"])
        pose = truth.pose(photo["time_s"])
        if cam is None or pose is None or look is None:
            continue
        seen = project_target(cam, pose[0], pose[1], look, 0.0)
        if seen is None:  # behind the camera
            offsets.append(math.inf)
            continue
        u, v, _ = seen
        offsets.append(math.hypot(u - cam["cx"], v - cam["cy"]))
        in_frame += 0 <= u <= cam["width_px"] - 1 and 0 <= v <= cam["height_px"] - 1
    radius = None
    if look is not None and photos:
        t0, t1 = photos[0]["time_s"], photos[-1]["time_s"]
        on = (truth.t >= t0) & (truth.t <= t1)
        if on.any():
            r = np.hypot(truth.p[on, 0] - look[0], truth.p[on, 1] - look[1])
            radius = {"radius_mean_m": float(r.mean()),
                      "radius_rms_error_m": _rms(r - params["radius_m"])}
            # ... and as the vehicle's navigation had it (the centre is given in its frame)
            nav_t, nav_p = _navigation(log, t0, t1)
            if len(nav_t):
                r = np.hypot(nav_p[:, 0] - look[0], nav_p[:, 1] - look[1])
                radius["radius_rms_error_nav_m"] = _rms(r - params["radius_m"])
    finite = [o for o in offsets if math.isfinite(o)]
    orbit = {
        **path,
        "photos": len(photos),
        "images_planned": int(params.get("images", 0)),
        "photos_with_gps": sum(1 for p in photos if p.get("lat_deg") is not None),
        "centre_in_frame": in_frame,
        "centre_offset_px_mean": float(np.mean(finite)) if finite else None,
        "centre_offset_px_max": max(offsets) if offsets else None,
        "centre_offset_px": [round(o, 1) if math.isfinite(o) else None for o in offsets],
        **(radius or {}),
    }
    return {"orbit": orbit}


def _footprints(log: Records, photos: Sequence[Mapping], truth: _Truth, ground_down_m: float
                ) -> list[Polygon | None]:
    out = []
    for photo in photos:
        cam = _camera(log, photo["camera"])
        pose = truth.pose(photo["time_s"])
        if cam is None or pose is None:
            out.append(None)
            continue
        outline = ground_footprint(camera_intrinsics(cam), np.array(cam["rotation_body_cam"]),
                                   np.array(cam["position_body_m"]), pose[0], pose[1],
                                   ground_down_m)
        out.append(Polygon(outline).buffer(0) if outline is not None else None)
    return out


def survey_metrics(log: Records, intervals: list[tuple[float, float]], step: Mapping) -> dict:
    path, plan, truth = path_metrics(log, intervals, step)
    if plan is None or truth is None or not plan.get("polygon"):
        return {}
    rings = plan["polygon"]
    area = Polygon(rings[0], rings[1:]).buffer(0)
    photos = _photos_of(log, step)
    feet = _footprints(log, photos, truth, 0.0)
    valid = [f for f in feet if f is not None and not f.is_empty]
    covered = unary_union(valid).intersection(area).area if valid else 0.0
    # which line each photo was planned on: the nearest of the plan's lines
    lines = [np.array(line, dtype=float)[:, :2] for line in plan.get("lines", [])]

    def line_of(photo) -> int:
        p = np.asarray(photo["planned_ned_m"][:2], dtype=float)
        dist = []
        for a, b in lines:
            ab = b - a
            f = float(np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-12), 0.0, 1.0))
            dist.append(float(np.linalg.norm(a + f * ab - p)))
        return int(np.argmin(dist)) if dist else 0

    by_line: dict[int, list[Polygon]] = {}
    forward = []
    for photo, foot in zip(photos, feet, strict=True):
        if foot is None:
            continue
        k = line_of(photo)
        group = by_line.setdefault(k, [])
        if group and group[-1].area > 0:
            forward.append(group[-1].intersection(foot).area / group[-1].area)
        group.append(foot)
    side = []
    if len(lines) > 1 and by_line:
        # neighbouring strips (a strip over a concave polygon holds several lines): the share
        # of one strip's photo footprints that the next strip's photos also cover
        angle = math.radians(plan.get("angle_deg") or 0.0)
        normal = np.array([-math.sin(angle), math.cos(angle)])
        step = float(plan.get("spacing_m") or 1.0)
        offsets = {k: float(np.dot(lines[k].mean(axis=0), normal)) for k in by_line}
        first = min(offsets.values())
        strips: dict[int, list[Polygon]] = {}
        for k, feet in by_line.items():  # (strips are spacing_m apart: count them)
            strips.setdefault(round((offsets[k] - first) / step), []).extend(feet)
        ordered = sorted(strips)
        for a, b in itertools.pairwise(ordered):
            if b - a != 1:
                continue
            ua, ub = unary_union(strips[a]), unary_union(strips[b])
            if ua.area > 0:
                side.append(ua.intersection(ub).area / ua.area)
    survey = {
        **path,
        "coverage": covered / area.area if area.area > 0 else None,
        "area_m2": area.area,
        "photos": len(photos),
        "photos_planned": len(plan.get("photo_points_ned_m") or []),
        "photos_with_gps": sum(1 for p in photos if p.get("lat_deg") is not None),
        "lines": len(lines),
        "spacing_m": plan.get("spacing_m"),
        "forward_overlap_mean": float(np.mean(forward)) if forward else None,
        "forward_overlap_min": float(np.min(forward)) if forward else None,
        "side_overlap_mean": float(np.mean(side)) if side else None,
        "side_overlap_min": float(np.min(side)) if side else None,
    }
    return {"survey": survey}


def goto_metrics(log: Records, intervals: list[tuple[float, float]], step: Mapping) -> dict:
    path, plan, truth = path_metrics(log, intervals, step)
    if plan is None or truth is None:
        return {}
    end = np.array(plan["points_ned_m"][-1], dtype=float)
    out = {**path, "final_error_m": float(np.linalg.norm(truth.p[-1] - end))}
    # where the vehicle's navigation put it at the end (the goal is given in its frame)
    nav_t, nav_p = _navigation(log, float(plan["time_s"]), intervals[-1][1])
    if len(nav_t):
        out["final_error_nav_m"] = float(np.linalg.norm(nav_p[-1] - end))
    return {"goto": out}


# ------------------------------------------------------------------------------------------
# Registration
# ------------------------------------------------------------------------------------------


def _goto(params: GotoParams, ctx: StepContext) -> Goto:
    return Goto(params, trajectory_settings(ctx.config), ctx.offload)


def _orbit(params: OrbitParams, ctx: StepContext) -> Orbit:
    return Orbit(params, trajectory_settings(ctx.config), _photo_camera(params, ctx.config),
                 ctx.offload)


def _survey(params: SurveyParams, ctx: StepContext) -> Survey:
    return Survey(params, trajectory_settings(ctx.config), _photo_camera(params, ctx.config),
                  survey_spacing_m(params, ctx.config), ctx.offload)


def _survey_info(params: SurveyParams, config: AppConfig) -> dict:
    return {"spacing_m": survey_spacing_m(params, config),
            "footprint_m": list(footprint_m(params, config))}


#: the status codes of seed 005's protocol (the same numbers and labels)
GOTO_CODES = (register_status(4, "goto in progress"), register_status(5, "goto completed"))
ORBIT_CODES = (register_status(6, "images in progress"), register_status(7, "images completed"))
SURVEY_CODES = (register_status(10, "coverage in progress"),
                register_status(11, "coverage completed"))


def _frame_needs(params) -> tuple[str, ...]:
    return ("rover_link",) if getattr(params, "frame", "world") == "rover" else ()


def _goto_needs(params, config: AppConfig) -> tuple[str, ...]:
    return (("global_position",) if params.latlon is not None else ()) + _frame_needs(params)


def _orbit_needs(params, config: AppConfig) -> tuple[str, ...]:
    # geotagged photos, or a centre on Earth
    on_earth = params.images or params.center_latlon is not None
    return (("global_position",) if on_earth else ()) + _frame_needs(params)


def _survey_needs(params, config: AppConfig) -> tuple[str, ...]:
    return ("global_position", *_frame_needs(params))  # its photos are geotagged

register(StepKind(
    "goto", GotoParams, _goto, check=_check_goto, metrics=goto_metrics, reach=_goto_reach,
    summary=((Figure("goto", "final_error_m", "final position error", "m"),
              Figure("goto", "rms_cross_track_m", "cross-track error RMS", "m"),
              Figure("goto", "rms_cross_track_nav_m", "as navigation saw it RMS", "m")),),
    pipelines=_frame_pipelines, needs=_goto_needs,
    report=("trajectory", "path"), status=GOTO_CODES,
    description="fly a straight line to position_m (or latlon) at speed_m_s"))
register(StepKind(
    "orbit", OrbitParams, _orbit, check=_check_orbit, metrics=orbit_metrics, reach=_orbit_reach,
    warnings=_orbit_warnings, example={"center_m": [6, 0], "radius_m": 3, "images": 8},
    summary=((Figure("orbit", "rms_cross_track_m", "cross-track error RMS", "m"),
              Figure("orbit", "max_cross_track_m", "max", "m"),
              Figure("orbit", "rms_cross_track_nav_m", "as navigation saw it RMS", "m"),
              Figure("orbit", "rms_navigation_error_m", "navigation error RMS", "m"),
              Figure("orbit", "photos", "photos"), Figure("orbit", "images_planned", "of"),
              Figure("orbit", "centre_in_frame", "with the centre in frame")),),
    pipelines=_frame_pipelines, needs=_orbit_needs,
    report=("trajectory", "path"), status=ORBIT_CODES,
    photo_camera=lambda params, config: _photo_camera(params, config) if params.images
    else None,
    description="circle center_m at radius_m facing it, taking `images` photos"))
register(StepKind(
    "survey", SurveyParams, _survey, check=_check_survey, metrics=survey_metrics,
    summary=((Figure("survey", "rms_cross_track_m", "cross-track error RMS", "m"),
              Figure("survey", "max_cross_track_m", "max", "m"),
              Figure("survey", "rms_cross_track_nav_m", "as navigation saw it RMS", "m"),
              Figure("survey", "rms_navigation_error_m", "navigation error RMS", "m"),
              Figure("survey", "coverage", "coverage", "%"),
              Figure("survey", "photos", "photos"), Figure("survey", "photos_planned", "of")),),
    reach=_survey_reach, needs=_survey_needs,
    pipelines=_frame_pipelines,
    report=("trajectory", "path"), status=SURVEY_CODES, photo_camera=_photo_camera,
    plan_info=_survey_info,
    description="lawnmower over polygon_m at altitude_m, photos every photo_spacing_m"))

__all__ = ["footprint_m", "survey_spacing_m", "trajectory_settings"]
