"""What a trajectory step (goto, orbit, survey) asks, and where it may fly: the parameter
models, the frames its positions are in (world, home, rover; latitude/longitude), the plan
bounds and the geofence its path is checked against before it starts (a goal before it is
accepted), and the errors that say which key and which limit."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator
from shapely.geometry import Polygon

from autopilot.behaviors.base import (
    BehaviorInputs,
    Params,
)
from autopilot.planning.trajectory import (
    Limits,
)

Frame = Literal["world", "home", "rover"]
Speed = Annotated[float, Field(gt=0, le=20)]
NorthEast = tuple[float, float]
LatLon = tuple[Annotated[float, Field(ge=-90, le=90)], Annotated[float, Field(ge=-180, le=180)]]

_NO_ROVER = ("frame: rover, but there is no estimate of the rover yet (no rover report, UWB "
             "range or deck tag heard): fly with frame world or home, or wait for the rover")
_ROVER_LATLON = "latitude/longitude are absolute: frame rover does not apply to them"


class PlanError(ValueError):
    """A step cannot be planned as asked (the frame unknown, the polygon empty, …)."""


class LimitError(PlanError):
    """A step beyond a limit (its path too long, too many photos, outside the geofence):
    ``key`` names the parameter that puts it there."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key

    def __reduce__(self):  # (raised in a planning worker process, re-raised here)
        return type(self), (self.key, str(self))


#: runs a planning job off the control loop (a worker process): the job → its future
Offload = Callable[[Callable[[], object]], Future]


def _finite(values, name: str):
    if values is not None and not all(math.isfinite(float(v)) for v in values):
        raise ValueError(f"{name}: every value must be a finite number")
    return values


class GotoParams(Params):
    position_m: tuple[float, float, float] | None = None
    """Where to go: [north, east, altitude] in ``frame``. Give this or ``latlon``."""
    latlon: tuple[Annotated[float, Field(ge=-90, le=90)],
                  Annotated[float, Field(ge=-180, le=180)], float] | None = None
    """Where to go: [latitude, longitude] (WGS-84, degrees) and the altitude above home. Give
    this or ``position_m``."""
    frame: Frame = "world"
    """What ``position_m`` is measured from: ``world`` (the local NED frame, altitudes above
    its origin), ``home`` (from where the vehicle armed) or ``rover`` (from the rover's deck,
    where its estimate puts it when the step starts)."""
    speed_m_s: Speed = 2.0
    """Cruise speed along the line (within ``control.trajectory``'s limits)."""
    yaw_deg: Annotated[float, Field(ge=-360, le=360)] | None = None
    """The heading to fly at (degrees from north, towards east); None: keep the heading."""

    @model_validator(mode="after")
    def _one_target(self) -> GotoParams:
        if (self.position_m is None) == (self.latlon is None):
            raise ValueError("give exactly one of position_m [north, east, altitude] or latlon "
                             "[lat, lon, altitude]")
        _finite(self.position_m, "position_m")
        _finite(self.latlon, "latlon")
        return self


class OrbitParams(Params):
    center_m: NorthEast | None = None
    """The centre: [north, east] in ``frame``. Give this or ``center_latlon``."""
    center_latlon: LatLon | None = None
    """The centre: [latitude, longitude] (WGS-84, degrees). Give this or ``center_m``."""
    frame: Frame = "world"
    """What ``center_m`` and the altitudes are measured from: ``world`` (the local NED frame,
    altitudes above its origin), ``home`` (from where the vehicle armed) or ``rover`` (from the
    rover's deck, where its estimate puts it when the step starts)."""
    radius_m: Annotated[float, Field(ge=1.0, le=500)] = 3.0
    """The circle's radius (the path's joins are rounded; the circle itself is flown at this
    radius)."""
    altitude_m: Annotated[float, Field(gt=0.5, le=500)] = 8.0
    """The height to circle at, in ``frame`` (above home for ``center_latlon``)."""
    speed_m_s: Speed = 2.0
    """Cruise speed along the circle (slower where ``control.trajectory`` limits the lateral
    acceleration)."""
    images: Annotated[int, Field(ge=0, le=1000)] = 8
    """How many photos, evenly spaced over all the laps, each facing the centre."""
    laps: Annotated[float, Field(gt=0, le=100)] = 1.0
    """How many times round (a fraction flies part of a lap)."""
    direction: Literal["clockwise", "counterclockwise"] = "clockwise"
    """The way round, seen from above (clockwise: from north towards east)."""
    start_bearing_deg: Annotated[float, Field(ge=-360, le=360)] | None = None
    """Where the circle is entered: the bearing of the entry point from the centre (degrees
    from north, towards east); None: where the tangent from the vehicle's position touches the
    circle."""
    camera: str | None = None
    """The camera the photos are taken with; None: ``photos.camera`` (config.yaml)."""
    center_altitude_m: Annotated[float, Field(ge=-100, le=500)] = 0.0
    """The height of what the photos are of, in the step's ``frame`` (above home for
    ``center_latlon``): the point at the centre the camera looks at."""

    @model_validator(mode="after")
    def _one_center(self) -> OrbitParams:
        if (self.center_m is None) == (self.center_latlon is None):
            raise ValueError("give exactly one of center_m [north, east] or center_latlon "
                             "[lat, lon]")
        _finite(self.center_m, "center_m")
        return self


