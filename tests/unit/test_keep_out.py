"""Keep-out discs (seed 001: blue = keep away): the detector on synthetic frames (read noise and
a JPEG round trip, as the realistic cameras deliver them), the ground projection, the map of
zones, and the guard every setpoint passes through."""

import math

import cv2
import numpy as np
import pytest

from autopilot.control.keep_out import GuardSettings, KeepOutGuard, entry_distance
from autopilot.estimation.pose_history import Pose
from autopilot.perception.colors import COLORS
from autopilot.perception.keep_out import (
    DiscAcceptance,
    DiscDetector,
    DiscSettings,
    accept,
    ground_circle,
    ground_points,
)
from autopilot.perception.keep_out_map import KeepOutMap, KeepOutZone, MapSettings
from drivers.base import CameraInfo, CameraIntrinsics, Setpoint, SetpointFrame
from drivers.camera_model import undistort_points
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.model import camera_rotation_body

from ..factories import vehicle_state

BLUE = COLORS["blue"]
FRONT_FX = 320.0  # 90° across 640 px
DOWN_FX = 320.0 / math.tan(math.radians(40.0))


def _camera(name, pitch_deg, fx, distortion=(-0.08, 0.012, 0.0005, -0.0003, 0.0)):
    return CameraInfo(name, CameraIntrinsics(640, 480, fx, fx, 319.5, 239.5, distortion),
                      camera_rotation_body(pitch_deg, 0.0), np.array([0.1, 0.0, 0.0]), 30.0)


def _pose(north=0.0, east=0.0, height=1.7, yaw=0.0, pitch=0.0):
    return Pose(0.0, np.array([north, east, -height]), quat_from_euler(0.0, pitch, yaw))


def _render(camera, pose, shapes, *, seed=1, noise_dn=2.0, quality=75):
    """The ground as ``camera`` sees it from ``pose`` (exactly, through its lens): grass-green
    with ``shapes`` — (inside(north, east) → bool, BGR) — painted on it, a pale sky above;
    then read noise and a JPEG round trip."""
    h, w = camera.intrinsics.height_px, camera.intrinsics.width_px
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    norm = undistort_points(camera.intrinsics, np.column_stack([u.ravel(), v.ravel()]))
    ground, _, _ = ground_points(norm, camera, pose, 0.0)
    image = np.empty((h * w, 3), np.float64)
    image[:] = (235, 215, 200)  # sky (BGR)
    on_ground = np.isfinite(ground[:, 0])
    image[on_ground] = (60, 110, 85)
    for inside, bgr in shapes:
        hit = on_ground.copy()
        hit[on_ground] = inside(ground[on_ground, 0], ground[on_ground, 1])
        image[hit] = bgr
    rng = np.random.default_rng(seed)
    image = image.reshape(h, w, 3) + rng.normal(0.0, noise_dn, (h, w, 3))
    image = np.clip(image, 0, 255).astype(np.uint8)
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.imdecode(jpeg, cv2.IMREAD_COLOR)


def _disc(n0, e0, r, rgba=BLUE[0]):
    bgr = tuple(255 * c for c in (rgba[2], rgba[1], rgba[0]))
    return (lambda n, e: (n - n0) ** 2 + (e - e0) ** 2 <= r * r), bgr


def _detector():
    return DiscDetector(DiscSettings(BLUE[1]))


def test_a_disc_far_ahead_on_the_ground_is_found_and_placed_where_it_is():
    # the front camera, 1.7 m up, pitched 5° down: a 0.4 m disc 4 m ahead is a flat ellipse
    camera, pose = _camera("front", -5.0, FRONT_FX), _pose()
    image = _render(camera, pose, [_disc(4.0, 0.6, 0.4)])
    found = _detector().detect(image, camera, 0.0)
    assert found is not None
    assert len(found.blobs) == 1
    blob = found.blobs[0]
    assert not blob.clipped
    width = np.ptp(blob.outline_norm[:, 0]) / np.ptp(blob.outline_norm[:, 1])
    assert width > 2.0  # (an ellipse, not a circle, in the image)
    circle = ground_circle(blob, camera, pose, 0.0)
    assert circle is not None
    assert circle.centre_ne_m == pytest.approx((4.0, 0.6), abs=0.06)
    assert circle.radius_m == pytest.approx(0.4, rel=0.06)
    assert accept(circle, DiscAcceptance()) is None
    assert circle.arc_deg > 300


