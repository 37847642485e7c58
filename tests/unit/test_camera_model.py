"""The pinhole + OpenCV distortion camera model (drivers/camera_model.py)."""

import math

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from drivers import camera_model as cm
from drivers.base import CameraIntrinsics

FRONT = cm.pinhole(640, 480, 90.0, (-0.08, 0.012, 0.0005, -0.0003, 0.0))
DOWN = cm.pinhole(640, 480, 80.0, (-0.05, 0.006, 0.0003, 0.0002, 0.0))
STRONG = CameraIntrinsics(800, 600, 410.0, 412.0, 405.3, 297.8, (-0.25, 0.07, 0.001, -0.002, 0.0))
IDEAL = cm.pinhole(640, 480, 90.0)
CAMERAS = [FRONT, DOWN, STRONG]


def _pixel_grid(intr: CameraIntrinsics, step: float = 4.0) -> np.ndarray:
    """Pixels over the whole image, edges and corners included."""
    u = np.append(np.arange(-0.5, intr.width_px - 0.5, step), intr.width_px - 0.5)
    v = np.append(np.arange(-0.5, intr.height_px - 0.5, step), intr.height_px - 0.5)
    uu, vv = np.meshgrid(u, v)
    return np.column_stack([uu.ravel(), vv.ravel()])


def test_pinhole_matches_the_field_of_view_and_centres_the_principal_point():
    assert math.degrees(FRONT.hfov_rad) == pytest.approx(90.0)
    assert FRONT.fx == FRONT.fy == pytest.approx(320.0)
    assert (FRONT.cx, FRONT.cy) == (319.5, 239.5)  # pixel centres at integers
    assert FRONT.distortion == (-0.08, 0.012, 0.0005, -0.0003, 0.0)


@pytest.mark.parametrize("intr", CAMERAS, ids=["front", "down", "strong"])
def test_undistort_then_project_round_trip_within_a_hundredth_of_a_pixel(intr):
    pixels = _pixel_grid(intr)
    xy = cm.undistort_points(intr, pixels)
    back = cm.project_points(intr, np.column_stack([xy, np.ones(len(xy))]))
    assert np.max(np.abs(back - pixels)) < 0.01
    # and through the normalised distortion and the camera matrix
    xd = cm.distort_points(intr, xy)
    uv = xd * (intr.fx, intr.fy) + (intr.cx, intr.cy)
    assert np.max(np.abs(uv - pixels)) < 0.01


@pytest.mark.parametrize("intr", CAMERAS, ids=["front", "down", "strong"])
def test_distort_then_undistort_round_trip(intr):
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1.0, 1.0, (500, 2)) * (intr.cx / intr.fx, intr.cy / intr.fy)
    pixels = cm.distort_points(intr, xy) * (intr.fx, intr.fy) + (intr.cx, intr.cy)
    again = cm.undistort_points(intr, pixels)
    assert np.max(np.abs(again - xy) * intr.fx) < 0.01


@pytest.mark.parametrize("intr", CAMERAS, ids=["front", "down", "strong"])
def test_projection_matches_opencv(intr):
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-1, 1, 300), rng.uniform(-0.8, 0.8, 300),
                              rng.uniform(1.0, 2.0, 300)]) * rng.uniform(0.5, 20, (300, 1))
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), intr.matrix,
                                    np.array(intr.distortion))
    got = cm.project_points(intr, points)
    np.testing.assert_allclose(got, expected.reshape(-1, 2), atol=1e-9)
    # one point in, one pixel out
    np.testing.assert_allclose(cm.project_points(intr, points[0]), expected[0, 0], atol=1e-9)


def test_undistorted_camera_is_the_plain_pinhole():
    points = np.array([[0.3, -0.2, 2.0], [-1.0, 0.7, 1.5]])
    for p in points:
        np.testing.assert_allclose(cm.project_points(IDEAL, p), IDEAL.project(p), atol=1e-9)
    pixels = np.array([[10.0, 20.0], [600.5, 470.0]])
    np.testing.assert_allclose(cm.undistort_points(IDEAL, pixels, to_pixels=True), pixels)
    np.testing.assert_allclose(cm.undistort_points(IDEAL, pixels),
                               (pixels - (IDEAL.cx, IDEAL.cy)) / IDEAL.fx)