class SurveyParams(Params):
    polygon_m: list[NorthEast] | None = None
    """The area to cover: its corners, [[north, east], ...] in ``frame`` (at least 3; concave
    is fine). Give this or ``polygon_latlon``."""
    polygon_latlon: list[LatLon] | None = None
    """The area to cover: its corners as [[latitude, longitude], ...] (WGS-84, degrees). Give
    this or ``polygon_m``."""
    holes_m: list[list[NorthEast]] = Field(default_factory=list)
    """Areas inside the polygon not to cover, each a list of corners like ``polygon_m``."""
    frame: Frame = "world"
    """What ``polygon_m`` and ``altitude_m`` are measured from: ``world`` (the local NED frame,
    altitudes above its origin), ``home`` (from where the vehicle armed) or ``rover`` (from the
    rover's deck, where its estimate puts it when the step starts)."""
    altitude_m: Annotated[float, Field(gt=0.5, le=500)] = 10.0
    """The height to fly the lines at, in ``frame`` (above home for ``polygon_latlon``)."""
    spacing_m: Annotated[float, Field(gt=0.2, le=500)] | None = None
    """Distance between neighbouring lines; None: the camera's footprint across the lines ×
    (1 − ``side_overlap``)."""
    side_overlap: Annotated[float, Field(ge=0, lt=0.95)] = 0.6
    """The share of a photo's footprint neighbouring lines overlap by, when ``spacing_m`` is
    None."""
    photo_spacing_m: Annotated[float, Field(gt=0.1, le=500)] | None = None
    """The greatest distance between photos along a line (they are spaced evenly, the line's
    ends included); None: ``spacing_m``."""
    speed_m_s: Speed = 3.0
    """Cruise speed along the lines (slower in the turns)."""
    angle_deg: Annotated[float, Field(ge=-360, le=360)] | None = None
    """The lines' direction (degrees from north, towards east); None: the direction that needs
    the fewest lines."""
    smoothing: Literal["bspline", "none"] = "bspline"
    """``bspline``: turns between lines are smooth B-splines (no jerk entering or leaving
    them); ``none``: stop and turn at the corners."""
    turnaround_m: Annotated[float, Field(ge=0, le=100)] | None = None
    """Each line is flown this far beyond its ends, to be level and at speed at its first and
    last photo; None: what braking from ``speed_m_s`` takes at
    ``control.trajectory.accel_m_s2``."""
    camera: str | None = None
    """The camera the photos are taken with; None: ``photos.camera`` (config.yaml)."""

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
    bounds: PlanBounds = field(default_factory=lambda: PlanBounds())


@dataclass(frozen=True, slots=True)
class PlanBounds:
    """What one step may plan: checked before it is planned (and a goal before it is
    accepted). Heights and distances are from home; None: that bound is off."""

    max_path_m: float = 10_000.0  # control.trajectory.max_path_m
    max_photos: int = 2000  # control.trajectory.max_photos
    max_distance_m: float | None = None  # failsafe.geofence.max_distance_m (horizontal)
    max_altitude_m: float | None = None  # failsafe.geofence.max_altitude_m
    min_altitude_m: float | None = None  # failsafe.geofence.min_altitude_m
    polygon_ne_m: tuple[tuple[float, float], ...] | None = None  # failsafe.geofence.polygon_m


@dataclass(frozen=True, slots=True, eq=False)
class Reach:
    """Where a step would fly, worked out before planning it: the points that bound it (local
    NED; None: its frame cannot be resolved yet), the keys that put them there, the length of
    its path (the way in included when the start is known) and its photos."""

    points_ned_m: np.ndarray | None
    place_key: str  # e.g. "center_m" (what puts the points where they are)
    altitude_key: str  # e.g. "altitude_m"
    path_m: float
    path_key: str  # e.g. "laps" (what makes the path long)
    photos: int = 0
    photos_key: str = "images"


