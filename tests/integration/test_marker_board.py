"""The simulated marker board: rendered where its ground truth says, printed the right way round
on its face only, turning as configured, moving along the ball's paths."""

import contextlib
import math

import mujoco
import numpy as np
import pytest

from autopilot.perception.marker import MarkerDetector, MarkerDetectorSettings
from drivers.geometry import quat_from_euler, quat_to_matrix, yaw_from_quat
from drivers.sim.scenario import MarkerBoard, Static, marker_in_camera, marker_objects
from drivers.sim.simulator import Simulator

from .simtools import armable, run, simulator

VEHICLE = (0.0, 0.0, -1.5)


def _capture(sim_config, objects, vehicle=VEHICLE, euler=(0.0, 0.0, 0.0)):
    """A front-camera frame and ground truth with the vehicle posed (boards turned to it)."""
    sim = Simulator(sim_config, scenario=objects)
    try:
        sim.set_vehicle_pose(vehicle, quat_from_euler(*euler))
        for obj in objects:
            obj.update(0.0, sim.data)
        mujoco.mj_forward(sim.model, sim.data)
        return sim.capture("front"), sim.ground_truth()
    finally:
        sim.close()


def test_board_faces_the_camera_printed_the_right_way_round(sim_config):
    board = MarkerBoard("marker", 36, Static((1.1, 0.0, -1.5)), facing="drone")
    frame, truth = _capture(sim_config, [board])
    t = truth.bodies["marker"]
    assert t.position_ned_m == pytest.approx([1.1, 0.0, -1.5])
    assert yaw_from_quat(t.attitude_q) == pytest.approx(math.pi)  # looking back at the vehicle
    det = MarkerDetector().detect(frame.image, frame.camera, frame.time_s)
    assert det is not None
    assert det.marker_id == 36
    position, rotation = marker_in_camera(t, truth.vehicle, frame.camera)
    assert np.linalg.norm(det.position_cam_m - position) < 0.01
    # upright: the marker's x axis runs right in the image, its y axis up
    assert det.rotation_cam_marker[:, 0] @ (1, 0, 0) > 0.99
    assert det.rotation_cam_marker[:, 1] @ (0, -1, 0) > 0.97  # the camera looks 5° down
    assert np.allclose(rotation[:, :2], det.rotation_cam_marker[:, :2], atol=0.07)


def test_back_of_the_board_is_blank(sim_config):
    board = MarkerBoard("marker", 36, Static((1.2, 0.0, -1.5)), facing="fixed", yaw_deg=0.0)
    frame, truth = _capture(sim_config, [board])
    position, _ = marker_in_camera(truth.bodies["marker"], truth.vehicle, frame.camera)
    u, v = np.round(frame.camera.intrinsics.project(position)).astype(int)
    middle = frame.image[v - 30:v + 30, u - 30:u + 30]  # the board spans ±40 px
    assert middle.min() > 120  # plain grey: no black square
    detector = MarkerDetector(MarkerDetectorSettings(marker_id=96))
    assert detector.find(frame.image) == []


def test_decoys_render_with_their_own_ids(sim_config):
    objects = marker_objects(start_distance_m=2.0, height_m=1.5, decoys=3, seed=11,
                             decoy_ids=(7, 12, 300))
    # put the decoys in view, beside the followed board
    for decoy, east in zip(objects[1:], (-0.8, 0.8, 0.4), strict=True):
        decoy.trajectory = Static((2.3, east, -1.5 + 0.45 * (east > 0.5)))
    frame, truth = _capture(sim_config, objects)
    found = MarkerDetector().find(frame.image)
    assert sorted(f.marker_id for f in found) == [7, 12, 36, 300]
    for obj in objects:
        t = truth.bodies[obj.name]
        to_vehicle = math.atan2(-t.position_ned_m[1], -t.position_ned_m[0])
        assert math.remainder(yaw_from_quat(t.attitude_q) - to_vehicle, math.tau) == \
            pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("facing", ["travel", "drone"])
def test_board_moves_along_its_path_and_turns(sim_config, facing):
    objects = marker_objects(path="circle", speed_mps=1.0, path_size_m=2.0, height_m=1.5,
                             start_distance_m=3.0, facing=facing)
    board = objects[0]

    async def main():
        async with simulator(sim_config, scenario=objects) as drv:
            await armable(drv)
            await drv.arm()  # scripted motion starts when the vehicle arms
            samples = []
            async with contextlib.aclosing(drv.ground_truth(buffer=1024)) as stream:
                async for sample in stream:
                    start = drv.simulator.scenario_start_s
                    if start is not None and sample.time_s > start + 0.1:
                        samples.append((sample, sample.time_s - start))
                    if len(samples) >= 100:  # 2 s
                        break
            return samples

    samples = run(main())
    for truth, t in samples:
        b = truth.bodies["marker"]
        pos, vel, _ = board.trajectory(t)
        assert b.position_ned_m == pytest.approx(pos)
        assert b.velocity_ned_m_s == pytest.approx(vel)
        assert np.linalg.norm(vel) == pytest.approx(1.0)
        normal = quat_to_matrix(b.attitude_q)[:, 0]  # out of the face
        assert abs(normal[2]) < 1e-9  # upright
        if facing == "travel":
            assert normal[:2] @ vel[:2] == pytest.approx(1.0, abs=1e-6)
        else:
            to_vehicle = truth.vehicle.position_ned_m[:2] - b.position_ned_m[:2]
            assert normal[:2] @ to_vehicle / np.linalg.norm(to_vehicle) == \
                pytest.approx(1.0, abs=1e-4)
    travelled = np.linalg.norm(samples[-1][0].bodies["marker"].position_ned_m
                               - samples[0][0].bodies["marker"].position_ned_m)
    assert travelled > 1.0
