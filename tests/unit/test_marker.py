"""The marker detector on synthetic views: a generated marker warped into a cluttered image from
a known pose (exact geometry, lens distortion included, supersampled), and the marker board's
texture and scenario builder (no rendering)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from autopilot.perception.marker import (
    MarkerDetector,
    MarkerDetectorSettings,
    MarkerHint,
    refine_corners_on_edges,
    rotation_angle,
)
from drivers.base import CameraInfo, CameraIntrinsics
from drivers.sim.scenario import (
    BOARD_FROM_MARKER,
    Delayed,
    MarkerBoard,
    RandomWalk,
    Static,
    marker_objects,
    marker_texture,
)

SIZE = 0.16
BOARD = 0.3
HEAD_ON = np.diag([1.0, -1.0, -1.0])  # marker upright, facing the camera


def camera(f: float = 320.0, distortion=(0.0, 0.0, 0.0, 0.0, 0.0)) -> CameraInfo:
    return CameraInfo("front", CameraIntrinsics(640, 480, f, f, 319.5, 239.5, tuple(distortion)),
                      np.eye(3), np.zeros(3), 30.0)


def tilt(x_deg: float = 0.0, y_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """A marker orientation: head-on, rolled about the line of sight, then tilted about the
    camera's x and y axes."""
    r_tilt = cv2.Rodrigues(np.radians([x_deg, y_deg, 0.0]))[0]
    r_roll = cv2.Rodrigues(np.radians([0.0, 0.0, roll_deg]))[0]
    return r_tilt @ r_roll @ HEAD_ON


def clutter(width: int, height: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(60, 200, (height // 24, width // 24)).astype(np.uint8),
                     (width, height), interpolation=cv2.INTER_CUBIC)
    for _ in range(40):
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        grey = int(rng.integers(0, 256))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(15, 240)),
                                        y + int(rng.integers(15, 240))), grey, -1)
        else:
            cv2.line(img, (x, y), (int(rng.integers(0, width)), int(rng.integers(0, height))),
                     grey, int(rng.integers(3, 10)))
    return img


def render(boards, cam: CameraInfo, *, blur: float = 0.8, noise: float = 4.0, seed: int = 0,
           ss: int = 3) -> np.ndarray:
    """A grey-level view of boards ``(texture, board_side_m, R_cam_marker, t_cam_m)`` over
    clutter: each pixel's ray (through the lens distortion) meets the board's plane;
    ``ss``×``ss`` samples a pixel, then blur and noise."""
    intr = cam.intrinsics
    w, h = intr.width_px, intr.height_px
    uu, vv = np.meshgrid((np.arange(w * ss) + 0.5) / ss - 0.5, (np.arange(h * ss) + 0.5) / ss - 0.5)
    pts = np.stack((uu.ravel(), vv.ravel()), axis=-1)
    if any(intr.distortion):
        xy = cv2.undistortPoints(pts.reshape(-1, 1, 2), intr.matrix, np.array(intr.distortion),
                                 criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40,
                                           1e-10)).reshape(-1, 2)
    else:
        xy = (pts - (intr.cx, intr.cy)) / (intr.fx, intr.fy)
    rays = np.column_stack((xy, np.ones(len(xy))))
    out = clutter(w * ss, h * ss, seed + 1)
    for texture, side, r, t in boards:
        normal = r[:, 2]
        denom = rays @ normal
        lam = (t @ normal) / np.where(np.abs(denom) < 1e-12, 1e-12, denom)
        local = (rays * lam[:, None] - t) @ r  # marker frame
        n = texture.shape[0]
        col = (local[:, 0] / side + 0.5) * n - 0.5
        row = (0.5 - local[:, 1] / side) * n - 0.5
        inside = (lam > 0) & (np.abs(local[:, 0]) <= side / 2) & (np.abs(local[:, 1]) <= side / 2)
        sampled = cv2.remap(texture, col.reshape(h * ss, w * ss).astype(np.float32),
                            row.reshape(h * ss, w * ss).astype(np.float32), cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)
        out = np.where(inside.reshape(h * ss, w * ss), sampled, out)
    img = cv2.resize(out, (w, h), interpolation=cv2.INTER_AREA)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    rng = np.random.default_rng(seed)
    img = np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