def check_reach(reach: Reach, bounds: PlanBounds, home_ned_m: np.ndarray | None) -> None:
    """Raise :class:`LimitError` naming the key and the limit when ``reach`` is beyond
    ``bounds`` (the geofence's limits are from ``home_ned_m``; unknown: the local origin)."""
    _check_fence(reach, bounds, home_ned_m)
    if reach.path_m > bounds.max_path_m:
        raise LimitError(reach.path_key, f"the path would be {reach.path_m:,.0f} m long, more "
                         f"than control.trajectory.max_path_m ({bounds.max_path_m:g})")
    if reach.photos > bounds.max_photos:
        raise LimitError(reach.photos_key, f"{reach.photos:,} photos planned, more than "
                         f"control.trajectory.max_photos ({bounds.max_photos})")


def _check_fence(reach: Reach, bounds: PlanBounds, home_ned_m: np.ndarray | None) -> None:
    pts = reach.points_ned_m
    if pts is None or not len(pts):
        return
    home = np.zeros(3) if home_ned_m is None else np.asarray(home_ned_m, dtype=float)
    rel = np.asarray(pts, dtype=float).reshape(-1, 3) - home
    far = float(np.max(np.hypot(rel[:, 0], rel[:, 1])))
    if bounds.max_distance_m and far > bounds.max_distance_m * 1.0001:
        raise LimitError(reach.place_key, f"it would fly {far:,.1f} m from home, beyond "
                         f"failsafe.geofence.max_distance_m ({bounds.max_distance_m:g})")
    high, low = float(np.max(-rel[:, 2])), float(np.min(-rel[:, 2]))
    if bounds.max_altitude_m and high > bounds.max_altitude_m * 1.0001:
        raise LimitError(reach.altitude_key, f"it would fly {high:.1f} m above home, above "
                         f"failsafe.geofence.max_altitude_m ({bounds.max_altitude_m:g})")
    if bounds.min_altitude_m is not None and low < bounds.min_altitude_m - 1e-6:
        where = "below the ground" if low < 0 else "too near the ground"
        raise LimitError(reach.altitude_key, f"it would fly {low:.1f} m above home, {where}: "
                         f"failsafe.geofence.min_altitude_m is {bounds.min_altitude_m:g}")
    if bounds.polygon_ne_m:
        from shapely import contains_xy

        fence = Polygon(bounds.polygon_ne_m)
        inside = contains_xy(fence.buffer(1e-6), pts[:, 0], pts[:, 1])
        if not np.all(inside):
            n, e = pts[int(np.argmin(inside))][:2]
            raise LimitError(reach.place_key, f"it would fly outside failsafe.geofence."
                             f"polygon_m (at {n:.1f}, {e:.1f} m)")


def from_here(bounds: PlanBounds, start_ned: np.ndarray, home_ned_m: np.ndarray | None
               ) -> PlanBounds:
    """``bounds`` for a planned path that starts where the vehicle is: the way from there
    may pass where the vehicle already is (lower than the floor, or further out), never
    further beyond."""
    home = np.zeros(3) if home_ned_m is None else np.asarray(home_ned_m, dtype=float)
    rel = np.asarray(start_ned, dtype=float) - home
    far, up = float(np.hypot(rel[0], rel[1])) + 0.01, float(-rel[2])
    polygon = bounds.polygon_ne_m
    if polygon:
        from shapely.geometry import Point

        if not Polygon(polygon).buffer(1e-6).covers(Point(float(start_ned[0]),
                                                          float(start_ned[1]))):
            polygon = None  # (outside it already: the way back in crosses it)
    return dataclasses.replace(
        bounds, polygon_ne_m=polygon,
        max_distance_m=bounds.max_distance_m and max(bounds.max_distance_m, far),
        max_altitude_m=bounds.max_altitude_m and max(bounds.max_altitude_m, up + 0.01),
        min_altitude_m=None if bounds.min_altitude_m is None
        else min(bounds.min_altitude_m, up - 0.01))


def _transit_m(inputs: BehaviorInputs | None, points: np.ndarray | None) -> float:
    """From where the vehicle is to the nearest of ``points`` (0: either unknown)."""
    if inputs is None or points is None or not len(points):
        return 0.0
    here = np.asarray(inputs.state.position_ned_m, dtype=float)
    if not np.all(np.isfinite(here)):
        return 0.0
    return float(np.min(np.linalg.norm(np.asarray(points) - here, axis=1)))


