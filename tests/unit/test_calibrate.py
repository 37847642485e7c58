"""``autopilot calibrate``'s core (autopilot/calibration/): board specs, detection, view
selection, the fit and its files, against a camera whose truth the test sets.

Views are made with plain OpenCV, no simulator: board corners projected with
``cv2.projectPoints``, or whole images rendered by ray-casting every pixel (through the lens
model, 2×2 supersampled) onto a printed board's texture.
"""

from __future__ import annotations

import functools
import json
import math

import cv2
import numpy as np
import pytest

from autopilot.calibration import (
    BoardDetector,
    BoardSpec,
    BoardView,
    CalibrationFailed,
    CalibrationOptions,
    FrameSource,
    SourceFrame,
    calibrate,
    calibrate_frames,
    consistent_corners,
    parse_board_spec,
    select_views,
    write_result,
)
from autopilot.cli import EXIT_OK, EXIT_USAGE, main
from autopilot.config import InputError
from drivers.base import CameraIntrinsics
from drivers.calibration import load_calibration
from drivers.camera_model import project_points, undistort_points

#: The camera the views are made with: non-square pixels, an off-centre principal point and
#: a barrel lens, so that a calibration that ignored any of them would show it.
CAMERA = CameraIntrinsics(640, 480, 400.0, 404.0, 323.0, 236.5,
                          (-0.12, 0.03, 0.0008, -0.0005, 0.0))
CHESSBOARD = "chessboard:9x7:0.03"
CHARUCO = "charuco:8x6:0.035:0.026:DICT_4X4_50"


# -- making views --------------------------------------------------------------------------


def _poses(board: BoardSpec, count: int, seed: int, whole: bool,
           distance_m: tuple[float, float] = (0.35, 0.6)):
    """Board poses (rvec, tvec) spread over the image (centre on a jittered 4×3 grid), tilted
    up to 45° in any direction and rolled ±20°; ``whole``: every corner inside the image."""
    rng = np.random.default_rng(seed)
    obj = board.object_points_m()
    poses = []
    while len(poses) < count:
        cell = len(poses) % 12
        u = (cell % 4 + rng.uniform(0.1, 0.9)) * CAMERA.width_px / 4
        v = (cell // 4 + rng.uniform(0.1, 0.9)) * CAMERA.height_px / 3
        tilt, psi = math.radians(rng.uniform(5.0, 45.0)), rng.uniform(0.0, 2.0 * math.pi)
        r_tilt, _ = cv2.Rodrigues(tilt * np.array([math.cos(psi), math.sin(psi), 0.0]))
        r_roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, math.radians(rng.uniform(-20, 20))]))
        r = r_roll @ r_tilt
        x, y = undistort_points(CAMERA, (u, v))
        centre = rng.uniform(*distance_m) * np.array([x, y, 1.0]) / math.hypot(x, y, 1.0)
        t = centre - r @ board.centre_m()
        uv = project_points(CAMERA, obj @ r.T + t)
        inside = (np.isfinite(uv).all(axis=1) & (uv[:, 0] > 8) & (uv[:, 1] > 8)
                  & (uv[:, 0] < CAMERA.width_px - 9) & (uv[:, 1] < CAMERA.height_px - 9))
        if inside.all() or (not whole and inside.mean() > 0.5):
            poses.append((cv2.Rodrigues(r)[0].ravel(), t))
    return poses


def _projected_views(board: BoardSpec, count: int, noise_px: float, seed: int = 1):
    """BoardViews of projected corners (those inside the image), with Gaussian noise."""
    rng = np.random.default_rng(seed + 100)
    obj = board.object_points_m()
    views = []
    for n, (rvec, tvec) in enumerate(_poses(board, count, seed, whole=False)):
        r, _ = cv2.Rodrigues(rvec)
        uv = project_points(CAMERA, obj @ r.T + tvec)
        inside = np.isfinite(uv).all(axis=1) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) \
            & (uv[:, 0] <= CAMERA.width_px - 1) & (uv[:, 1] <= CAMERA.height_px - 1)
        ids = np.flatnonzero(inside)
        views.append(BoardView(f"view{n:02d}", uv[ids] + rng.normal(0.0, noise_px,
                                                                     (len(ids), 2)), ids, 1.2))
    return views