def test_a_disc_under_the_down_camera_cut_by_the_border_is_still_placed():
    camera = _camera("down", -90.0, DOWN_FX, (-0.05, 0.006, 0.0003, 0.0002, 0.0))
    pose = _pose(height=2.0, yaw=0.3)
    # 2 m up, the frame spans ±1.25 m north: a disc centred 1.3 m ahead is cut nearly in half
    image = _render(camera, pose, [_disc(1.3, 0.2, 0.4)])
    found = _detector().detect(image, camera, 0.0)
    assert found is not None
    blob = found.blobs[0]
    assert blob.clipped
    circle = ground_circle(blob, camera, pose, 0.0)
    assert circle.centre_ne_m == pytest.approx((1.3, 0.2), abs=0.04)
    assert circle.radius_m == pytest.approx(0.4, rel=0.05)
    assert 180.0 < circle.arc_deg < 330.0
    assert accept(circle, DiscAcceptance(min_arc_deg=150.0)) is None
    assert "seen" in accept(circle, DiscAcceptance(min_arc_deg=340.0))


def test_several_discs_are_found_and_other_colours_and_shapes_are_not_discs():
    camera, pose = _camera("front", -5.0, FRONT_FX), _pose()
    orange = COLORS["orange"][0]
    stripe = ((lambda n, e: (np.abs(e + 1.0) < 0.1) & (n > 3.0) & (n < 6.0)),
              tuple(255 * c for c in (BLUE[0][2], BLUE[0][1], BLUE[0][0])))
    image = _render(camera, pose, [_disc(3.5, 1.2, 0.4), _disc(6.0, -0.2, 0.5),
                                   _disc(3.0, -0.5, 0.3, orange), stripe])
    found = _detector().detect(image, camera, 0.0)
    circles = [ground_circle(b, camera, pose, 0.0) for b in found.blobs]
    kept = sorted((tuple(np.round(c.centre_ne_m, 1)), round(c.radius_m, 1)) for c in circles
                  if c is not None and accept(c, DiscAcceptance()) is None)
    assert kept == [((3.5, 1.2), 0.4), ((6.0, -0.2), 0.5)]  # not the orange disc, nor the stripe
    assert len(found.blobs) == 3  # (the stripe is a blob; on the ground it is no circle)


def test_nothing_blue_nothing_found():
    camera, pose = _camera("front", -5.0, FRONT_FX), _pose()
    image = _render(camera, pose, [_disc(3.0, 0.0, 0.4, COLORS["red"][0])])
    assert _detector().detect(image, camera, 0.0) is None


def test_ground_points_meet_the_plane_where_the_rays_do():
    down = CameraInfo("down", CameraIntrinsics(640, 480, 400.0, 400.0, 320.0, 240.0),
                      camera_rotation_body(-90.0, 0.0), np.zeros(3), 30.0)
    pose = _pose(north=2.0, east=-1.0, height=3.0)
    # the principal point: straight down; 100 px right (the image's x is the body's right:
    # east at yaw 0) is 3 × 100/400 m east
    pts, cam, height = ground_points(np.array([[0.0, 0.0], [0.25, 0.0]]), down, pose)
    assert height == pytest.approx(3.0)
    assert cam == pytest.approx((2.0, -1.0, -3.0))
    assert pts[0] == pytest.approx((2.0, -1.0))
    assert pts[1] == pytest.approx((2.0, -1.0 + 0.75))
    # on a ground 0.5 m lower, the same ray goes further
    pts, _, _ = ground_points(np.array([[0.25, 0.0]]), down, pose, ground_down_m=0.5)
    assert pts[0] == pytest.approx((2.0, -1.0 + 0.25 * 3.5))
    # the front camera's rays above the horizon never meet the ground
    front = _camera("front", 0.0, FRONT_FX, (0.0,) * 5)
    pts, _, _ = ground_points(np.array([[0.0, -0.1], [0.0, 0.2]]), front, _pose(height=2.0))
    assert np.isnan(pts[0]).all()
    assert pts[1] == pytest.approx((0.1 + 2.0 / 0.2, 0.0))


def test_a_rolled_vehicle_places_the_disc_with_its_attitude():
    camera = _camera("down", -90.0, DOWN_FX, (0.0,) * 5)
    tilted = Pose(0.0, np.array([0.0, 0.0, -3.0]), quat_from_euler(math.radians(8), 0.0, 0.0))
    image = _render(camera, tilted, [_disc(0.5, 0.8, 0.4)], noise_dn=0.0, quality=95)
    blob = _detector().detect(image, camera, 0.0).blobs[0]
    assert ground_circle(blob, camera, tilted).centre_ne_m == pytest.approx((0.5, 0.8),
                                                                            abs=0.03)
    level = Pose(0.0, tilted.position_ned_m, np.array([1.0, 0.0, 0.0, 0.0]))
    wrong = ground_circle(blob, camera, level).centre_ne_m  # the attitude ignored: ~0.4 m off
    assert np.linalg.norm(wrong - (0.5, 0.8)) > 0.3
    assert quat_to_matrix(tilted.attitude_q)[2, 2] < 1.0


# -- the map -------------------------------------------------------------------------------------