def test_barrel_distortion_pulls_the_edges_in():
    """k1 < 0: a point off-axis is imaged nearer the centre than the pinhole would put it, and
    more so further out; the front camera's side edges see 94.7° instead of the pinhole's 90°."""
    edge = np.array([1.0, 0.0, 1.0])  # 45° to the right: the pinhole image's edge
    ideal_u = IDEAL.project(edge)[0]
    u = cm.project_points(FRONT, edge)[0]
    k1, k2 = FRONT.distortion[:2]
    assert ideal_u - u == pytest.approx(-FRONT.fx * (k1 + k2), abs=0.5)  # r·(1 + k1 r² + k2 r⁴)
    half = cm.project_points(FRONT, [0.5, 0.0, 1.0])[0]
    assert 0 < (IDEAL.project([0.5, 0.0, 1.0])[0] - half) < (ideal_u - u) / 4
    assert cm.project_points(FRONT, [0.0, 0.0, 3.0]) == pytest.approx([FRONT.cx, FRONT.cy])
    x_edge = cm.undistort_points(FRONT, [FRONT.width_px - 0.5, FRONT.cy])[0]
    assert math.degrees(2 * math.atan(x_edge)) == pytest.approx(94.7, abs=0.1)


def test_undistort_to_pixels_and_rays():
    pixel = np.array([[40.0, 30.0]])
    xy = cm.undistort_points(FRONT, pixel)
    ideal_px = cm.undistort_points(FRONT, pixel, to_pixels=True)
    np.testing.assert_allclose(ideal_px, xy * FRONT.fx + (FRONT.cx, FRONT.cy), atol=1e-9)
    ray = cm.pixel_rays(FRONT, pixel[0])
    assert ray.shape == (3,)
    assert np.linalg.norm(ray) == pytest.approx(1.0)
    np.testing.assert_allclose(ray[:2] / ray[2], xy[0], atol=1e-12)
    # a ray projects back onto its pixel
    np.testing.assert_allclose(cm.project_points(FRONT, ray * 5.0), pixel[0], atol=1e-6)


def test_points_behind_or_past_the_lens_fold_are_not_projected():
    assert np.isnan(cm.project_points(FRONT, [0.1, 0.1, -1.0])).all()
    folding = CameraIntrinsics(640, 480, 320.0, 320.0, 319.5, 239.5, (-0.3, 0.0, 0.0, 0.0, 0.0))
    # r·(1 − 0.3 r²) peaks at r = 1.05: a point at r = 2 would otherwise land in the image
    assert np.isnan(cm.project_points(folding, [2.0, 0.0, 1.0])).all()
    assert np.isfinite(cm.project_points(folding, [0.9, 0.0, 1.0])).all()


def test_distortion_problem_catches_a_lens_that_folds_over_within_the_image():
    assert cm.distortion_problem(FRONT) is None
    assert cm.distortion_problem(IDEAL) is None
    folding = cm.pinhole(640, 480, 90.0, (-0.35, 0.0, 0.0, 0.0, 0.0))
    assert "folds over" in cm.distortion_problem(folding)


@pytest.mark.parametrize("fit", [False, True], ids=["same-focal-length", "fit"])
def test_render_intrinsics_cover_the_distorted_image(fit):
    source = cm.render_intrinsics(FRONT, margin_px=2, fit=fit)
    assert not cm.is_distorted(source)
    assert (source.cx, source.cy) == ((source.width_px - 1) / 2, (source.height_px - 1) / 2)
    if fit:  # the frame's size, plus margins, at a lower focal length
        assert (source.width_px, source.height_px) == (644, 484)
        assert source.fx == pytest.approx(0.885 * FRONT.fx, abs=0.005 * FRONT.fx)
    else:  # the frame's focal length; even growth keeps the principal point's sub-pixel place
        assert source.fx == FRONT.fx
        assert (source.width_px, source.height_px) == (726, 546)
    # every pixel centre of the distorted frame samples the render at least 2 px from its edges
    u, v = np.meshgrid(np.arange(FRONT.width_px), np.arange(FRONT.height_px))
    xy = cm.undistort_points(FRONT, np.column_stack([u.ravel(), v.ravel()]))
    in_source = xy * (source.fx, source.fy) + (source.cx, source.cy)
    assert in_source.min() >= 2.0
    assert in_source[:, 0].max() <= source.width_px - 1 - 2.0
    assert in_source[:, 1].max() <= source.height_px - 1 - 2.0
    assert in_source[:, 0].max() > source.width_px - 1 - 4.0  # and not much more
    assert cm.render_intrinsics(IDEAL, margin_px=0) == IDEAL
    assert cm.render_intrinsics(IDEAL, margin_px=0, fit=True) == IDEAL


