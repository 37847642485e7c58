"""The shared down-camera search (land_pad, hover_image): the expanding square's corners, their
order and spacing from the camera's footprint, coverage of the area, the climb first, the wait
over the start, the timeout; and the footprint's width for a camera looking down."""

import math

import numpy as np
import pytest

from autopilot.control.search import (
    Search,
    SearchSettings,
    expanding_square,
    ring_spacing_m,
)
from autopilot.planning.footprint import footprint_width_per_m
from drivers.base import CameraIntrinsics
from drivers.camera_model import pinhole
from drivers.sim.model import camera_rotation_body

DIRS = {(1, 0): "N", (0, 1): "E", (-1, 0): "S", (0, -1): "W"}


def _legs(corners):
    d = np.diff(np.array(corners), axis=0)
    lengths = np.linalg.norm(d, axis=1)
    names = [DIRS.get(tuple(int(v) for v in np.round(x / n)), "?") if n > 1e-9 else "0"
             for x, n in zip(d, lengths, strict=True)]
    return names, lengths


def _distance_to_path(points, corners):
    """Each point's distance to the polyline through ``corners``."""
    a, b = np.array(corners[:-1]), np.array(corners[1:])
    ab = b - a
    rel = points[:, None, :] - a[None]
    t = np.clip(np.einsum("pki,ki->pk", rel, ab) / np.maximum(
        np.einsum("ki,ki->k", ab, ab), 1e-12), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - nearest, axis=2).min(axis=1)


def test_the_square_expands_north_east_south_west_and_closes_its_last_ring():
    corners = expanding_square((1.0, 2.0), 2.0, 4.0)
    assert corners[0] == pytest.approx((1.0, 2.0))
    assert corners[-1] == pytest.approx((1.0, 2.0))  # back over the start
    names, lengths = _legs(corners[:-1])
    assert names == ["N", "E", "S", "W"] * 2 + ["N", "E"]
    # 1, 1, 2, 2, 3, 3, 4, 4 ring spacings out; then up the last ring's west side, and along
    # its north side to where that side's first pass began
    assert lengths == pytest.approx([2, 2, 4, 4, 6, 6, 8, 8, 8, 2])
    rel = np.array(corners) - (1.0, 2.0)
    assert np.abs(rel).max() == pytest.approx(4.0)  # the outermost ring's half side: the radius
    assert (np.abs(rel) <= 4.0 + 1e-9).all()  # every corner within the radius
    assert corners[-2] - np.array((1.0, 2.0)) == pytest.approx((4.0, -2.0))


def test_the_rings_fit_the_radius_no_further_apart_than_the_spacing():
    for spacing, radius, rings in ((3.2, 4.0, 2), (5.4, 4.0, 1), (1.0, 3.5, 4), (2.0, 2.0, 1)):
        corners = expanding_square((0.0, 0.0), spacing, radius)
        step = radius / rings
        assert step <= spacing + 1e-9
        _, lengths = _legs(corners[:-1])
        assert lengths[0] == pytest.approx(step)  # the first leg: one ring out
        assert len(corners) == 4 * rings + 4  # centre, 4 legs a ring, 2 closing, back
        assert np.abs(np.array(corners)).max() == pytest.approx(radius)
    assert [tuple(c) for c in expanding_square((3.0, -1.0), 2.0, 0.0)] == [(3.0, -1.0)]


@pytest.mark.parametrize(("altitude", "size", "radius"),
                         [(4.0, 1.0, 4.0), (6.0, 0.8, 4.0), (3.0, 1.0, 6.0), (10.0, 2.0, 30.0)])
def test_a_target_anywhere_in_the_square_is_wholly_in_view_from_the_path(altitude, size, radius):
    footprint_per_m = 1.23  # the down camera's
    spacing = ring_spacing_m(footprint_per_m, altitude, size)
    corners = expanding_square((0.0, 0.0), spacing, radius)
    step = radius / math.ceil(radius / spacing)
    g = np.linspace(-radius, radius, 81)
    grid = np.array([(n, e) for n in g for e in g])  # the square out to the radius
    worst = _distance_to_path(grid, corners).max()
    # the farthest: off a ring's corner, √2·a from it and s − a from the next ring out, at
    # most s·√2/(1 + √2) = 0.586 s
    bound = step * math.sqrt(2.0) / (1.0 + math.sqrt(2.0))
    assert worst <= bound + 1e-9
    assert worst >= 0.95 * bound  # (the bound is not loose)
    # a target whose centre is within half the footprint less its size of the vehicle is
    # wholly in view (a level vehicle; ring_spacing_m's overlap leaves the rest for tilt)
    assert worst < (footprint_per_m * altitude - size) / 2.0
    # and beyond the square, half a spacing out along its sides
    side = np.array([(radius + step / 2, e) for e in np.linspace(-radius, radius, 41)])
    for sign in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        for pts in (side * sign, side[:, ::-1] * sign):
            assert _distance_to_path(pts, corners).max() <= 0.5 * step + 1e-9


def test_ring_spacing_is_the_footprint_at_the_search_altitude_less_the_target():
    # the down camera's 1.23 m per metre: 4 m up, a 1 m image: 0.8 × (4.92 − 1)
    assert ring_spacing_m(1.23, 4.0, 1.0) == pytest.approx(0.8 * (1.23 * 4.0 - 1.0))
    assert ring_spacing_m(1.23, 8.0, 1.0) > ring_spacing_m(1.23, 4.0, 1.0)  # higher: wider
    assert ring_spacing_m(1.23, 4.0, 2.0) < ring_spacing_m(1.23, 4.0, 1.0)  # bigger target
    assert ring_spacing_m(1.23, 1.0, 5.0) == pytest.approx(0.5)  # never below 0.5 m


