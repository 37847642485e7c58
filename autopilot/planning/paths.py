"""The paths of the offboard step kinds, and where along them to take photos.

* :func:`orbit_plan`: in from where the vehicle is along the tangent to the circle (or straight
  out to it from inside), ``laps`` times round, out along the tangent; corners and the joins of
  straight and round rounded by a Gaussian along the path (the circle is drawn that much wider
  so that it is ``radius_m`` after the rounding); photos at evenly spaced angles.
* :func:`survey_plan`: lawnmower lines across a polygon (convex or not, with holes; shapely),
  each covering the strip of the polygon within half a line spacing of it; the lines flown in
  the order that keeps transits short; turns (and the way in) made of scipy B-splines (clamped
  quintics, tangent and without curvature at both ends, so the vehicle enters and leaves a
  turn without a jerk); photos evenly spaced along each line, its ends included, no further
  apart than ``photo_spacing_m``.

All positions are local NED (north, east, down) in metres; shapely works in (north, east).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import BSpline
from scipy.ndimage import gaussian_filter1d
from shapely import affinity
from shapely.geometry import LineString, Polygon, box
from shapely.geometry.base import BaseGeometry

from autopilot.planning.trajectory import dedupe, resample, resample_evenly

_STEP_M = 0.05  # dense path resolution


@dataclass(frozen=True, slots=True, eq=False)
class PathPlan:
    """A planned path (dense points, NED) and the photo points along it."""

    points: np.ndarray
    photo_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: what the photos are of: the orbit's centre (NED), or None
    look_at_ned_m: np.ndarray | None = None
    #: the survey's lines as ((n, e) start, (n, e) end), in the order flown
    lines: tuple = ()
    angle_deg: float = 0.0  # survey: direction of the lines (from north, towards east)


def wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


# ------------------------------------------------------------------------------------------
# Orbit
# ------------------------------------------------------------------------------------------


def orbit_plan(start_ned: np.ndarray, center_ne: tuple[float, float], radius_m: float,
               down_m: float, *, laps: float = 1.0, clockwise: bool = True, images: int = 0,
               start_bearing_rad: float | None = None, rounding_m: float = 0.5,
               run_out_m: float = 2.0) -> PathPlan:
    """An orbit of ``center_ne`` at ``radius_m`` and height ``down_m`` (NED), ``laps`` times
    round (clockwise seen from above: north towards east), entered from ``start_ned``.

    The circle is entered where the tangent from the start touches it (or at
    ``start_bearing_rad``, the bearing of the entry point from the centre), left along its
    tangent for ``run_out_m``; ``images`` photo points are spaced evenly over the laps, the
    first half a spacing after the entry."""
    p0 = np.asarray(start_ned, dtype=float)
    c = np.array(center_ne, dtype=float)
    sign = 1.0 if clockwise else -1.0  # bearing increases clockwise (north → east)
    sigma = rounding_m
    # drawn wider so that the Gaussian rounding brings it back to radius_m
    r_draw = radius_m * math.exp(sigma ** 2 / (2.0 * radius_m ** 2))
    rel = p0[:2] - c
    d = float(np.hypot(*rel))
    bearing0 = math.atan2(rel[1], rel[0])
    if start_bearing_rad is not None:
        entry = float(start_bearing_rad)
    elif d > r_draw * 1.02:
        # the tangent point from which the line in goes on round the circle the right way
        entry = bearing0 + sign * math.acos(min(r_draw / d, 1.0))
    else:
        entry = bearing0 if d > 1e-6 else 0.0
    total = 2.0 * math.pi * laps
    n = max(int(total * r_draw / _STEP_M), 16)
    th = entry + sign * np.linspace(0.0, total, n + 1)
    circle = np.column_stack([c[0] + r_draw * np.cos(th), c[1] + r_draw * np.sin(th),
                              np.full(n + 1, down_m)])
    tangent_out = sign * np.array([-math.sin(th[-1]), math.cos(th[-1]), 0.0])
    run_out = circle[-1] + np.outer(np.linspace(0.0, run_out_m, 20), tangent_out)
    approach = resample(np.vstack([p0, circle[0]]), _STEP_M)
    points = np.vstack([approach, circle[1:], run_out[1:]])
    points = _round(points, sigma, keep_ends=True)
    photos = np.zeros((0, 3))
    if images > 0:
        step = total / images
        ang = entry + sign * step * (np.arange(images) + 0.5)
        photos = np.column_stack([c[0] + radius_m * np.cos(ang),
                                  c[1] + radius_m * np.sin(ang), np.full(images, down_m)])
    return PathPlan(points, photos, np.array([c[0], c[1], 0.0]))


def _round(points: np.ndarray, sigma_m: float, keep_ends: bool) -> np.ndarray:
    """``points`` (resampled evenly) smoothed by a Gaussian of ``sigma_m`` along the path."""
    pts = resample_evenly(points, _STEP_M)
    if sigma_m <= 0 or len(pts) < 5:
        return pts
    smooth = gaussian_filter1d(pts, sigma_m / _STEP_M, axis=0, mode="nearest")
    if keep_ends:
        smooth[0], smooth[-1] = pts[0], pts[-1]
    return smooth


# ------------------------------------------------------------------------------------------
# Survey
# ------------------------------------------------------------------------------------------


def best_angle_deg(area: Polygon) -> float:
    """The line direction that needs the fewest lines: across the polygon's narrowest width."""
    best, best_width = 0.0, math.inf
    for angle in range(0, 180):
        rotated = affinity.rotate(area, -angle, origin=(0, 0), use_radians=False)
        _, miny, _, maxy = rotated.bounds
        if maxy - miny < best_width - 1e-9:
            best, best_width = float(angle), maxy - miny
    return best