@functools.lru_cache(maxsize=4)
def _texture(board: BoardSpec, px_per_square: int = 32) -> tuple[np.ndarray, int]:
    """The printed board, one square margin; returns the image and the margin (texels)."""
    margin = px_per_square
    if board.pattern == "chessboard":
        cells = (np.indices((board.rows, board.columns)).sum(axis=0) % 2).astype(np.uint8) * 255
        face = np.kron(cells, np.ones((px_per_square, px_per_square), np.uint8))
        return cv2.copyMakeBorder(face, margin, margin, margin, margin, cv2.BORDER_CONSTANT,
                                  value=255), margin
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    cv_board = cv2.aruco.CharucoBoard((board.columns, board.rows), board.square_m,
                                      board.marker_m, dictionary)
    size = (board.columns * px_per_square + 2 * margin, board.rows * px_per_square + 2 * margin)
    return cv_board.generateImage(size, marginSize=margin, borderBits=1), margin


_RAYS: dict[CameraIntrinsics, tuple[np.ndarray, np.ndarray]] = {}


def _render(board: BoardSpec, rvec, tvec, *, blur_px: float = 0.0, noise_dn: float = 1.5,
            seed: int = 0, px_per_square: int = 32) -> np.ndarray:
    """The camera's grey image of the board at a pose: each of 2×2 sub-pixels' rays (through
    the lens) meets the board's plane at a texel; a grey background elsewhere."""
    texture, margin = _texture(board, px_per_square)
    if CAMERA not in _RAYS:
        w, h = CAMERA.width_px, CAMERA.height_px
        u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
        xy = undistort_points(CAMERA, np.column_stack([u.ravel(), v.ravel()]))
        # the sub-pixels' centres, (i + 0.5) / 2 - 0.5, are where cv2.resize samples when it
        # doubles an image: the smooth undistortion, interpolated there
        x2, y2 = (cv2.resize(c.reshape(h, w).astype(np.float32), (2 * w, 2 * h),
                             interpolation=cv2.INTER_LINEAR) for c in xy.T)
        _RAYS[CAMERA] = (x2, y2)
    x, y = _RAYS[CAMERA]  # each sub-pixel's ray: (x, y, 1)
    r, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    # the rays along the board's axes (element-wise: a BLAS product of a million rows is
    # slow when the machine is busy); the camera's view of the board's origin
    along = [x * np.float32(r[0, k]) + y * np.float32(r[1, k]) + np.float32(r[2, k])
             for k in range(3)]
    origin = r.T @ np.asarray(tvec, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.float32(origin[2]) / along[2]  # where each ray meets the board's plane
    scale = np.float32(px_per_square / board.square_m)
    map_x, map_y = (np.where(s > 0, (s * along[k] - np.float32(origin[k])) * scale
                             + np.float32(margin - 0.5), np.float32(-10.0)) for k in (0, 1))
    big = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=110)
    image = cv2.resize(big.astype(np.float32) * 0.8 + 20.0, (CAMERA.width_px, CAMERA.height_px),
                       interpolation=cv2.INTER_AREA)
    if blur_px > 0.0:
        image = cv2.GaussianBlur(image, (0, 0), blur_px)
    image += np.random.default_rng(seed).normal(0.0, noise_dn, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Image folders of each board, 18 sharp views and one blurred (``view99.png``)."""
    folders = {}
    for spec in (CHESSBOARD, CHARUCO):
        board = parse_board_spec(spec)
        folder = tmp_path_factory.mktemp(board.pattern)
        poses = _poses(board, 19, seed=7, whole=board.pattern == "chessboard")
        for n, (rvec, tvec) in enumerate(poses[:-1]):
            cv2.imwrite(str(folder / f"view{n:02d}.png"), _render(board, rvec, tvec, seed=n))
        cv2.imwrite(str(folder / "view99.png"), _render(board, *poses[-1], blur_px=2.5))
        folders[board.pattern] = folder
    return folders


# -- board specs -----------------------------------------------------------------------------


def test_board_specs_count_squares():
    board = parse_board_spec("chessboard:10x7:0.025")
    assert board == BoardSpec("chessboard", 10, 7, 0.025)
    assert board.inner_corners == (9, 6)
    assert board.corner_count == 54
    assert parse_board_spec(board.text) == board
    charuco = parse_board_spec("ChArUco:11X8:0.03:0.022:5x5_100")
    assert charuco == BoardSpec("charuco", 11, 8, 0.03, 0.022, "DICT_5X5_100")
    assert parse_board_spec(charuco.text) == charuco


def test_corner_ids_and_positions_are_opencvs():
    board = parse_board_spec("charuco:5x4:0.04:0.03:DICT_4X4_50")
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    cv_board = cv2.aruco.CharucoBoard((5, 4), 0.04, 0.03, dictionary)
    np.testing.assert_allclose(board.object_points_m(), cv_board.getChessboardCorners(),
                               atol=1e-7)


@pytest.mark.parametrize(("spec", "match"), [
    ("charuco:8x6:0.06", "a charuco takes 4 fields"),
    ("chessboard:8x6", "a chessboard takes 2 fields"),
    ("grid:8x6:0.06", "unknown pattern 'grid'"),
    ("chessboard:8by6:0.06", "'8by6' is not COLSxROWS"),
    ("chessboard:3x6:0.06", "at least 4x4 squares"),
    ("chessboard:8x6:25", "in metres: 25 m .*0.025"),
    ("chessboard:8x6:-0.1", "must be positive"),
    ("chessboard:8x6:abc", "SQUARE_M 'abc' is not a number"),
    ("charuco:8x6:0.03:0.04:DICT_4X4_50", r"MARKER_M \(0.04\) must be smaller"),
    ("charuco:8x6:0.03:0.02:DICT_9X9_1", "no ArUco dictionary 'DICT_9X9_1'"),
    ("charuco:12x10:0.03:0.02:DICT_4X4_50", "has 50 markers; a 12x10 ChArUco board needs 60"),
])
def test_bad_board_specs_say_the_expected_form(spec, match):
    with pytest.raises(InputError, match=match) as err:
        parse_board_spec(spec)
    assert "expected chessboard:COLSxROWS:SQUARE_M or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT" \
        in str(err.value)


# -- the fit ---------------------------------------------------------------------------------


def _assert_close_to_truth(intr: CameraIntrinsics, focal_pct: float, centre_px: float,
                           model_px: float) -> None:
    assert abs(intr.fx - CAMERA.fx) / CAMERA.fx * 100 < focal_pct
    assert abs(intr.fy - CAMERA.fy) / CAMERA.fy * 100 < focal_pct
    assert math.hypot(intr.cx - CAMERA.cx, intr.cy - CAMERA.cy) < centre_px
    # the whole lens model: pixels within the image, through the estimate and back through
    # the truth, land where they started
    u, v = np.meshgrid(np.linspace(20, 620, 16), np.linspace(20, 460, 12))
    grid = np.column_stack([u.ravel(), v.ravel()])
    rays = undistort_points(intr, grid)
    back = project_points(CAMERA, np.column_stack([rays, np.ones(len(rays))]))
    assert np.abs(back - grid).max() < model_px


def test_calibrates_exact_corners_to_the_true_camera():
    board = parse_board_spec(CHARUCO)
    result = calibrate(_projected_views(board, 20, noise_px=0.0), board, (640, 480))
    _assert_close_to_truth(result.intrinsics, focal_pct=1e-3, centre_px=1e-3, model_px=1e-3)
    assert result.reprojection_rms_px < 1e-3
    assert result.intrinsics.distortion == pytest.approx(CAMERA.distortion, abs=1e-5)


def test_calibrates_noisy_corners_and_reports_each_view():
    board = parse_board_spec(CHARUCO)
    views = _projected_views(board, 25, noise_px=0.05)
    result = calibrate(views, board, (640, 480))
    # this small board's views fix fx to about ±0.25 px (the fit's own σ)
    assert max(result.std_px) < 0.4
    _assert_close_to_truth(result.intrinsics, focal_pct=0.3, centre_px=1.5, model_px=1.5)
    assert 0.03 < result.reprojection_rms_px < 0.1  # the noise: 0.05 px per axis
    assert len(result.views) == 25
    assert not result.rejected
    assert {v.name for v in result.views} == {v.name for v in views}
    assert all(v.rms_px < 0.15 for v in result.views)
    assert result.coverage.cells_fraction > 0.8
    assert result.coverage.tilt_deg_max > 30.0


def test_a_view_that_does_not_fit_is_dropped_and_the_camera_refitted():
    board = parse_board_spec(CHARUCO)
    views = _projected_views(board, 20, noise_px=0.05)
    bad = views[5]
    rng = np.random.default_rng(3)
    shaken = bad.image_points_px + rng.normal(0, 2.0, bad.image_points_px.shape)
    views[5] = BoardView(bad.name, shaken, bad.corner_ids, bad.edge_width_px)
    result = calibrate(views, board, (640, 480))
    assert [(r.name, r.reason) for r in result.rejected] == [(bad.name, "outlier")]
    assert bad.name not in {v.name for v in result.views}
    _assert_close_to_truth(result.intrinsics, focal_pct=0.3, centre_px=1.5, model_px=1.5)
    assert result.reprojection_rms_px < 0.1


def test_too_few_views_is_refused():
    board = parse_board_spec(CHARUCO)
    with pytest.raises(CalibrationFailed, match="4 usable views of the board; need at least 10"):
        calibrate(_projected_views(board, 4, noise_px=0.05), board, (640, 480))


def test_selection_drops_blurry_views_and_duplicates_and_keeps_the_corners_covered():
    board = parse_board_spec(CHARUCO)
    views = _projected_views(board, 30, noise_px=0.05)
    blurry = BoardView("blurry", views[0].image_points_px + 5.0, views[0].corner_ids, 4.0)
    twin = BoardView("twin", views[1].image_points_px + 0.3, views[1].corner_ids, 1.3)
    options = CalibrationOptions(max_views=12)
    selection = select_views([*views, blurry, twin], board, (640, 480), options)
    reasons = {r.name: r.reason for r in selection.rejected}
    assert reasons["blurry"] == "blurry"
    assert reasons["twin"] == "duplicate"
    assert views[1].name not in reasons  # the sharper of the two is kept
    assert len(selection.views) == 12
    assert sum(r == "not_needed" for r in reasons.values()) == 30 - 12 - 0
    # whatever reached each of the image's corner cells, some chosen view reaches too
    for corner in ((0, 0), (640, 0), (0, 480), (640, 480)):
        def near(view, corner=corner):
            return np.min(np.hypot(*(view.image_points_px - corner).T)) < 90

        if any(near(v) for v in views):
            assert any(near(v) for v in selection.views), corner


def test_misplaced_corners_are_found():
    ids = np.arange(48)
    grid = np.column_stack([ids % 8, ids // 8]) * 22.0 + 100.0
    h = np.array([[1.0, 0.1, 0.0], [0.05, 0.9, 0.0], [4e-4, 2e-4, 1.0]])
    q = np.column_stack([grid, np.ones(48)]) @ h.T
    points = q[:, :2] / q[:, 2:] + np.random.default_rng(0).normal(0, 0.1, (48, 2))
    assert consistent_corners(points, ids, 8).all()
    points[[5, 20, 47]] += [[4.0, 0.0], [0.0, -3.0], [2.5, 2.5]]
    assert list(np.flatnonzero(~consistent_corners(points, ids, 8))) == [5, 20, 47]


def test_edge_width_measures_blur():
    board = parse_board_spec(CHESSBOARD)
    detector = BoardDetector(board)
    rvec, tvec = _poses(board, 1, seed=2, whole=True)[0]
    widths = [detector.detect(_render(board, rvec, tvec, blur_px=sigma)).edge_width_px
              for sigma in (0.0, 1.0, 2.0)]
    assert widths[0] < 1.8
    assert widths == sorted(widths)
    # a Gaussian blur of σ widens a step to about √(2π)·σ
    assert widths[2] == pytest.approx(2.5 * 2.0, rel=0.2)


# -- images ----------------------------------------------------------------------------------


@pytest.mark.parametrize("pattern", ["chessboard", "charuco"])
def test_calibrates_rendered_images_of_either_board(rendered, pattern):
    board = parse_board_spec(CHESSBOARD if pattern == "chessboard" else CHARUCO)
    source = FrameSource(str(rendered[pattern]))
    result = calibrate_frames(source, board)
    assert result.frames_read == 19
    used = {v.name for v in result.views}
    assert "view99.png" not in used  # blurred: not found, or left out as blurry
    assert len(used) >= 15
    assert result.reprojection_rms_px < 0.3
    _assert_close_to_truth(result.intrinsics, focal_pct=0.5, centre_px=2.0, model_px=1.0)


def test_both_files_are_written_and_load_back(rendered, tmp_path):
    board = parse_board_spec(CHARUCO)
    result = calibrate_frames(FrameSource(str(rendered["charuco"])), board)
    out, ros = write_result(result, tmp_path / "front.yaml", camera_name="front")
    assert ros == tmp_path / "front_ros.yaml"
    for path in (out, ros):
        got = load_calibration(path)
        intr = result.intrinsics
        assert (got.width_px, got.height_px) == (640, 480)
        assert (got.fx, got.fy, got.cx, got.cy) == pytest.approx(
            (intr.fx, intr.fy, intr.cx, intr.cy), abs=1e-9)
        assert got.distortion == pytest.approx(intr.distortion, abs=1e-12)
    text = out.read_text()
    assert text.startswith("%YAML")
    assert "reprojection_rms_px:" in text
    assert f"views: {len(result.views)}" in text
    assert "camera_name: front" in ros.read_text()
    (tmp_path / "ros").mkdir()
    _, elsewhere = write_result(result, tmp_path / "a.yaml", tmp_path / "ros" / "b.yaml")
    assert elsewhere == tmp_path / "ros" / "b.yaml"
    assert load_calibration(elsewhere).fx == pytest.approx(result.intrinsics.fx)


def test_a_folder_without_the_board_says_so(tmp_path):
    for i in range(3):
        noise = np.random.default_rng(i).integers(0, 255, (240, 320), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / f"{i}.png"), noise)
    board = parse_board_spec("chessboard:10x7:0.025")
    with pytest.raises(CalibrationFailed, match=r"no chessboard 10x7 found in any of the 3 "
                       r"frames\..*9x6 inner corners"):
        calibrate_frames(FrameSource(str(tmp_path)), board)


def test_too_few_views_in_a_folder_says_how_many(rendered, tmp_path):
    for name in ("view00.png", "view01.png", "view02.png"):
        (tmp_path / name).write_bytes((rendered["charuco"] / name).read_bytes())
    with pytest.raises(CalibrationFailed, match=r"found in 3 of 3 frames, 3 of them usable.*"
                       r"need at least 10 views"):
        calibrate_frames(FrameSource(str(tmp_path)), parse_board_spec(CHARUCO))


def test_sources_that_cannot_be_read(tmp_path):
    with pytest.raises(InputError, match="no such file or folder"):
        FrameSource(str(tmp_path / "missing"))
    with pytest.raises(InputError, match="no images in this folder"):
        FrameSource(str(tmp_path))
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match="none of its 1 image files could be read"):
        list(FrameSource(str(tmp_path)))
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((10, 20), np.uint8))
    cv2.imwrite(str(tmp_path / "wide.png"), np.zeros((10, 30), np.uint8))
    source = FrameSource(str(tmp_path))
    with pytest.raises(InputError, match=r"wide\.png: 30x10 pixels, but small\.png is 20x10"):
        calibrate_frames(source, parse_board_spec(CHESSBOARD))
    assert source.skipped == ["broken.png"]


def test_ctrl_c_ends_a_live_source_and_calibrates_with_what_was_read(rendered):
    board = parse_board_spec(CHARUCO)
    files = sorted(rendered["charuco"].glob("view0*.png")) + sorted(
        rendered["charuco"].glob("view1*.png"))

    class Stream:
        live = True

        def __iter__(self):
            for path in files[:12]:
                yield SourceFrame(path.name, cv2.imread(str(path)))
            raise KeyboardInterrupt

    result = calibrate_frames(Stream(), board)
    assert result.frames_read == 12
    Stream.live = False  # a folder or a file: Ctrl-C aborts
    with pytest.raises(KeyboardInterrupt):
        calibrate_frames(Stream(), board)


def test_a_video_file_is_read_frame_by_frame(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    if not writer.isOpened():
        pytest.skip("OpenCV cannot write MJPG video here")
    for i in range(8):
        writer.write(np.full((48, 64, 3), 30 * i, np.uint8))
    writer.release()
    frames = list(FrameSource(str(path), every=2, max_frames=3))
    assert [f.name for f in frames] == ["frame 0", "frame 2", "frame 4"]
    assert [int(f.image.mean() / 30 + 0.5) for f in frames] == [0, 2, 4]


# -- the command -----------------------------------------------------------------------------


def test_the_command_prints_a_summary_and_writes_both_files(rendered, tmp_path, capsys):
    out = tmp_path / "cam.yaml"
    code = main(["calibrate", str(rendered["chessboard"]), "--board", CHESSBOARD,
                 "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == EXIT_OK
    for part in ("views:", "coverage:", "reprojection RMS", "fx ", "distortion: k1"):
        assert part in printed
    assert f"wrote {out} (OpenCV) and {tmp_path / 'cam_ros.yaml'}" in printed
    assert load_calibration(tmp_path / "cam_ros.yaml").fx == pytest.approx(
        load_calibration(out).fx)

    code = main(["calibrate", str(rendered["chessboard"]), "--board", CHESSBOARD,
                 "--out", str(tmp_path / "again.yaml"), "--json"])
    data = json.loads(capsys.readouterr().out)
    assert code == EXIT_OK
    assert abs(data["fx_px"] - CAMERA.fx) / CAMERA.fx < 0.005
    assert data["views_used"] == len(data["views"]) >= 15
    assert set(data["rejected"]) == {"blurry", "duplicate", "not_needed", "outlier"}


@pytest.mark.parametrize(("args", "match"), [
    (["--board", "chessboard:9x7"], "expected chessboard:COLSxROWS:SQUARE_M"),
    (["--board", CHESSBOARD, "--min-views", "50"], "--min-views 50"),
])
def test_the_command_refuses_bad_input_with_exit_2(rendered, tmp_path, capsys, args, match):
    code = main(["calibrate", str(rendered["chessboard"]), "--out", str(tmp_path / "c.yaml"),
                 *args])
    assert code == EXIT_USAGE
    assert match in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()