def test_footprint_width_of_a_camera_looking_down_and_of_one_that_does_not():
    down = camera_rotation_body(-90.0, 0.0)
    intr = CameraIntrinsics(640, 480, 320.0, 320.0, 319.5, 239.5)
    # straight down, no lens distortion: the image's shorter side on the ground, 479/320 per m
    # (the outline runs through the outermost pixel centres)
    assert footprint_width_per_m(intr, down, np.zeros(3)) == pytest.approx(479.0 / 320.0,
                                                                           rel=1e-3)
    # the project's down camera (80°, mild barrel: its edges see a little more than the
    # pinhole's), 4 cm below the body's origin: per metre of the camera's height
    lens = pinhole(640, 480, 80.0, (-0.05, 0.006, 0.0003, 0.0002, 0.0))
    width = footprint_width_per_m(lens, down, np.array([0.0, 0.0, 0.04]))
    assert 479.0 / lens.fy < width < 1.1 * 479.0 / lens.fy
    assert width == pytest.approx(footprint_width_per_m(lens, down, np.zeros(3)))
    # tilted 20° off the vertical: the point under the vehicle is off the image's centre
    tilted = footprint_width_per_m(intr, camera_rotation_body(-70.0, 0.0), np.zeros(3))
    assert 0.0 < tilted < 479.0 / 320.0
    # looking forward: it does not see the ground under the vehicle
    assert footprint_width_per_m(intr, camera_rotation_body(0.0, 0.0), np.zeros(3)) == 0.0


def _settings(**kw):
    values = {"altitude_m": 4.0, "radius_m": 4.0, "spacing_m": 3.2, "speed_m_s": 2.0,
              "timeout_s": 60.0} | kw
    return SearchSettings(**values)


def _fly(search, start_ned, t0=0.0, dt=0.05, until_s=120.0, max_speed=2.5):
    """A vehicle that goes at its setpoint at up to ``max_speed``; the commands and where it
    was, at every tick."""
    here = np.array(start_ned, dtype=float)
    log = []
    t = t0
    while t < until_s:
        command = search.update(t, here)
        log.append((t, here.copy(), command))
        step = np.array(command.position_ned_m) - here
        n = float(np.linalg.norm(step))
        here = here + (step if n <= max_speed * dt else step / n * max_speed * dt)
        t += dt
    return log


def test_climbs_over_the_start_then_sweeps_the_corners_in_order_then_waits_over_the_start():
    search = Search(_settings())
    search.start(0.0, (10.0, -5.0))
    corners = search.waypoints
    log = _fly(search, (10.0, -5.0, -2.0), until_s=55.0)
    first = log[0][2]
    assert first.stage == "climbing"
    assert first.position_ned_m == pytest.approx((10.0, -5.0, -4.0))  # straight up
    climbing = [c for _, _, c in log if c.stage == "climbing"]
    assert all(c.position_ned_m[:2] == pytest.approx((10.0, -5.0)) for c in climbing)
    sweeping = [(t, p, c) for t, p, c in log if c.stage == "sweeping"]
    assert sweeping
    assert all(c.position_ned_m[2] == -4.0 for _, _, c in sweeping)
    # the setpoint leads the vehicle by about a second at the search speed
    lead = [np.linalg.norm(np.array(c.position_ned_m[:2]) - p[:2]) for _, p, c in sweeping]
    assert max(lead) == pytest.approx(2.0, abs=1e-6)
    # every corner passed, in order (a corner may be passed again later: the last ring is
    # closed where its north side began)
    k = 1
    for _, p, _ in log:
        if k < len(corners) - 1 and np.linalg.norm(p[:2] - corners[k]) < 0.3:
            k += 1
    assert k == len(corners) - 1, f"corner {k} {corners[k]} not reached in order"
    # then over the start, waiting, at the search altitude
    _, here, last = log[-1]
    assert last.stage == "waiting"
    assert here == pytest.approx((10.0, -5.0, -4.0), abs=0.05)
    assert not last.timed_out


def test_times_out_after_the_timeout_from_its_start_and_restarts_afresh():
    search = Search(_settings(timeout_s=10.0, radius_m=0.0))
    search.start(5.0, (0.0, 0.0))
    log = _fly(search, (0.0, 0.0, -4.0), t0=5.0, until_s=16.0)
    assert not any(c.timed_out for t, _, c in log if t <= 15.0)
    assert all(c.timed_out for t, _, c in log if t > 15.0 + 1e-9)
    assert all(c.position_ned_m == pytest.approx((0.0, 0.0, -4.0)) for _, _, c in log)
    # radius 0: climb and look only
    assert {c.stage for _, _, c in log} == {"waiting"}
    search.start(20.0, (3.0, 3.0))  # a new search: a new start, a new clock
    command = search.update(20.1, (0.0, 0.0, -4.0))
    assert not command.timed_out
    assert command.stage == "waiting"
    assert command.position_ned_m[:2] == pytest.approx((math.sqrt(2.0),) * 2)  # 2 m on


def test_already_at_the_search_altitude_it_sweeps_at_once():
    search = Search(_settings())
    search.start(0.0, (0.0, 0.0))
    command = search.update(0.0, (0.0, 0.0, -4.1))
    assert command.stage == "sweeping"
    assert command.position_ned_m == pytest.approx((2.0, 0.0, -4.0))  # north first