def test_distortion_maps_distort_a_synthetic_image_as_projection_predicts():
    """Remapping an ideal image of dots through the maps puts each dot where project_points
    says the distorted camera sees it."""
    source = cm.render_intrinsics(FRONT)
    map_x, map_y = cm.distortion_maps(FRONT, source)
    assert map_x.shape == (FRONT.height_px, FRONT.width_px)
    assert map_x.dtype == np.float32
    assert not map_x.flags.writeable
    assert cm.distortion_maps(FRONT, source)[0] is map_x  # cached
    rays = np.array([[x, y, 1.0] for x in (-0.9, -0.4, 0.0, 0.5, 0.95)
                     for y in (-0.68, -0.3, 0.2, 0.7)])
    ideal = np.zeros((source.height_px, source.width_px), np.uint8)
    for x, y, _ in rays:
        u, v = x * source.fx + source.cx, y * source.fy + source.cy
        cv2.circle(ideal, (round(u * 16), round(v * 16)), 4 * 16, 255, -1, cv2.LINE_AA, 4)
    image = cv2.remap(ideal, map_x, map_y, cv2.INTER_LINEAR)
    n, _, stats, _ = cv2.connectedComponentsWithStats((image > 0).astype(np.uint8))
    found = []
    for i in range(1, n):
        x0, y0, w, h = stats[i, :4]
        patch = image[y0:y0 + h, x0:x0 + w].astype(float)
        vv, uu = np.mgrid[y0:y0 + h, x0:x0 + w]
        found.append(((patch * uu).sum() / patch.sum(), (patch * vv).sum() / patch.sum()))
    expected = cm.project_points(FRONT, rays)
    assert len(found) == len(rays)
    for e in expected:
        nearest = min(found, key=lambda c: np.hypot(*(np.array(c) - e)))
        # a disc's centroid moves slightly under the distortion's curvature
        assert np.hypot(*(np.array(nearest) - e)) < 0.2, (e, nearest)


def test_rejects_points_of_the_wrong_shape():
    with pytest.raises(ValueError, match="shape"):
        cm.project_points(FRONT, [1.0, 2.0])
    with pytest.raises(ValueError, match="ideal pinhole"):
        cm.distortion_maps(FRONT, FRONT)


def test_camera_configuration_rejects_an_impossible_lens_or_exposure(sim_config):
    front = sim_config.cameras["front"].model_dump()
    CameraConfig = type(sim_config.cameras["front"])
    assert CameraConfig.model_validate(front).realistic
    with pytest.raises(ValidationError, match="folds over"):
        CameraConfig.model_validate({**front, "distortion": [-0.4, 0.0, 0.0, 0.0, 0.0]})
    # an ideal camera ignores its distortion
    CameraConfig.model_validate({**front, "realistic": False,
                                 "distortion": [-0.4, 0.0, 0.0, 0.0, 0.0]})
    with pytest.raises(ValidationError, match=r"exposure_s .* shorter than the frame period"):
        CameraConfig.model_validate({**front, "exposure_s": 0.04})
    with pytest.raises(ValidationError, match="rolling_shutter_s"):
        CameraConfig.model_validate({**front, "rolling_shutter_s": 0.034})
    with pytest.raises(ValidationError, match="noise_std_dn"):
        CameraConfig.model_validate({**front, "noise_std_dn": -1})
