"""The realistic simulated camera on real renders: lens distortion as its intrinsics say (and
undone by drivers/camera_model.py), read noise of the configured size, motion blur and rolling
shutter from the vehicle's motion, deterministic for a seed; with the effects off, MuJoCo's
ideal pinhole image as before."""

import contextlib
import hashlib
import math

import cv2
import numpy as np
import pytest

from drivers import camera_model
from drivers.base import Setpoint
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.camera_effects import VehicleMotion, blur_kernel, image_motion_px_s
from drivers.sim.scenario import Geom, MocapBody, Static
from drivers.sim.simulator import Simulator

from ..conftest import sim_with
from .simtools import Offboard, run, simulator, take_off

RED = (1.0, 0.0, 0.0, 1.0)
HOVER = (0.0, 0.0, -2.0)
LEVEL = quat_from_euler(0.0, 0.0, 0.0)  # facing north


def _ideal(sim_config):
    return sim_with(sim_config, **{"cameras.front.realistic": False,
                                   "cameras.down.realistic": False})


def _effects_only(sim_config, **front):
    """Realistic front camera with only the given effects (others off)."""
    keys = {"distortion": [0.0] * 5, "noise_std_dn": 0.0, "exposure_s": 0.0,
            "rolling_shutter_s": 0.0, **front}
    return sim_with(sim_config, **{f"cameras.front.{k}": v for k, v in keys.items()})


def _capture(cfg, scenario=(), position=HOVER, attitude=LEVEL, rates_frd=(0.0, 0.0, 0.0),
             velocity_ned=(0.0, 0.0, 0.0), camera="front", count=1, seed=None):
    """Frames of a vehicle posed (and moving: body rates, velocity) as given."""
    sim = Simulator(cfg, scenario=list(scenario), seed=seed)
    try:
        sim.set_vehicle_pose(position, attitude)
        sim.body.set_motion(velocity_ned, rates_frd)
        frames = [sim.capture(camera) for _ in range(count)]
    finally:
        sim.close()
    return frames if count > 1 else frames[0]


def _pixel_of(info, point_ned, position=HOVER, attitude=LEVEL):
    """Where the camera sees points (rows, local NED) from the pose (model projection)."""
    p_body = (np.asarray(point_ned, float) - np.asarray(position)) @ quat_to_matrix(attitude)
    p_cam = (p_body - info.position_body_m) @ info.rotation_body_cam
    return camera_model.project_points(info.intrinsics, p_cam)


# ---------------------------------------------------------------------------------------------
# Lens distortion
# ---------------------------------------------------------------------------------------------

#: A thin red bar across the view, 2.5 m ahead and 1.2 m below the camera: a straight line in
#: the world, low in the image where the barrel bends it most.
BAR_NED = (2.5, 0.0, -0.8)
BAR = MocapBody("bar", [Geom("box", (0.005, 6.0, 0.015), RED)], Static(BAR_NED))


def _bar_centreline(image):
    """Per column, the intensity-weighted row of the red bar (columns where it is found)."""
    _b, g, r = cv2.split(image.astype(np.float32))
    redness = np.clip(r - g, 0, None)
    redness[redness < 40] = 0
    rows = np.arange(image.shape[0], dtype=np.float32)[:, None]
    weight = redness.sum(axis=0)
    cols = np.flatnonzero(weight > 200)
    return cols.astype(float), (redness * rows).sum(axis=0)[cols] / weight[cols]


def _line_residual(u, v):
    """Largest distance of the points from their least-squares straight line (px)."""
    a, c = np.polyfit(u, v, 1)
    return float(np.max(np.abs(v - (a * u + c))) / math.hypot(a, 1.0))