def survey_lines(area: Polygon, spacing_m: float, angle_deg: float
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The lawnmower lines: for each strip one ``spacing_m`` wide across the polygon, a line
    along its middle spanning each connected part of the polygon within the strip (so that
    photos along it see the whole strip). Returned as ((n, e), (n, e)) in strip order, each
    strip's parts from low to high along the line."""
    # shapely's rotate turns anticlockwise in its (x, y) = (north, east) plane, which is
    # clockwise seen from above: towards east. Lines run along x in the rotated frame.
    rotated = affinity.rotate(area, -angle_deg, origin=(0, 0), use_radians=False)
    minx, miny, maxx, maxy = rotated.bounds
    width = maxy - miny
    count = max(math.ceil(width / spacing_m - 1e-9), 1)
    first = miny + (width - (count - 1) * spacing_m) / 2.0
    lines = []
    for k in range(count):
        y = first + k * spacing_m
        strip = rotated.intersection(box(minx - 1, y - spacing_m / 2, maxx + 1, y + spacing_m / 2))
        parts = sorted(_polygons(strip), key=lambda g: g.bounds[0])
        for part in parts:
            x0, _, x1, _ = part.bounds
            seg = LineString([(x0, y), (x1, y)])
            back = affinity.rotate(seg, angle_deg, origin=(0, 0), use_radians=False)
            a, b = np.array(back.coords[0]), np.array(back.coords[-1])
            lines.append((a, b))
    return lines


def _polygons(geometry: BaseGeometry) -> list[Polygon]:
    if geometry.is_empty:
        return []
    if isinstance(geometry, Polygon):
        return [geometry] if geometry.area > 1e-9 else []
    return [g for part in getattr(geometry, "geoms", []) for g in _polygons(part)]


def order_lines(lines: list[tuple[np.ndarray, np.ndarray]], start_ne: np.ndarray
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The lines in flying order, each oriented as flown: from wherever the vehicle is, always
    the nearest end of a line not flown yet (a convex polygon comes out as a lawnmower)."""
    left = list(lines)
    here = np.asarray(start_ne, dtype=float)
    out = []
    while left:
        best = min(((i, flip) for i in range(len(left)) for flip in (False, True)),
                   key=lambda c: float(np.linalg.norm(left[c[0]][1 if c[1] else 0] - here)))
        a, b = left.pop(best[0])
        if best[1]:
            a, b = b, a
        out.append((a, b))
        here = b
    return out


def quintic_turn(p0: np.ndarray, d0: np.ndarray, p1: np.ndarray, d1: np.ndarray,
                 reach_m: float) -> np.ndarray:
    """A clamped quintic B-spline from ``p0`` heading ``d0`` to ``p1`` heading ``d1`` (unit
    vectors): tangent to both and without curvature at both ends. ``reach_m``: how far its
    control points reach along the headings."""
    ctrl = np.array([p0, p0 + d0 * reach_m / 2, p0 + d0 * reach_m,
                     p1 - d1 * reach_m, p1 - d1 * reach_m / 2, p1])
    spline = BSpline(np.r_[np.zeros(6), np.ones(6)], ctrl, 5)
    chord = float(np.linalg.norm(p1 - p0)) + 2 * reach_m
    return spline(np.linspace(0.0, 1.0, max(int(chord / _STEP_M), 8) + 1))


def survey_plan(start_ned: np.ndarray, area: Polygon, down_m: float, spacing_m: float,
                photo_spacing_m: float, *, angle_deg: float | None = None,
                smoothing: str = "bspline", turnaround_m: float = 2.0) -> PathPlan:
    """The survey of ``area`` at height ``down_m`` (NED) from ``start_ned``. Each line is
    flown ``turnaround_m`` beyond its ends (QGroundControl's turnaround distance), so that the
    vehicle is level and at speed at the first and last photo of a line, not tilted into a
    turn."""
    if not area.is_valid or area.area <= 0:
        raise ValueError("the survey polygon is not a valid area")
    angle = best_angle_deg(area) if angle_deg is None else float(angle_deg)
    lines = order_lines(survey_lines(area, spacing_m, angle), np.asarray(start_ned)[:2])
    p0 = np.asarray(start_ned, dtype=float)

    def at_height(ne: np.ndarray) -> np.ndarray:
        return np.array([ne[0], ne[1], down_m])

    def heading(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = at_height(b) - at_height(a)
        n = float(np.linalg.norm(d))
        if n < 1e-9:  # a line of one point: the survey's direction
            r = math.radians(angle)
            return np.array([math.cos(r), math.sin(r), 0.0])
        return d / n

    pieces: list[np.ndarray] = []
    photos: list[np.ndarray] = []
    reach = max(spacing_m * 0.75, 1.0)
    here, here_dir = p0, None
    for a, b in lines:
        d = heading(a, b)
        start = at_height(a) - d * turnaround_m
        # the way to this line: a smooth turn (B-spline) or straight (smoothing: none)
        if smoothing == "bspline":
            if here_dir is None:  # from the start: head for the line, then turn onto it
                to = start - here
                dist = float(np.linalg.norm(to))
                here_dir = to / dist if dist > 1e-6 else d
                pieces.append(quintic_turn(here, here_dir, start, d,
                                           min(reach, max(dist / 3, 0.2))))
            else:
                pieces.append(quintic_turn(here, here_dir, start, d, reach))
        else:
            pieces.append(resample(np.vstack([here, start]), _STEP_M))
        end = at_height(b) + d * turnaround_m
        pieces.append(resample(np.vstack([start, at_height(a), at_height(b), end]), _STEP_M))
        length = float(np.linalg.norm(at_height(b) - at_height(a)))
        n = max(math.ceil(length / photo_spacing_m - 1e-9), 0) + 1
        for f in np.linspace(0.0, 1.0, n) if n > 1 else [0.5]:
            photos.append(at_height(a) + (at_height(b) - at_height(a)) * f)
        here, here_dir = end, d
    points = dedupe(np.vstack(pieces))
    return PathPlan(points, np.array(photos).reshape(-1, 3), None,
                    tuple((a.copy(), b.copy()) for a, b in lines), angle)


def goto_path(start_ned: np.ndarray, target_ned: np.ndarray) -> np.ndarray:
    """A straight line (its points; the trajectory's speed law does the rest)."""
    return np.vstack([np.asarray(start_ned, float), np.asarray(target_ned, float)])