def _resolvable(inputs: BehaviorInputs | None, frame: str, latlon: bool) -> bool:
    """Whether the step's positions can be put in the local frame now."""
    if inputs is None:
        return False
    try:
        if latlon:
            _latlon_ne(0.0, 0.0, inputs)
        else:
            _frame_offset(frame, inputs)
    except PlanError:
        return False
    return True


def goto_reach(params: GotoParams, inputs: BehaviorInputs | None) -> Reach:
    key = "latlon" if params.latlon is not None else "position_m"
    if not _resolvable(inputs, params.frame, params.latlon is not None):
        return Reach(None, key, key, 0.0, key)
    target = resolve_point(inputs, params.frame, params.position_m, params.latlon)
    return Reach(target[None, :], key, key, _transit_m(inputs, target[None, :]), key)


def orbit_reach(params: OrbitParams, inputs: BehaviorInputs | None) -> Reach:
    key = "center_latlon" if params.center_latlon is not None else "center_m"
    path = 2.0 * math.pi * params.radius_m * params.laps
    if not _resolvable(inputs, params.frame, params.center_latlon is not None):
        return Reach(None, key, "altitude_m", path, "laps", params.images)
    centre = resolve_ne(inputs, params.frame, params.center_m, params.center_latlon)
    down = resolve_down(inputs, params.frame, params.altitude_m, params.center_latlon is not None)
    angle = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
    ring = np.column_stack([centre[0] + params.radius_m * np.cos(angle),
                            centre[1] + params.radius_m * np.sin(angle),
                            np.full(len(angle), down)])
    return Reach(ring, key, "altitude_m", path + _transit_m(inputs, ring), "laps",
                 params.images)


def survey_reach(params: SurveyParams, inputs: BehaviorInputs | None, spacing_m: float,
                 turnaround_m: float) -> Reach:
    """The lines' length (the area over the spacing, each line flown ``turnaround_m`` beyond
    both ends, the turns between them) and the photos along them."""
    key = "polygon_latlon" if params.polygon_latlon is not None else "polygon_m"
    latlon = params.polygon_latlon is not None
    if latlon:  # (its size, not its place: metres from its first corner)
        lat0, lon0 = params.polygon_latlon[0]
        k = math.pi / 180.0 * 6_371_000.0
        ring = [((lat - lat0) * k, (lon - lon0) * k * math.cos(math.radians(lat0)))
                for lat, lon in params.polygon_latlon]
        area = Polygon(ring)
    else:
        area = Polygon(params.polygon_m, params.holes_m)
    rect = area.minimum_rotated_rectangle
    if rect.geom_type != "Polygon":  # (a degenerate outline: a line or a point)
        width = 0.0
    elif params.angle_deg is None:  # the planner's fewest lines: across the narrowest width
        corners = np.array(rect.exterior.coords, dtype=float)
        width = float(np.min(np.linalg.norm(np.diff(corners[:3], axis=0), axis=1)))
    else:
        a = math.radians(params.angle_deg)
        corners = np.array(area.exterior.coords, dtype=float)
        across = corners @ np.array([-math.sin(a), math.cos(a)])
        width = float(across.max() - across.min())
    lines = math.ceil(width / spacing_m) + 1
    photo = params.photo_spacing_m or spacing_m
    path = area.area / spacing_m + lines * (spacing_m + 2.0 * turnaround_m)
    photos = math.ceil(area.area / spacing_m / photo) + 2 * lines
    path_key = "spacing_m" if params.spacing_m is not None else "polygon_m"
    if not _resolvable(inputs, params.frame, latlon):
        return Reach(None, key, "altitude_m", path, path_key, photos, "photo_spacing_m")
    corners = [resolve_ne(inputs, params.frame, latlon=c) for c in params.polygon_latlon] \
        if latlon else [resolve_ne(inputs, params.frame, c) for c in params.polygon_m]
    outline = Polygon([tuple(c) for c in corners]).buffer(turnaround_m, join_style="mitre")
    down = resolve_down(inputs, params.frame, params.altitude_m, latlon)
    pts = np.array(outline.exterior.coords, dtype=float)
    pts = np.column_stack([pts, np.full(len(pts), down)])
    return Reach(pts, key, "altitude_m", path + _transit_m(inputs, pts), path_key, photos,
                 "photo_spacing_m")


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