def board(marker_id: int, r: np.ndarray, t, dictionary: str = "DICT_ARUCO_ORIGINAL"):
    texture, side = marker_texture(dictionary, marker_id, SIZE, BOARD, px_per_cell=24)
    return texture, side, r, np.asarray(t, dtype=float)


def projected_corners(cam: CameraInfo, r: np.ndarray, t) -> np.ndarray:
    h = SIZE / 2
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=float)
    pts, _ = cv2.projectPoints(obj, cv2.Rodrigues(r)[0], np.asarray(t, dtype=float),
                               cam.intrinsics.matrix, np.array(cam.intrinsics.distortion))
    return pts.reshape(4, 2)


BACKENDS = {
    "aruco-edges": MarkerDetectorSettings(),
    "aruco-subpix": MarkerDetectorSettings(corner_refinement="subpix"),
    "aruco-apriltag": MarkerDetectorSettings(corner_refinement="apriltag"),
    "aruco-apriltag36h11": MarkerDetectorSettings(dictionary="DICT_APRILTAG_36h11"),
    "pupil-apriltags": MarkerDetectorSettings(backend="apriltag", dictionary="tag36h11"),
}


def _dictionary(settings: MarkerDetectorSettings) -> str:
    return "DICT_APRILTAG_36h11" if "36h11" in settings.dictionary else settings.dictionary


# -- the detector -------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(BACKENDS))
@pytest.mark.parametrize(("r", "t"), [
    (tilt(25.0, -30.0, 10.0), (0.12, -0.08, 1.0)),
    (tilt(-40.0, 15.0, 100.0), (-0.25, 0.1, 1.2)),
    (tilt(0.0, 55.0, -70.0), (0.05, 0.15, 0.9)),
])
def test_pose_against_the_known_pose(name, r, t):
    settings = BACKENDS[name]
    cam = camera()
    image = render([board(36, r, t, _dictionary(settings))], cam)
    det = MarkerDetector(settings).detect(image, cam, 1.5)
    assert det is not None
    assert det.marker_id == 36
    assert det.time_s == 1.5
    assert det.camera == "front"
    assert np.abs(det.corners_px - projected_corners(cam, r, t)).max() < 1.0
    tolerance = 0.02 if name == "aruco-subpix" else 0.01  # OpenCV's subpix: 0.2-0.4 px corners
    assert np.linalg.norm(det.position_cam_m - t) < tolerance
    assert det.range_m == pytest.approx(np.linalg.norm(t), abs=tolerance)
    assert math.degrees(rotation_angle(det.rotation_cam_marker, r)) < 3.0
    assert not det.ambiguous
    assert det.chosen_by == "fit"
    assert det.reprojection_error_px < 0.5


def test_the_edge_fit_beats_subpix_and_matches_apriltag_refinement():
    """Corner error over a set of views (f = 320 px, 1 and 2 m, tilts up to 50°)."""
    cam = camera()
    rng = np.random.default_rng(3)
    errors = {"edges": [], "subpix": [], "apriltag": []}
    detectors = {k: MarkerDetector(MarkerDetectorSettings(corner_refinement=k)) for k in errors}
    for i in range(8):
        r = tilt(*rng.uniform(-35, 35, 2), rng.uniform(-180, 180))
        t = np.array([*rng.uniform(-0.2, 0.2, 2), 1.0 + i % 2])
        image = render([board(36, r, t)], cam, seed=i)
        truth = projected_corners(cam, r, t)
        for k, det in detectors.items():
            found = det.detect(image, cam, 0.0)
            if found is not None:
                errors[k].extend(np.linalg.norm(found.corners_px - truth, axis=1))
    median = {k: float(np.median(v)) for k, v in errors.items()}
    assert median["edges"] < 0.25
    assert median["edges"] < 0.6 * median["subpix"]
    assert median["edges"] < 1.5 * median["apriltag"]