def _circle(n, e, r=0.4, range_m=3.0, height=1.7):
    from autopilot.perception.keep_out import GroundCircle

    return GroundCircle(np.array([n, e]), r, 0.02, 360.0, range_m, height)


def test_the_same_disc_seen_again_refines_one_zone_which_counts_after_three_views():
    m = KeepOutMap(MapSettings(confirm_after=3))
    assert m.observe(_circle(3.2, 0.1, range_m=6.0), 0.0) == (0, None)
    assert m.zones() == ()  # one view is not a zone
    assert m.observe(_circle(3.0, 0.0, r=0.38, range_m=2.0), 0.1)[0] == 0
    index, note = m.observe(_circle(3.0, 0.0, r=0.38, range_m=2.0), 0.2)
    assert index == 0
    assert "keep-out zone 0" in note
    (zone,) = m.zones()
    # the near views (weight ∝ 1/range⁴) outweigh the far one
    assert zone.centre_ne_m == pytest.approx((3.0, 0.0), abs=0.01)
    assert zone.radius_m == pytest.approx(0.38, abs=0.005)
    assert zone.observations == 3
    # a second disc 2 m away is a zone of its own
    for t in (0.3, 0.4, 0.5):
        assert m.observe(_circle(3.0, 2.0), t)[0] == 1
    assert [z.index for z in m.zones()] == [0, 1]


def test_a_lone_blob_is_forgotten_and_the_zone_follows_a_slow_drift():
    m = KeepOutMap(MapSettings(confirm_after=3, forget_unconfirmed_s=1.0, memory=0.9))
    m.observe(_circle(-4.0, 4.0), 0.0)
    for k in range(3):
        m.observe(_circle(0.0, 0.0), 2.0 + 0.1 * k)
    assert [z.index for z in m.zones()] == [1]  # (zone 0, never confirmed, went)
    assert m.observe(_circle(-4.0, 4.0), 3.0)[0] == 2
    # seen 100 times 0.3 m further north (the navigation drifted): the zone followed
    for k in range(100):
        m.observe(_circle(0.3, 0.0), 4.0 + 0.03 * k)
    assert m.zones()[0].centre_ne_m == pytest.approx((0.3, 0.0), abs=0.01)


# -- the guard -----------------------------------------------------------------------------------


ZONE = KeepOutZone(0, (0.0, 0.0), 0.4, 10)


def _guard(zones=(ZONE,), **settings):
    return KeepOutGuard("keep_out", lambda: zones, GuardSettings(**settings))


def test_a_position_setpoint_inside_a_zone_is_moved_to_its_edge():
    guard = _guard(margin_m=0.5)
    state = vehicle_state(0.0, pos=(3.0, 3.0, -2.0))
    out = guard.guard(Setpoint.position(0.3, 0.0, -2.5, 0.4), state)
    assert out.action == "moved to edge"
    assert out.setpoint.position_ned_m[:2] == pytest.approx((0.92, 0.0), abs=1e-6)
    assert out.setpoint.position_ned_m[2] == -2.5  # heights and heading untouched
    assert out.setpoint.yaw_rad == 0.4
    assert "zone 0" in out.text


def test_a_velocity_into_a_zone_is_turned_round_it_and_one_away_passes():
    guard = _guard(margin_m=0.5, lookahead_s=1.0)
    state = vehicle_state(0.0, pos=(-1.5, 0.1, -2.0))
    out = guard.guard(Setpoint.velocity_ned(1.0, 0.0, 0.2), state)
    assert out.action == "deflected"
    v = out.setpoint.velocity_m_s
    assert np.hypot(v[0], v[1]) == pytest.approx(1.0)  # the speed kept: it goes round
    assert v[2] == 0.2
    direction = v[:2] / np.hypot(v[0], v[1])
    p = np.array([-1.5, 0.1])
    assert entry_distance(p, direction, np.zeros(2), 0.9) == math.inf  # never enters
    assert v[1] > 0  # on the side it was heading for (it was north-east of the line)
    # slow enough not to reach it within the lookahead: untouched; away from it: untouched
    assert guard.guard(Setpoint.velocity_ned(0.3, 0.0, 0.0), state).action is None
    assert guard.guard(Setpoint.velocity_ned(-1.0, 0.0, 0.0), state).action is None
    # the zone passed by: untouched
    assert guard.guard(Setpoint.velocity_ned(1.0, 0.0, 0.0),
                       vehicle_state(0.0, pos=(-1.5, 1.2, -2.0))).action is None


