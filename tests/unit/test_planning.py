"""Trajectory planning: speed laws within limits, stops at sharp corners, orbit and survey
geometry, and the coverage the planned photos give."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon
from shapely.ops import unary_union

from autopilot.planning.paths import best_angle_deg, orbit_plan, survey_lines, survey_plan
from autopilot.planning.trajectory import (
    Limits,
    Path,
    Trajectory,
    cross_track_m,
    face_point,
    hold_heading,
    resample,
)

_DT = 0.02


def _circle(r: float, n: int = 600) -> np.ndarray:
    th = np.linspace(0.0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(th), r * np.sin(th), np.full(n, -3.0)])


def test_speed_law_keeps_every_limit_and_starts_and_ends_at_rest():
    limits = Limits(3.0, accel_m_s2=1.5, lateral_accel_m_s2=1.5, jerk_m_s3=4.0)
    traj = Trajectory(Path(_circle(4.0)), limits, face_point(0.0, 0.0))
    speed = np.linalg.norm(traj.velocities, axis=1)
    assert speed[0] == pytest.approx(0.0, abs=1e-6)
    assert speed[-1] == pytest.approx(0.0, abs=1e-6)
    # on a 4 m circle √(1.5·4) = 2.45 m/s is all the lateral limit allows, under the 3 m/s asked
    assert speed.max() == pytest.approx(math.sqrt(1.5 * 4.0), rel=0.01)
    lateral = speed ** 2 / 4.0
    assert lateral.max() <= 1.5 * 1.01
    along = np.gradient(traj.speed_m_s, _DT)
    assert np.abs(along).max() <= 1.5 * 1.02
    jerk = np.abs(np.diff(traj.accelerations, axis=0)) / _DT
    assert jerk.max() < 4.0 * 1.5  # (lateral and along-track jerk combine)
    # the reference is consistent: positions integrate the velocities
    integrated = traj.positions[0] + np.cumsum(traj.velocities[:-1] * _DT, axis=0)
    assert np.abs(integrated[-1] - traj.positions[-1]).max() < 0.05
    # facing the centre all the way: heading rate = ω at cruise
    mid = len(traj.times_s) // 2
    assert traj.yaw_rate_rad_s[mid] == pytest.approx(speed[mid] / 4.0, rel=0.02)


def test_a_sharp_corner_is_a_stop_not_a_skid():
    square = resample(np.array([[0, 0, -5], [10, 0, -5], [10, 10, -5], [0, 10, -5.0]]), 0.05)
    path = Path(square)
    assert path.stops_m.tolist() == pytest.approx([10.0, 20.0], abs=0.06)
    traj = Trajectory(path, Limits(3.0), hold_heading(0.0))
    for stop in path.stops_m:
        i = int(np.argmin(np.abs(traj.s_m - stop)))
        assert np.linalg.norm(traj.velocities[i]) < 0.05
    assert np.linalg.norm(traj.accelerations, axis=1).max() <= 1.5 * 1.01
    # the straight stretches stay straight: nothing cut off the corners
    assert cross_track_m(square, traj.positions).max() < 0.01


def test_reference_after_the_end_holds_the_end_at_rest():
    traj = Trajectory(Path(np.array([[0, 0, -2], [5, 0, -2.0]])), Limits(2.0), hold_heading(1.0))
    ref = traj.at(traj.duration_s + 5.0)
    assert ref.position_ned_m == pytest.approx([5, 0, -2])
    assert np.all(ref.velocity_ned_m_s == 0)
    assert ref.yaw_rad == pytest.approx(1.0)
    # 5 m at 2 m/s with 1.5 m/s² ramps and jerk-limited ends: a little over 4 s
    assert 3.5 < traj.duration_s < 6.0


@pytest.mark.parametrize("clockwise", [True, False])
def test_orbit_is_entered_on_the_tangent_and_flown_at_its_radius(clockwise):
    start = np.array([0.0, 0.0, -3.0])
    plan = orbit_plan(start, (10.0, 0.0), 4.0, -6.0, clockwise=clockwise, images=6)
    pts = plan.points
    assert pts[0] == pytest.approx(start)
    r = np.hypot(pts[:, 0] - 10.0, pts[:, 1])
    on_circle = r[np.abs(pts[:, 2] + 6.0) < 1e-6]
    # the Gaussian rounding is compensated: the circle is flown at its radius
    assert np.median(on_circle) == pytest.approx(4.0, abs=0.005)
    assert on_circle.min() > 3.9
    # clockwise seen from above: the bearing from the centre increases (north → east)
    bearings = np.unwrap(np.arctan2(pts[:, 1], pts[:, 0] - 10.0))
    turned = bearings[-30] - bearings[len(pts) // 2]
    assert (turned > 0) == clockwise
    # photos evenly spaced in angle, at the radius
    ang = np.arctan2(plan.photo_points[:, 1], plan.photo_points[:, 0] - 10.0)
    steps = np.abs(np.diff(np.unwrap(ang)))
    assert steps == pytest.approx(np.full(5, 2 * math.pi / 6), abs=1e-6)
    assert np.hypot(plan.photo_points[:, 0] - 10, plan.photo_points[:, 1]) == pytest.approx(4.0)


def _nominal_coverage(area: Polygon, photos: np.ndarray, across_m: float, along_m: float,
                      angle_deg: float) -> float:
    """Coverage of the planned photo points by a level camera's footprint."""
    a = math.radians(angle_deg)
    u = np.array([math.cos(a), math.sin(a)])  # along the lines
    v = np.array([-u[1], u[0]])
    feet = []
    for p in photos[:, :2]:
        corners = [p + su * along_m / 2 * u + sv * across_m / 2 * v
                   for su, sv in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
        feet.append(Polygon(corners))
    return unary_union(feet).intersection(area).area / area.area


@pytest.mark.parametrize(("name", "area"), [
    ("rectangle", Polygon([(0, 0), (30, 0), (30, 20), (0, 20)])),
    ("rotated", Polygon([(0, 0), (20, 20), (14, 26), (-6, 6)])),
    ("concave-u", Polygon([(0, 0), (24, 0), (24, 24), (16, 24), (16, 8), (8, 8), (8, 24),
                           (0, 24)])),
    ("hole", Polygon([(0, 0), (30, 0), (30, 30), (0, 30)],
                     [[(10, 10), (20, 10), (20, 20), (10, 20)]])),
    ("triangle", Polygon([(0, 0), (25, 3), (8, 18)])),
])
def test_survey_photos_cover_the_polygon(name, area):
    across, along = 16.8, 12.6  # the down camera from 10 m
    plan = survey_plan(np.array([0.0, -5.0, -3.0]), area, -10.0, 6.0, 6.0)
    assert _nominal_coverage(area, plan.photo_points, across, along, plan.angle_deg) > 0.999
    # photos are on the lines, no further apart along them than photo_spacing_m
    for a, b in plan.lines:
        ab = b - a
        on = [p for p in plan.photo_points
              if abs(ab[0] * (p[1] - a[1]) - ab[1] * (p[0] - a[0])) < 1e-6 * max(
                  np.linalg.norm(ab), 1) and -1e-6 <= np.dot(p[:2] - a, ab) <= np.dot(ab, ab)
              + 1e-6]
        if len(on) > 1:
            gaps = np.linalg.norm(np.diff(np.array(on)[:, :2], axis=0), axis=1)
            assert gaps.max() <= 6.0 + 1e-6
    # the path flies every line, at the survey's height
    for a, b in plan.lines:
        assert cross_track_m(plan.points[:, :2], np.array([a, b])).max() < 0.01
    assert np.all(np.abs(plan.points[5:, 2] + 10.0) < 1e-6) or name  # (the way in climbs)


def test_survey_lines_run_along_the_long_side():
    long_thin = Polygon([(0, 0), (40, 40), (37, 43), (-3, 3)])  # 56 m long at 45°, 4 m wide
    assert best_angle_deg(long_thin) == pytest.approx(45.0, abs=1.0)
    lines = survey_lines(long_thin, 6.0, 45.0)
    assert len(lines) == 1


def test_concave_strips_are_split_and_the_turns_are_smooth():
    u_shape = Polygon([(0, 0), (24, 0), (24, 24), (16, 24), (16, 8), (8, 8), (8, 24), (0, 24)])
    lines = survey_lines(u_shape, 6.0, 0.0)
    # lines along north: the strips over the arms (east 8..24) hold two parts each
    by_east = {}
    for a, _ in lines:
        by_east.setdefault(round(a[1], 3), []).append(a)
    assert max(len(v) for v in by_east.values()) == 2
    plan = survey_plan(np.array([0.0, 0.0, -3.0]), u_shape, -10.0, 6.0, 6.0)
    traj = Trajectory(Path(plan.points), Limits(3.0), hold_heading(0.0))
    assert np.linalg.norm(traj.accelerations, axis=1).max() < 2.2
    assert np.linalg.norm(traj.velocities, axis=1).max() <= 3.0 * 1.001


@pytest.mark.parametrize("start", [(10.0, 0.0, -6.0), (0.0, 0.0, -3.0), (6.0, -8.0, -6.0),
                                   (6.5, 0.5, -6.0)])
def test_orbit_entry_turns_smoothly_onto_the_circle_without_stopping(start):
    from autopilot.behaviors.trajectory import photo_arc_lengths

    plan = orbit_plan(np.array(start), (6.0, 0.0), 3.0, -6.0, images=8, laps=2)
    d = np.diff(plan.points[:, :2], axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    inside = np.hypot(start[0] - 6.0, start[1]) < 3.0
    # from outside: along the tangent, no corner anywhere (inside: one rounded 90° turn)
    assert np.degrees(np.abs(np.diff(heading))).max() < (10.0 if inside else 2.0)
    path = Path(plan.points)
    traj = Trajectory(path, Limits(2.0), face_point(6.0, 0.0))
    assert len(path.stops_m) == 0
    assert traj.duration_s < 2 * (path.length_m / 2.0) + 10
    # two laps: the photos come one after another, never all at once
    s = photo_arc_lengths(traj, plan.photo_points)
    assert np.all(np.diff(s) > 1.0)
