"""Onboard cameras: geometry (intrinsics and extrinsics, to the pixel), timing, rendering only
while consumed."""

import contextlib
import math

import cv2
import numpy as np
import pytest

from drivers import camera_model
from drivers.base import CameraUnavailable
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim import camera
from drivers.sim.driver import SimDriver
from drivers.sim.scenario import Geom, MocapBody, Static
from drivers.sim.simulator import Simulator

from ..conftest import sim_with
from .simtools import run, simulator

RED = (1.0, 0.0, 0.0, 1.0)


def _markers(points):
    return [MocapBody(f"marker{i}", [Geom("sphere", (0.05,), RED)], Static(tuple(p)))
            for i, p in enumerate(points)]


def _blob_centres(image):
    b, g, r = cv2.split(image.astype(np.int16))
    mask = ((r > 100) & (g < 60) & (b < 60)).astype(np.uint8)
    n, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
    return [centroids[i] for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= 12]


def _expected_pixel(info, truth, point):
    """Where the frame's camera model (pinhole and lens distortion) puts a world point."""
    r_world_body = quat_to_matrix(truth.vehicle.attitude_q)
    p_body = r_world_body.T @ (np.asarray(point) - truth.vehicle.position_ned_m)
    p_cam = info.rotation_body_cam.T @ (p_body - info.position_body_m)
    assert p_cam[2] > 0, "marker behind the camera"
    return camera_model.project_points(info.intrinsics, p_cam)


@pytest.mark.parametrize("realistic", [True, False], ids=["realistic", "ideal"])
@pytest.mark.parametrize(
    ("camera", "vehicle", "euler_deg", "points"),
    [
        ("front", (0.0, 0.0, -2.0), (0, 0, 0),
         [(3.0, 0.0, -1.9), (4.0, 1.5, -2.5), (2.5, -1.0, -1.2), (5.0, -2.5, -3.5)]),
        ("front", (1.0, -2.0, -3.0), (8, -12, 35),
         [(4.0, 0.5, -2.9), (3.5, 2.0, -2.2), (5.0, 0.0, -4.0), (2.5, -0.5, -3.3)]),
        ("down", (0.0, 0.0, -3.0), (0, 0, 0),
         [(0.0, 0.0, -0.5), (0.8, 0.6, -0.3), (-0.7, -0.9, -0.6)]),
        ("down", (2.0, 1.0, -3.0), (-10, 7, -60),
         [(2.0, 1.0, -0.5), (2.6, 0.4, -0.3), (1.5, 1.8, -0.6)]),
    ],
)
def test_marker_appears_at_projected_pixel(sim_config, camera, vehicle, euler_deg, points,
                                           realistic):
    """To the pixel, with the lens distortion the frame reports (realistic camera, default)
    and without (an ideal pinhole: ``intrinsics.project``)."""
    if not realistic:
        sim_config = sim_with(sim_config, **{f"cameras.{camera}.realistic": False})
    sim = Simulator(sim_config, scenario=_markers(points))
    try:
        sim.set_vehicle_pose(vehicle, quat_from_euler(*np.radians(euler_deg)))
        frame = sim.capture(camera)
        truth = sim.ground_truth()
    finally:
        sim.close()
    assert camera_model.is_distorted(frame.camera.intrinsics) == realistic
    found = _blob_centres(frame.image)
    assert len(found) == len(points)
    for point in points:
        expected = _expected_pixel(frame.camera, truth, point)
        nearest = min(found, key=lambda c: np.linalg.norm(c - expected))
        assert np.linalg.norm(nearest - expected) < 1.0, (point, expected, nearest)


def test_two_cameras_rendering_in_turn_each_draw_their_own_view(sim_config):
    """Each camera has its own framebuffer on the one OpenGL context: drawing into the one
    bound last would hand each camera the other's picture."""
    ahead, below = (3.0, 0.0, -1.9), (0.3, 0.2, -0.5)
    sim = Simulator(sim_config, scenario=_markers([ahead, below]))
    try:
        sim.set_vehicle_pose((0.0, 0.0, -2.5), quat_from_euler(0.0, 0.0, 0.0))
        frames = [sim.capture(name) for name in ("front", "down", "front", "down")]
        truth = sim.ground_truth()
    finally:
        sim.close()
    for frame in frames:
        point = ahead if frame.camera.name == "front" else below
        (found,) = _blob_centres(frame.image)  # the other marker is out of this camera's view
        expected = _expected_pixel(frame.camera, truth, point)
        assert np.linalg.norm(found - expected) < 1.0, (frame.camera.name, found, expected)