def test_axes_and_corner_order():
    """Head-on and upright: R = diag(1, -1, -1), corners TL TR BR BL; rolled 90° clockwise
    (as the image shows it), the marker's x axis points down the image."""
    cam = camera()
    det = MarkerDetector()
    upright = det.detect(render([board(36, HEAD_ON, (0, 0, 0.8))], cam), cam, 0.0)
    assert np.allclose(upright.rotation_cam_marker, HEAD_ON, atol=0.06)
    tl, tr, br, bl = upright.corners_px
    assert tl[0] < tr[0]
    assert tl[1] < bl[1]
    assert br[0] > bl[0]
    assert br[1] > tr[1]
    assert abs(upright.quaternion @ [0.0, 1.0, 0.0, 0.0]) > 0.999  # a half turn about x
    assert upright.normal_cam == pytest.approx([0, 0, -1], abs=0.06)
    rolled = det.detect(render([board(36, tilt(roll_deg=90), (0, 0, 0.8))], cam), cam, 0.0)
    assert rolled.rotation_cam_marker[:, 0] == pytest.approx([0, 1, 0], abs=0.06)
    assert np.allclose(rolled.corners_px[0], upright.corners_px[1], atol=0.5)  # TL now top right


@pytest.mark.parametrize("name", ["aruco-edges", "pupil-apriltags"])
def test_only_the_configured_id_is_followed(name):
    settings = BACKENDS[name]
    cam = camera()
    d = _dictionary(settings)
    both = render([board(36, tilt(10, 0), (-0.25, 0.0, 1.2), d),
                   board(7, tilt(-10, 20), (0.25, 0.05, 1.2), d),
                   board(12, HEAD_ON, (0.0, -0.3, 1.5), d)], cam)
    det = MarkerDetector(settings).detect(both, cam, 0.0)
    assert det is not None
    assert det.position_cam_m[0] < 0  # the left one
    assert det.other_ids == (7, 12)
    decoys = render([board(7, tilt(-10, 20), (0.25, 0.05, 1.2), d),
                     board(12, HEAD_ON, (0.0, -0.3, 1.5), d)], cam)
    assert MarkerDetector(settings).detect(decoys, cam, 0.0) is None
    other = MarkerDetector(MarkerDetectorSettings(marker_id=7, backend=settings.backend,
                                                  dictionary=settings.dictionary))
    assert other.detect(decoys, cam, 0.0).other_ids == (12,)


def test_lens_distortion_is_used():
    """A marker near the corner of a strongly distorted image: right with the camera's
    coefficients, centimetres off without them."""
    dist = (-0.28, 0.09, 0.001, -0.0005, -0.012)
    cam = camera(distortion=dist)
    r, t = tilt(15, -20), np.array([-0.55, -0.38, 1.0])
    image = render([board(36, r, t)], cam)
    det = MarkerDetector().detect(image, cam, 0.0)
    assert det is not None
    assert np.abs(det.corners_px - projected_corners(cam, r, t)).max() < 1.0
    assert np.linalg.norm(det.position_cam_m - t) < 0.015
    assert math.degrees(rotation_angle(det.rotation_cam_marker, r)) < 3.0
    naive = MarkerDetector().detect(image, camera(), 0.0)
    assert np.linalg.norm(naive.position_cam_m - t) > 0.05


def _ambiguous_view():
    """A small marker nearly head-on (2.5 m at f = 320 px: 20 px): its two poses fit alike."""
    cam = camera()
    r, t = tilt(0.0, 8.0), np.array([0.05, 0.0, 2.5])
    for seed in range(10, 40):  # (10 is the first that gives one: each render takes a second)
        image = render([board(36, r, t)], cam, seed=seed)
        det = MarkerDetector().detect(image, cam, 0.0)
        if det is not None and det.ambiguous:
            return cam, r, image, det
    raise AssertionError("no ambiguous view")


