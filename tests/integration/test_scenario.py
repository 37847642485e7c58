"""Scenario objects: bodies with scripted motion added to the world, seen by the cameras and by
ground truth, without touching the airframe model."""

import contextlib
import math

import cv2
import numpy as np
import pytest

from drivers.sim.scenario import Circle, Geom, MocapBody

from .simtools import armable, run, simulator


def test_circling_body_moves_on_script_and_is_seen(sim_config):
    path = Circle(center_ned_m=(6.0, 0.0, -0.5), radius_m=1.0, speed_m_s=1.0)
    ball = MocapBody("ball", [Geom("sphere", (0.15,), (1.0, 0.0, 0.0, 1.0))], path)

    async def main():
        async with simulator(sim_config, scenario=[ball]) as drv:
            await armable(drv)
            still = await anext(drv.ground_truth())
            await drv.arm()  # scripted motion starts when the vehicle arms
            seen = []
            async with contextlib.aclosing(drv.frames("front")) as frames:
                async for frame in frames:
                    start = drv.simulator.scenario_start_s
                    if start is not None and frame.time_s >= start:
                        seen.append(frame)
                    if seen and frame.time_s >= start + math.pi / 2:  # a quarter lap
                        break
            truth = await anext(drv.ground_truth())
            return still, start, seen, truth

    still, start, frames, truth = run(main())
    assert start is not None
    assert np.allclose(still.bodies["ball"].position_ned_m, path(0.0)[0])  # waits for arming
    pos, vel, _ = path(truth.time_s - start)
    assert np.allclose(truth.bodies["ball"].position_ned_m, pos)
    assert np.allclose(truth.bodies["ball"].velocity_ned_m_s, vel)
    assert np.linalg.norm(vel) == pytest.approx(1.0)

    def ball_column(image):
        b, g, r = cv2.split(image.astype(np.int16))
        cols = np.flatnonzero(((r > 100) & (g < 60) & (b < 60)).any(axis=0))
        return cols.mean()

    # counter-clockwise seen from above, starting 7 m north on the camera's axis: a quarter lap
    # later it is 6 m north and 1 m west, i.e. f/6 ≈ 53 px left of the image centre
    cx = frames[0].camera.intrinsics.cx
    assert ball_column(frames[0].image) == pytest.approx(cx, abs=3)
    assert ball_column(frames[-1].image) == pytest.approx(cx - 320.0 / 6.0, abs=5)