def test_straight_line_bends_as_the_distortion_predicts_and_straightens_when_undistorted(
        sim_config):
    frame = _capture(sim_config, [BAR])
    intr = frame.camera.intrinsics
    assert intr.distortion == tuple(sim_config.cameras["front"].distortion)
    u, v = _bar_centreline(frame.image)
    assert u.min() < 5  # across the whole image
    assert u.max() > intr.width_px - 6

    # where the model puts the bar's centreline, column by column
    east = np.linspace(-6.0, 6.0, 4001)
    line = np.column_stack([np.full_like(east, BAR_NED[0]), east, np.full_like(east, BAR_NED[2])])
    predicted = _pixel_of(frame.camera, line)
    predicted = predicted[np.isfinite(predicted[:, 0])]
    order = np.argsort(predicted[:, 0])
    expected_v = np.interp(u, predicted[order, 0], predicted[order, 1])
    inner = (u > 3) & (u < intr.width_px - 4)
    assert np.max(np.abs(v - expected_v)[inner]) < 0.5

    bend = _line_residual(u, v)  # the image of a straight line is curved...
    assert bend > 5.0
    assert _line_residual(*predicted[(predicted[:, 0] > 0) & (predicted[:, 0] < 639)].T) \
        == pytest.approx(bend, abs=0.5)
    straight = camera_model.undistort_points(intr, np.column_stack([u, v]), to_pixels=True)
    assert _line_residual(straight[:, 0], straight[:, 1]) < 0.4  # ...and straight undistorted
    assert np.ptp(straight[:, 1]) < 1.0  # and level, as the pinhole sees it


def test_distorted_frame_has_no_empty_border(sim_config):
    """MuJoCo renders a larger ideal image, so that every pixel of the distorted frame samples
    inside it (no border filled in), for both cameras."""
    sim = Simulator(sim_config)
    try:
        for name in ("front", "down"):
            frame = sim.capture(name)
            target = sim.rig._targets[sim.cameras[name].cam_id]
            source = target.source
            assert source.fx == frame.camera.intrinsics.fx  # the frame's resolution
            assert (source.width_px, source.height_px) > (640, 480)
            map_x, map_y = target.maps[:2]
            assert map_x.min() >= 1
            assert map_x.max() <= source.width_px - 2
            assert map_y.min() >= 1
            assert map_y.max() <= source.height_px - 2
            assert frame.image.shape == (480, 640, 3)
    finally:
        sim.close()


# ---------------------------------------------------------------------------------------------
# Sensor noise
# ---------------------------------------------------------------------------------------------

def _sky_patch(frame):
    return frame.image[20:120, 220:420].reshape(-1, 3).astype(float)


def test_noise_has_the_configured_std_on_a_flat_region(sim_config):
    up = quat_from_euler(0.0, math.radians(40), 0.0)  # nose up: the top of the image is sky
    std = sim_config.cameras["front"].noise_std_dn
    assert std > 0
    a, b = _capture(sim_config, attitude=up, count=2)
    for frame in (a, b):
        patch = _sky_patch(frame)
        # rounding to whole DN adds 1/12 DN² of variance
        np.testing.assert_allclose(patch.std(axis=0), math.sqrt(std**2 + 1 / 12), rtol=0.05)
    assert np.abs(_sky_patch(a).mean(axis=0) - _sky_patch(b).mean(axis=0)).max() < 0.3
    diff = _sky_patch(a) - _sky_patch(b)
    assert diff.std() == pytest.approx(math.sqrt(2 * (std**2 + 1 / 12)), rel=0.05)  # fresh noise

    quiet = _capture(_effects_only(sim_config, noise_std_dn=0.0), attitude=up)
    assert _sky_patch(quiet).std(axis=0).max() == 0.0
    noisy = _capture(_effects_only(sim_config, noise_std_dn=5.0), attitude=up)
    np.testing.assert_allclose(_sky_patch(noisy).std(axis=0), math.sqrt(25 + 1 / 12), rtol=0.05)


# ---------------------------------------------------------------------------------------------
# Motion blur and rolling shutter
# ---------------------------------------------------------------------------------------------

#: A red pole 3 m ahead, in the middle of the front camera's view.
POLE = MocapBody("pole", [Geom("box", (0.02, 0.15, 1.2), RED)], Static((3.0, 0.0, -1.2)))


def _edge_profile(image, row):
    """The pole's left edge along an image row: the redness profile."""
    _b, g, r = cv2.split(image[row].astype(np.float32)[None])
    return (r - g)[0]


def _levels(profile):
    """Background and pole levels of a row's redness profile."""
    return float(np.median(profile[:250])), float(np.percentile(profile, 99))


def _edge_width_px(profile):
    """Rise width of the pole's left edge: the step divided by the steepest gradient."""
    lo, hi = _levels(profile)
    left = profile[: int(np.argmax(profile > 0.5 * (lo + hi))) + 8]
    return (hi - lo) / float(np.max(np.diff(left)))