def test_ambiguous_poses_are_reported_and_a_hint_chooses():
    cam, r, image, det = _ambiguous_view()
    assert det.ambiguity_ratio > MarkerDetectorSettings().ambiguity_threshold
    assert det.chosen_by == "fit"
    # the two poses: nearly the same position, orientations apart by about twice the tilt
    assert np.linalg.norm(det.position_cam_m - det.alternative.position_cam_m) < 0.05
    apart = math.degrees(rotation_angle(det.rotation_cam_marker,
                                        det.alternative.rotation_cam_marker))
    assert apart > 5.0
    detector = MarkerDetector()
    right = detector.detect(image, cam, 0.0, MarkerHint(rotation_cam_marker=r))
    assert right.chosen_by == "hint"
    assert math.degrees(rotation_angle(right.rotation_cam_marker, r)) < apart / 2
    # hinted at the other pose, that one is chosen (and the better fitting one kept aside)
    other = right.alternative.rotation_cam_marker
    flipped = detector.detect(image, cam, 0.0, MarkerHint(rotation_cam_marker=other))
    assert np.allclose(flipped.rotation_cam_marker, other)
    assert np.allclose(flipped.alternative.rotation_cam_marker, right.rotation_cam_marker)
    # an unambiguous pose ignores the hint
    clear = render([board(36, tilt(0.0, 40.0), (0.0, 0.0, 1.0))], cam)
    det = detector.detect(clear, cam, 0.0, MarkerHint(rotation_cam_marker=tilt(0.0, -40.0)))
    assert not det.ambiguous
    assert det.chosen_by == "fit"
    assert math.degrees(rotation_angle(det.rotation_cam_marker, tilt(0.0, 40.0))) < 3.0


def test_search_window_from_a_hint():
    cam = camera()
    r, t = tilt(20, 10), np.array([0.3, 0.1, 1.4])
    image = render([board(36, r, t), board(5, HEAD_ON, (-0.4, -0.2, 1.5))], cam)
    det = MarkerDetector()
    full = det.detect(image, cam, 0.0)
    assert full.window is None
    assert full.other_ids == (5,)
    hinted = det.detect(image, cam, 0.0, MarkerHint.from_detection(full))
    assert hinted.window is not None
    x0, y0, x1, y1 = hinted.window
    assert (x1 - x0) * (y1 - y0) < 0.2 * 640 * 480
    assert np.allclose(hinted.corners_px, full.corners_px, atol=0.05)
    assert np.allclose(hinted.position_cam_m, full.position_cam_m, atol=2e-3)
    assert hinted.other_ids == ()  # only the window was searched
    # a hint in the wrong place: the window misses, the whole image is searched
    lost = det.detect(image, cam, 0.0, MarkerHint((60.0, 400.0), 30.0))
    assert lost.window is None
    assert np.allclose(lost.corners_px, full.corners_px)


def test_hint_from_detection():
    cam = camera()
    det = MarkerDetector().detect(render([board(36, tilt(0, 30), (0.0, 0.0, 1.0))], cam), cam,
                                  0.0)
    hint = MarkerHint.from_detection(det)
    assert hint.center_px == pytest.approx(tuple(cam.intrinsics.project(np.array([0, 0, 1.0]))),
                                           abs=0.5)
    assert hint.size_px == pytest.approx(det.size_px)
    assert hint.rotation_cam_marker is det.rotation_cam_marker


def test_edge_fit_ignores_a_hopeless_start():
    image = np.full((100, 100), 128, np.uint8)
    corners = np.array([[30.0, 30.0], [70.0, 30.0], [70.0, 70.0], [30.0, 70.0]])
    assert np.array_equal(refine_corners_on_edges(image, corners, 7), corners)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"dictionary": "DICT_9X9_1"}, "unknown marker dictionary"),
    ({"backend": "apriltag", "dictionary": "DICT_4X4_50"}, "families"),
    ({"backend": "opencv"}, "backend"),
    ({"corner_refinement": "magic"}, "corner_refinement"),
    ({"size_m": 0.0}, "size_m"),
])
def test_settings_are_checked(kwargs, message):
    with pytest.raises(ValueError, match=message):
        MarkerDetectorSettings(**kwargs)