def test_a_position_setpoint_beyond_a_zone_is_turned_with_its_feed_forward():
    guard = _guard(margin_m=0.5)
    state = vehicle_state(0.0, pos=(-2.0, -0.05, -3.0))
    sp = Setpoint.position_velocity((2.0, 0.0, -3.0), (0.5, 0.0, 0.0))
    out = guard.guard(sp, state)
    assert out.action == "deflected"
    way = out.setpoint.position_ned_m[:2] - (-2.0, -0.05)
    assert np.linalg.norm(way) == pytest.approx(np.linalg.norm((4.0, 0.05)))
    assert way[1] < 0  # (round the side it was on)
    assert entry_distance(np.array([-2.0, -0.05]), way / np.linalg.norm(way), np.zeros(2),
                          0.9) == math.inf
    ff = out.setpoint.velocity_m_s[:2]
    assert np.linalg.norm(ff) == pytest.approx(0.5)
    assert math.atan2(ff[1], ff[0]) == pytest.approx(math.atan2(way[1], way[0]), abs=0.02)


def test_inside_a_zone_the_vehicle_is_pushed_out_never_deflected():
    guard = _guard(margin_m=0.5, push_out_speed_m_s=0.5)
    inside = vehicle_state(0.0, pos=(0.0, 0.6, -2.0))
    out = guard.guard(Setpoint.velocity_ned(0.0, -1.0, 0.0), inside)  # further in
    assert out.action == "pushed out"
    assert out.setpoint.velocity_m_s[:2] == pytest.approx((0.0, 0.5))
    out = guard.guard(Setpoint.velocity_ned(1.0, -1.0, 0.0), inside)
    assert out.setpoint.velocity_m_s[:2] == pytest.approx((1.0, 0.5))  # the tangential kept
    out = guard.guard(Setpoint.position(0.0, -3.0, -2.0), inside)
    assert out.setpoint.position_ned_m[:2] == pytest.approx((0.0, 0.92))  # its nearest edge


def test_body_frame_velocities_are_guarded_in_the_world():
    guard = _guard(margin_m=0.5)
    # facing east (yaw 90°), 1.5 m west of the zone's centre: forward is into it
    state = vehicle_state(0.0, pos=(0.0, -1.5, -2.0), yaw=math.pi / 2)
    out = guard.guard(Setpoint.velocity_body(1.0, 0.0, 0.0), state)
    assert out.action == "deflected"
    assert out.setpoint.frame is SetpointFrame.BODY_FRD
    forward, right = out.setpoint.velocity_m_s[:2]
    assert forward == pytest.approx(math.cos(math.asin(0.9 / 1.5) + math.radians(3)), abs=1e-6)
    assert abs(right) > 0.5


def test_no_zones_on_the_ground_or_both_sides_blocked():
    sp = Setpoint.velocity_ned(1.0, 0.0, 0.0)
    assert _guard(zones=()).guard(sp, vehicle_state(0.0, pos=(-1.5, 0, -2))).action is None
    landed = vehicle_state(0.0, pos=(-1.5, 0.0, 0.0), in_air=False)
    assert _guard().guard(sp, landed).action is None
    # a wall of zones across the way: no side goes round
    wall = tuple(KeepOutZone(i, (0.0, 1.0 * (i - 2)), 0.4, 5) for i in range(5))
    out = _guard(zones=wall, margin_m=0.2).guard(sp, vehicle_state(0.0, pos=(-1.0, 0, -2)))
    assert out.action == "stopped"
    assert out.setpoint.velocity_m_s[:2] == pytest.approx((0.0, 0.0))


def _fly(guard, start, goal, steps=1500, dt=0.02, lag_s=0.3, gain=1.0, max_speed=2.0):
    """A vehicle whose velocity follows the guarded command with a first-order lag, flying to
    ``goal`` by velocity setpoints: its track."""
    p, v = np.array(start, float), np.zeros(2)
    track = []
    for k in range(steps):
        want = gain * (np.asarray(goal) - p)
        n = np.linalg.norm(want)
        if n > max_speed:
            want *= max_speed / n
        state = vehicle_state(k * dt, pos=(*p, -2.0), vel=(*v, 0.0))
        sp = guard.guard(Setpoint.velocity_ned(*want, 0.0), state).setpoint
        v += (sp.velocity_m_s[:2] - v) * dt / lag_s
        p = p + v * dt
        track.append(p.copy())
    return np.array(track)


@pytest.mark.parametrize("offset", [0.0, 0.25, -0.35])
def test_a_vehicle_flying_through_a_zone_goes_round_it_and_arrives(offset):
    guard = _guard(margin_m=0.4)
    track = _fly(guard, (-4.0, offset), (4.0, offset))
    clearance = np.linalg.norm(track, axis=1).min()
    assert clearance > 0.4 + 0.3  # the disc, and most of the margin, never entered
    assert track[-1] == pytest.approx((4.0, offset), abs=0.05)
    # unguarded it would have flown straight through the disc
    assert np.linalg.norm(_fly(_guard(zones=()), (-4.0, offset), (4.0, offset)),
                          axis=1).min() < 0.4
