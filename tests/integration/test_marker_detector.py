"""The marker detector on rendered frames (the front camera as configured: lens distortion,
noise), scored against the board's ground truth: from a posed vehicle, and from a hovering
vehicle in lockstep while the board moves."""

import asyncio
import contextlib
import math

import mujoco
import numpy as np
import pytest

from autopilot.perception.marker import (
    MarkerDetector,
    MarkerDetectorSettings,
    MarkerHint,
    rotation_angle,
)
from drivers.base import Setpoint
from drivers.geometry import quat_from_euler
from drivers.sim.scenario import (
    BodyTruth,
    MarkerBoard,
    Static,
    marker_in_camera,
    marker_objects,
)
from drivers.sim.simulator import Simulator

from .simtools import Offboard, run, simulator, take_off

HOVER = (0.0, 0.0, -1.5)


@pytest.fixture(scope="module")
def detector():
    return MarkerDetector(MarkerDetectorSettings(marker_id=36, size_m=0.16))


def _capture(sim_config, objects, vehicle=HOVER, euler=(0.0, 0.0, 0.0)):
    sim = Simulator(sim_config, scenario=objects)
    try:
        sim.set_vehicle_pose(vehicle, quat_from_euler(*euler))
        for obj in objects:
            obj.update(0.0, sim.data)
        mujoco.mj_forward(sim.model, sim.data)
        return sim.capture("front"), sim.ground_truth()
    finally:
        sim.close()


def _errors(det, truth, frame, name="marker"):
    position, rotation = marker_in_camera(truth.bodies[name], truth.vehicle, frame.camera)
    return (float(np.linalg.norm(det.position_cam_m - position)),
            math.degrees(rotation_angle(det.rotation_cam_marker, rotation)), position)


@pytest.mark.parametrize(("board_ned", "facing", "yaw_deg", "euler"), [
    ((1.11, 0.0, -1.5), "drone", 0.0, (0.0, 0.0, 0.0)),  # the seed's 1 m, head-on
    ((1.1, 0.25, -1.65), "drone", 0.0, (0.03, -0.05, 0.1)),
    ((1.0, -0.2, -1.4), "fixed", 150.0, (0.0, 0.0, 0.0)),  # 40° oblique
    ((1.1, 0.3, -1.5), "fixed", 225.0, (-0.05, 0.04, 0.0)),  # 60° oblique
])
def test_pose_at_one_metre(sim_config, detector, board_ned, facing, yaw_deg, euler):
    board = MarkerBoard("marker", 36, Static(board_ned), facing=facing, yaw_deg=yaw_deg)
    frame, truth = _capture(sim_config, [board], euler=euler)
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    position_error, angle_error, position = _errors(det, truth, frame)
    assert np.linalg.norm(position) == pytest.approx(1.0, abs=0.15)
    assert position_error < 0.01
    # head-on, a 51 px marker's tilt is the least observable part of its pose
    assert angle_error < (5.0 if facing == "drone" else 3.0)


@pytest.mark.parametrize("distance_m", [2.0, 3.0])
def test_pose_farther_away(sim_config, detector, distance_m):
    board = MarkerBoard("marker", 36, Static((distance_m + 0.11, 0.2, -1.6)), facing="fixed",
                        yaw_deg=200.0)
    frame, truth = _capture(sim_config, [board])
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    position_error, angle_error, position = _errors(det, truth, frame)
    assert position_error < 0.015 * np.linalg.norm(position)
    assert angle_error < 10.0 or det.ambiguous


def test_decoys_are_ignored(sim_config, detector):
    objects = marker_objects(start_distance_m=1.4, height_m=1.5, decoys=3, seed=5,
                             decoy_ids=(37, 35, 96))  # 96: marker 36 mirrored
    for decoy, (north, east, down) in zip(objects[1:], [(1.6, -0.5, -1.5), (1.5, 0.45, -1.3),
                                                        (1.7, 0.1, -1.9)], strict=True):
        decoy.trajectory = Static((north, east, down))
    frame, truth = _capture(sim_config, objects)
    det = detector.detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    assert det.other_ids == (35, 37, 96)
    position_error, _, _ = _errors(det, truth, frame)
    assert position_error < 0.01
    alone = marker_objects(start_distance_m=-3.0, decoys=0)  # behind the camera
    frame, _ = _capture(sim_config, alone + objects[1:])
    assert detector.detect(frame.image, frame.camera, frame.time_s) is None