def test_apriltag_family_names_either_way():
    cam = camera()
    image = render([board(3, tilt(10, 10), (0, 0, 1.0), "DICT_APRILTAG_36h11")], cam)
    for backend, name in (("aruco", "tag36h11"), ("apriltag", "DICT_APRILTAG_36h11")):
        det = MarkerDetector(MarkerDetectorSettings(marker_id=3, backend=backend,
                                                    dictionary=name)).detect(image, cam, 0.0)
        assert det is not None
        assert np.linalg.norm(det.position_cam_m - (0, 0, 1.0)) < 0.01


# -- the simulated board (no rendering) -----------------------------------------------------


@pytest.mark.parametrize(("dictionary", "cells"), [("DICT_ARUCO_ORIGINAL", 7),
                                                   ("DICT_4X4_50", 6), ("tag36h11", 8)])
def test_board_texture_puts_the_marker_in_the_middle_at_its_size(dictionary, cells):
    image, side_m = marker_texture(dictionary, 36 % 50, 0.16, 0.3, px_per_cell=16)
    n = image.shape[0]
    dark = np.flatnonzero((image < 128).any(axis=0))
    marker_px = dark[-1] - dark[0] + 1
    assert marker_px == cells * 16
    assert marker_px / n * side_m == pytest.approx(0.16)
    assert side_m == pytest.approx(0.3, abs=0.3 / n)
    assert dark[0] == n - 1 - dark[-1]  # centred
    assert (image[0] == 255).all()
    assert (image[:, -1] == 255).all()


def test_board_frame_and_marker_axes():
    # the marker's z is the board's normal (body x), its y is up (body -z)
    assert BOARD_FROM_MARKER[:, 2] == pytest.approx([1, 0, 0])
    assert BOARD_FROM_MARKER[:, 1] == pytest.approx([0, 0, -1])
    assert np.linalg.det(BOARD_FROM_MARKER) == pytest.approx(1.0)


def test_board_headings():
    b = MarkerBoard("m", 36, Static((2.0, 0.0, -1.5)), facing="drone")
    assert b.moves  # turns to the vehicle even when standing still
    assert b.heading(np.array([2.0, 0.0, -1.5]), 0.3, np.array([0.0, 0.0, -2.0])) == \
        pytest.approx(math.pi)
    assert b.heading(np.array([2.0, 0.0, -1.5]), 0.3, np.array([2.0, 1.0, -2.0])) == \
        pytest.approx(math.pi / 2)
    travel = MarkerBoard("m", 36, Static((2.0, 0.0, -1.5)), facing="travel")
    assert not travel.moves
    assert travel.heading(np.zeros(3), 0.3, None) == pytest.approx(0.3)
    trail = MarkerBoard("m", 36, Static((2.0, 0.0, -1.5)), facing="trail")
    assert trail.heading(np.zeros(3), 0.3, None) == pytest.approx(0.3 + math.pi)
    fixed = MarkerBoard("m", 36, Static((2.0, 0.0, -1.5)), facing="fixed", yaw_deg=-90)
    assert fixed.heading(np.zeros(3), 0.3, np.ones(3)) == pytest.approx(-math.pi / 2)
    with pytest.raises(ValueError, match="facing"):
        MarkerBoard("m", 36, Static((0.0, 0.0, 0.0)), facing="sideways")
    with pytest.raises(ValueError, match="no marker"):
        MarkerBoard("m", 50, Static((0.0, 0.0, 0.0)), dictionary="DICT_4X4_50")