def _edge_position_px(profile):
    """Where the pole's left edge crosses half its height (sub-pixel)."""
    lo, hi = _levels(profile)
    half = 0.5 * (lo + hi)
    i = int(np.argmax(profile > half))
    return i - 1 + (half - profile[i - 1]) / (profile[i] - profile[i - 1])


def test_motion_blur_when_the_vehicle_yaws_fast_and_not_when_it_hovers(sim_config):
    cfg = _effects_only(sim_config, exposure_s=0.004)
    sharp = _capture(_effects_only(sim_config), [POLE])
    hover = _capture(cfg, [POLE])
    assert np.array_equal(hover.image, sharp.image)  # at rest: nothing to blur

    yaw_rate = 2.5  # rad/s to the right, about the blur a fast turn gives: 3.2 px
    yawing = _capture(cfg, [POLE], rates_frd=(0.0, 0.0, yaw_rate))
    length = yawing.camera.intrinsics.fx * yaw_rate * 0.004
    assert length == pytest.approx(3.2, abs=0.05)
    row = 240
    widths = {name: _edge_width_px(_edge_profile(f.image, row))
              for name, f in (("sharp", sharp), ("yawing", yawing))}
    assert widths["sharp"] < 1.6
    assert widths["yawing"] == pytest.approx(length, abs=0.8)
    # blurred along the motion only: the pole's top edge (horizontal) stays sharp
    col = _column_through_pole(sharp.image, row)
    top_sharp = np.abs(np.diff(_column_profile(sharp.image, col))).max()
    top_yawing = np.abs(np.diff(_column_profile(yawing.image, col))).max()
    assert top_yawing == pytest.approx(top_sharp, rel=0.15)
    # and centred on the capture time: the edge is where it was
    assert _edge_position_px(_edge_profile(yawing.image, row)) == pytest.approx(
        _edge_position_px(_edge_profile(sharp.image, row)), abs=0.3)

    slow = _capture(cfg, [POLE], rates_frd=(0.0, 0.0, 0.3))  # 0.38 px: not blurred
    assert np.array_equal(slow.image, sharp.image)