def test_intrinsics_match_configuration(sim_config):
    cam = sim_config.cameras["front"]
    sim = Simulator(sim_config)
    try:
        info = sim.cameras["front"].info
        frame = sim.capture("front")
    finally:
        sim.close()
    assert frame.image.shape == (cam.height_px, cam.width_px, 3)
    assert frame.image.dtype == np.uint8
    assert not frame.image.flags.writeable
    assert math.degrees(info.intrinsics.hfov_rad) == pytest.approx(cam.hfov_deg)
    assert info.intrinsics.cx == pytest.approx((cam.width_px - 1) / 2)
    assert cam.realistic
    assert info.intrinsics.distortion == tuple(cam.distortion)  # the autopilot undistorts


def test_frames_are_stamped_with_capture_time(sim_config):
    cam = sim_config.cameras["front"]
    step = 1.0 / sim_config.physics_rate_hz

    async def main():
        async with simulator(sim_config) as drv:
            got = []
            async with contextlib.aclosing(drv.frames("front")) as frames:
                async for frame in frames:
                    got.append((drv.clock.now(), frame))
                    if len(got) == 31:
                        break
            return got

    got = run(main())
    stamps = np.array([f.time_s for _, f in got])
    assert [f.seq for _, f in got] == list(range(got[0][1].seq, got[0][1].seq + 31))
    assert np.all(np.abs(np.diff(stamps) - 1.0 / cam.rate_hz) <= step + 1e-9)
    # each frame arrives its camera latency after capture
    for arrived, frame in got:
        assert arrived - frame.time_s == pytest.approx(cam.latency_s, abs=step + 1e-9)


def test_render_gate_holds_rendering_until_shortly_before_the_frame_is_due(sim_config):
    """Real time: each scheduled frame's rendering waits for the gate, which is asked for the
    instant ``realtime_render_lead_s`` before the frame is due; the frame is unchanged."""
    cam = sim_config.cameras["front"]
    sim = Simulator(sim_config)
    asked = []
    sim.rig.render_gate, sim.rig.background = asked.append, True
    sim.set_camera_active("front", True)
    frames = []
    while len(frames) < 5:
        frames += [out.payload for out in sim.advance_to(sim.time_s + 0.01) if out.kind == "frame"]
    sim.close()
    due = [f.time_s + cam.latency_s for f in frames]
    assert asked[:5] == pytest.approx([t - sim_config.realtime_render_lead_s for t in due])


def test_cameras_render_only_while_watched(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            cams = drv.simulator.cameras
            async with contextlib.aclosing(drv.frames("front")) as frames:
                async for frame in frames:
                    if frame.time_s >= 1.0:
                        break
            rendered_front = cams["front"].rendered
            await drv.clock.sleep(1.0)
            assert cams["front"].rendered <= rendered_front + 1  # stopped after unsubscribing
            assert cams["down"].rendered == 0
            assert 29 <= rendered_front <= 32

    run(main())


def test_unknown_camera_is_a_clear_error(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            with pytest.raises(ValueError, match="no camera 'rear'"):
                drv.frames("rear")

    run(main())


def test_render_contexts_are_made_at_connect_and_missing_opengl_fails_it(sim_config,
                                                                       monkeypatch):
    """The cameras are ready before flight; without OpenGL, connecting fails with a clear
    error instead of the first frame failing in the air."""
    async def connects():
        async with simulator(sim_config) as drv:
            rig = drv.simulator.rig
            assert {t.context is not None for t in rig._targets.values()} == {True}
            assert len(rig._targets) == len(drv.cameras) == 2
            assert all(cam.rendered == 0 for cam in drv.simulator.cameras.values())

    run(connects())

    def no_gl(model):
        raise camera.RenderingUnavailable("cannot render headless with MUJOCO_GL='egl': "
                                          "no EGL display")

    monkeypatch.setattr(camera, "_make_gl_context", no_gl)
    with pytest.raises(CameraUnavailable, match="simulator cameras: cannot render headless"):
        run(SimDriver(sim_config).connect())