@pytest.mark.parametrize("path", ["static", "circle", "figure8", "lissajous", "random_walk"])
def test_marker_objects(path):
    objects = marker_objects(path=path, speed_mps=1.0, height_m=1.2, start_distance_m=1.5,
                             heading_deg=90.0, origin_north_east_m=(1.0, 2.0), decoys=3,
                             decoy_ids=(7,), seed=4, facing="trail")
    main, *decoys = objects
    assert isinstance(main, MarkerBoard)
    assert main.name == "marker"
    assert main.marker_id == 36
    assert main.facing == "trail"
    pos, vel, _ = main.trajectory(0.0)
    assert pos == pytest.approx([1.0, 3.5, -1.2])  # 1.5 m east of the start, 1.2 m up
    if path == "static":
        assert not main.moves
        assert np.allclose(vel, 0.0)
    else:
        later, vel, _ = main.trajectory(5.0)
        assert np.linalg.norm(later - pos) > (0.5 if path == "random_walk" else 1.0)
        assert 0.3 < np.linalg.norm(vel) < 2.0
    assert next(d.marker_id for d in decoys) == 7
    assert len({d.marker_id for d in decoys}) == 3
    assert 36 not in {d.marker_id for d in decoys}
    assert [d.name for d in decoys] == ["marker_decoy0", "marker_decoy1", "marker_decoy2"]
    for d in decoys:
        p = d.trajectory(0.0)[0]
        assert np.linalg.norm(p[:2] - (1.0, 2.0)) > 1.5
        assert np.linalg.norm(p - pos) > 0.6
        assert d.facing == "drone"
    again = marker_objects(path=path, speed_mps=1.0, decoys=3, seed=4)
    assert [d.marker_id for d in again[1:]] == \
        [d.marker_id for d in marker_objects(path=path, speed_mps=1.0, decoys=3, seed=4)[1:]]


def test_marker_objects_delay_and_fixed_default():
    main = marker_objects(path="circle", speed_mps=1.0, start_delay_s=2.0, accel_mps2=0.5,
                          facing="fixed", heading_deg=30.0)[0]
    assert isinstance(main.trajectory, Delayed)
    assert main.yaw_deg == pytest.approx(210.0)  # looking back at the start
    assert np.allclose(main.trajectory(1.0)[0], main.trajectory(0.0)[0])


@pytest.mark.parametrize("seed", [0, 1])
def test_random_walk_moves_as_a_body_can(seed):
    # a walk asked for 2.5 m/s RMS within about 4 m of its start, accelerating at most 2 m/s²:
    # turning back at the edge at 2 m/s² costs speed (about 2.1 m/s RMS); with room, it
    # keeps its speed
    walk = RandomWalk((1.0, 2.0, -1.5), 2.5, seed=seed, radius_m=4.0, max_accel_m_s2=2.0,
                      duration_s=610.0)
    times = np.arange(0.0, 600.0, 0.05)
    samples = [walk(t) for t in times]
    pos = np.array([s[0] for s in samples])
    vel = np.array([s[1] for s in samples])
    speed = np.linalg.norm(vel, axis=1)
    assert 2.0 <= np.sqrt(np.mean(speed ** 2)) <= 2.6
    roomy = RandomWalk((0.0, 0.0, -1.5), 1.0, seed=seed, radius_m=10.0, max_accel_m_s2=2.0)
    assert np.sqrt(np.mean(np.sum(roomy._vel ** 2, axis=1))) == pytest.approx(1.0, rel=0.05)
    accel = np.linalg.norm(np.diff(vel, axis=0), axis=1) / 0.05
    assert accel.max() <= 2.0 + 1e-6
    # the velocity is the position's derivative; it stays near the start, on its plane
    assert np.allclose(np.diff(pos, axis=0) / 0.05, 0.5 * (vel[1:] + vel[:-1]), atol=0.03)
    reach = np.linalg.norm(pos[:, :2] - (1.0, 2.0), axis=1)
    assert np.percentile(reach, 95) < 4.0 * 2.0  # a soft edge: it turns back at 2 m/s²
    assert np.allclose(pos[:, 2], -1.5)
    again = RandomWalk((1.0, 2.0, -1.5), 2.5, seed=seed, radius_m=4.0, max_accel_m_s2=2.0,
                       duration_s=610.0)
    assert np.allclose(again(123.4)[0], walk(123.4)[0])  # seeded