def _interpolate(samples, time_s):
    """The vehicle's truth at a frame's time (between 50 Hz samples; attitude: the nearer)."""
    times = [s.time_s for s in samples]
    i = int(np.searchsorted(times, time_s))
    a, b = samples[max(i - 1, 0)], samples[min(i, len(samples) - 1)]
    f = 0.0 if b.time_s == a.time_s else (time_s - a.time_s) / (b.time_s - a.time_s)
    vehicle = BodyTruth(a.vehicle.position_ned_m + f * (b.vehicle.position_ned_m
                                                        - a.vehicle.position_ned_m),
                        a.vehicle.velocity_ned_m_s,
                        (a if f < 0.5 else b).vehicle.attitude_q)
    return vehicle


def test_tracks_a_moving_board_from_a_hovering_vehicle(sim_config, detector):
    """Hovering at 1.5 m, the front camera on a board circling 1.3-2.3 m ahead at 0.3 m/s and
    turning to face the vehicle; each frame searched around the last detection."""
    objects = marker_objects(path="circle", speed_mps=0.3, path_size_m=1.0, height_m=1.5,
                             start_distance_m=1.3, facing="drone", decoys=2, seed=3)
    board = objects[0]

    async def main():
        async with simulator(sim_config, scenario=objects) as drv:
            await take_off(drv, 1.5)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            offboard.setpoint = Setpoint.position(here[0], here[1], -1.5, yaw_rad=0.0)
            await drv.clock.sleep(3.0)
            truths, results = [], []

            async def collect():
                async with contextlib.aclosing(drv.ground_truth(buffer=1024)) as stream:
                    async for sample in stream:
                        truths.append(sample)

            task = asyncio.ensure_future(collect())
            hint, first = None, True
            start = drv.simulator.scenario_start_s
            async with contextlib.aclosing(drv.frames("front")) as frames:
                async for frame in frames:
                    if first:  # the first frame after subscribing shows the scene as it
                        first = False  # was when the cameras were prepared (a known bug)
                        continue
                    det = detector.detect(frame.image, frame.camera, frame.time_s, hint)
                    hint = MarkerHint.from_detection(det) if det is not None else None
                    results.append((frame, det, frame.time_s - start))
                    if len(results) >= 120:  # 4 s
                        break
            await drv.clock.sleep(0.1)
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await offboard.aclose()
            return truths, results

    truths, results = run(main())
    position_errors, angle_errors, windowed = [], [], 0
    for frame, det, t in results:
        assert det is not None
        vehicle = _interpolate(truths, frame.time_s)
        pos, vel, yaw = board.trajectory(t)
        heading = board.heading(pos, yaw, vehicle.position_ned_m)
        truth_board = BodyTruth(pos, vel, quat_from_euler(0.0, 0.0, heading))
        position, rotation = marker_in_camera(truth_board, vehicle, frame.camera)
        position_errors.append(np.linalg.norm(det.position_cam_m - position))
        angle_errors.append(math.degrees(rotation_angle(det.rotation_cam_marker, rotation)))
        windowed += det.window is not None
        assert len(det.other_ids) <= 2
    assert windowed >= len(results) - 1  # all but the first searched around the last one
    assert np.median(position_errors) < 0.01
    assert np.percentile(position_errors, 95) < 0.025
    # facing the camera at 1.3-2.3 m (25-40 px) the tilt is the least observable part of the
    # pose (measured: median 4°, p95 7°; the position: 4 mm, 9 mm)
    assert np.median(angle_errors) < 6.0
    assert np.percentile(angle_errors, 95) < 12.0