def _column_through_pole(image, row):
    profile = _edge_profile(image, row)
    inside = np.flatnonzero(profile > 0.5 * profile.max())
    return int(inside[len(inside) // 2])


def _column_profile(image, col):
    _b, g, r = cv2.split(image[:, col].astype(np.float32)[:, None])
    return (r - g)[:, 0]


def test_rolling_shutter_slants_a_vertical_edge_while_yawing(sim_config):
    rs = 0.02
    yaw_rate = 2.0
    global_shutter = _capture(_effects_only(sim_config), [POLE], rates_frd=(0, 0, yaw_rate))
    rolling = _capture(_effects_only(sim_config, rolling_shutter_s=rs), [POLE],
                       rates_frd=(0, 0, yaw_rate))
    f = rolling.camera.intrinsics.fx
    top, bottom = 200, 400  # the pole spans rows 165-420
    shift = {name: _edge_position_px(_edge_profile(fr.image, bottom))
             - _edge_position_px(_edge_profile(fr.image, top))
             for name, fr in (("global", global_shutter), ("rolling", rolling))}
    assert abs(shift["global"]) < 1.5  # perspective: the camera looks 5° down
    # later rows see the scene further left (the vehicle turns right)
    expected = -f * yaw_rate * rs * (bottom - top) / (rolling.camera.intrinsics.height_px - 1)
    assert expected == pytest.approx(-5.3, abs=0.1)
    assert shift["rolling"] - shift["global"] == pytest.approx(expected, abs=0.3)
    # the middle row is exposed at the frame's time stamp: it does not move
    mid = rolling.camera.intrinsics.height_px // 2  # 0.01 ms from it: shifted by 0.01 px
    assert _edge_position_px(_edge_profile(rolling.image, mid)) == pytest.approx(
        _edge_position_px(_edge_profile(global_shutter.image, mid)), abs=0.3)


def test_image_motion_from_rotation_and_translation(sim_config):
    """The image-centre motion that blur and rolling shutter use: yaw moves the front camera's
    image sideways at f·ω; flying forward moves the down camera's image down at f·v / height."""
    sim = Simulator(sim_config)
    try:
        front, down = sim.cameras["front"].info, sim.cameras["down"].info
    finally:
        sim.close()

    def motion(rates=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), height=2.0):
        return VehicleMotion(np.array([0.0, 0.0, -height]), np.array(velocity, float),
                             LEVEL, np.array(rates, float))

    du, dv = image_motion_px_s(front, motion(rates=(0.0, 0.0, 1.0)))
    assert du == pytest.approx(-front.intrinsics.fx, rel=0.01)
    assert abs(dv) < 0.1 * abs(du)
    du, dv = image_motion_px_s(front, motion(rates=(0.0, 1.0, 0.0)))  # nose up: image moves down
    assert dv == pytest.approx(front.intrinsics.fy, rel=0.01)
    du, dv = image_motion_px_s(down, motion(velocity=(2.0, 0.0, 0.0), height=2.04))
    assert dv == pytest.approx(down.intrinsics.fy * 2.0 / 2.0, rel=0.02)
    assert abs(du) < 1e-6
    du, dv = image_motion_px_s(front, motion(velocity=(0.0, 2.0, 0.0)))  # far away: ~nothing
    assert abs(du) < 0.1 * front.intrinsics.fx
    assert blur_kernel(0.3, 0.35) is None  # under half a pixel
    kernel = blur_kernel(3.0, 0.0)
    assert kernel.sum() == pytest.approx(1.0)
    assert kernel.shape == (5, 5)  # 3 px and the bilinear ends
    assert np.count_nonzero(kernel.sum(axis=1)) == 1  # horizontal line


# ---------------------------------------------------------------------------------------------
# Determinism, and the effects off
# ---------------------------------------------------------------------------------------------

def _turning_flight_frames(cfg, seed):
    """Front-camera frame hashes of a lockstep flight turning at 1.5 rad/s (blur on)."""
    async def main():
        async with simulator(cfg, seed=seed) as drv:
            await take_off(drv, 1.5)
            offboard = Offboard(drv)
            await offboard.start_holding_here()
            offboard.setpoint = Setpoint.velocity_body(0.0, 0.0, 0.0, yaw_rate_rad_s=1.5)
            await drv.clock.sleep(1.0)
            frames = []
            async with contextlib.aclosing(drv.frames("front")) as stream:
                async for frame in stream:
                    frames.append((frame.time_s, hashlib.sha1(frame.image.tobytes()).hexdigest()))
                    if len(frames) == 10:
                        break
            state = drv.latest_state
            await offboard.aclose()
            return frames, float(state.angular_velocity_frd_rad_s[2])

    return run(main())


def test_same_seed_same_frames_while_turning(sim_config):
    frames_a, rate = _turning_flight_frames(sim_config, 3)
    assert rate > 1.0  # turning fast enough to blur
    frames_b, _ = _turning_flight_frames(sim_config, 3)
    assert frames_a == frames_b
    frames_c, _ = _turning_flight_frames(sim_config, 4)
    assert [t for t, _ in frames_c] == [t for t, _ in frames_a]
    assert all(a != c for (_, a), (_, c) in zip(frames_a, frames_c, strict=True))  # noise


@pytest.mark.parametrize("camera", ["front", "down"])
def test_effects_off_is_the_ideal_pinhole_render(sim_config, camera):
    """``realistic: false`` renders as before (MuJoCo's image, flipped upright), reports no
    distortion, and equals a realistic camera whose every effect is zero."""
    scenario = [BAR, POLE]
    ideal = _capture(_ideal(sim_config), scenario, rates_frd=(0.3, 0.2, 2.0), camera=camera)
    assert not camera_model.is_distorted(ideal.camera.intrinsics)
    zero = {f"cameras.{camera}.{k}": v for k, v in
            {"distortion": [0.0] * 5, "noise_std_dn": 0.0, "exposure_s": 0.0,
             "rolling_shutter_s": 0.0}.items()}
    zeroed = _capture(sim_with(sim_config, **zero), scenario, rates_frd=(0.3, 0.2, 2.0),
                      camera=camera)
    assert np.array_equal(ideal.image, zeroed.image)
    realistic = _capture(sim_config, scenario, camera=camera)
    assert not np.array_equal(ideal.image, realistic.image)
