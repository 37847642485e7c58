"""The realistic profile's camera and compute dimensions, each on its own: dropped frames,
capture latency jitter, auto-exposure steps, the mount's error, and what detection is charged
on the lockstep clock."""

import asyncio
import math

import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.runtime import detection_charge
from drivers.clock import LockstepClock
from drivers.sim.camera_effects import CaptureModel
from drivers.sim.model import camera_info, mount_error, reported_camera_info, true_camera_info


@pytest.fixture(scope="module")
def realistic():
    return load_config(overrides=["sim.profile=realistic"])


@pytest.fixture(scope="module")
def ideal():
    return load_config(overrides=["sim.profile=ideal"])


def _captures(cam, n, seed=0):
    model = CaptureModel("front", cam, seed)
    return [model.next() for _ in range(n)]


def test_ideal_profile_keeps_the_kind_camera(ideal):
    cam = ideal.sim.cameras["front"]
    assert (cam.rolling_shutter_s, cam.latency_jitter_s, cam.drop_fraction,
            cam.mount_error_deg, cam.auto_exposure_step) == (0.0,) * 5
    assert cam.codec == "none"
    assert cam.sim_calibration == "truth"
    assert ideal.sim.compute_charge == "fixed"
    caps = _captures(cam, 2000)
    assert not any(c.dropped for c in caps)
    assert {c.delay_s for c in caps} == {0.0}
    assert {c.gain for c in caps} == {1.0}


def test_dropped_frame_rate(realistic):
    cam = realistic.sim.cameras["front"]
    assert cam.drop_fraction == pytest.approx(0.01)
    n = 30000
    dropped = sum(c.dropped for c in _captures(cam, n))
    # binomial: 300 expected, σ 17
    assert abs(dropped - n * cam.drop_fraction) < 4 * math.sqrt(n * 0.01 * 0.99)


def test_latency_jitter_is_half_normal_and_keeps_frames_in_order(realistic):
    cam = realistic.sim.cameras["front"].model_copy(update={"latency_jitter_s": 0.01})
    delays = np.array([c.delay_s for c in _captures(cam, 20000)])
    assert delays.min() >= 0.0
    # a half-normal of scale σ: mean σ·√(2/π), rms σ (frames 33 ms apart hardly ever collide)
    assert delays.mean() == pytest.approx(0.01 * math.sqrt(2 / math.pi), rel=0.03)
    assert math.sqrt(np.mean(delays ** 2)) == pytest.approx(0.01, rel=0.03)
    period = 1.0 / cam.rate_hz
    arrivals = np.arange(delays.size) * period + delays
    assert np.all(np.diff(arrivals) >= -1e-12)
    # a jitter longer than the frame period: still in order
    cam = cam.model_copy(update={"latency_jitter_s": 0.1})
    delays = np.array([c.delay_s for c in _captures(cam, 3000)])
    assert np.all(np.diff(np.arange(delays.size) * period + delays) >= -1e-12)


def test_auto_exposure_steps(realistic):
    cam = realistic.sim.cameras["front"]
    n = int(600 * cam.rate_hz)  # ten minutes
    gains = np.array([c.gain for c in _captures(cam, n)])
    steps = np.flatnonzero(np.diff(gains))
    expected = n / (cam.rate_hz * cam.auto_exposure_interval_s)
    assert abs(steps.size - expected) < 4 * math.sqrt(expected)
    assert np.allclose(np.abs(np.diff(gains)[steps]), cam.auto_exposure_step)
    assert gains.min() >= 1 - 2 * cam.auto_exposure_step - 1e-9
    assert gains.max() <= 1 + 2 * cam.auto_exposure_step + 1e-9
    assert len(set(np.round(gains, 6))) >= 3  # it goes both ways


def test_capture_model_is_deterministic_per_seed_and_camera(realistic):
    cam = realistic.sim.cameras["front"]
    assert _captures(cam, 500, seed=3) == _captures(cam, 500, seed=3)
    assert _captures(cam, 500, seed=3) != _captures(cam, 500, seed=4)


def _angle_deg(a, b):
    return math.degrees(math.acos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1)))


def test_mount_error_applied_to_the_camera_but_not_reported(realistic, ideal):
    angles = []
    for seed in range(40):
        for name, cam in realistic.sim.cameras.items():
            nominal = camera_info(name, cam).rotation_body_cam
            true = true_camera_info(name, cam, seed).rotation_body_cam
            assert np.allclose(true.T @ true, np.eye(3))
            assert np.allclose(reported_camera_info(name, cam).rotation_body_cam, nominal)
            angles.append(_angle_deg(nominal, true))
    # three axes of σ 1°: the angle is Maxwell-distributed, mean 1.6°
    assert np.mean(angles) == pytest.approx(2 * math.sqrt(2 / math.pi), rel=0.15)
    assert min(angles) > 0.0
    cam = realistic.sim.cameras["front"]
    assert np.array_equal(mount_error("front", cam, 5), mount_error("front", cam, 5))
    assert not np.array_equal(mount_error("front", cam, 5), mount_error("down", cam, 5))
    assert np.array_equal(mount_error("front", ideal.sim.cameras["front"], 5), np.eye(3))


def test_reported_intrinsics_come_from_the_calibration_file(realistic, tmp_path):
    from drivers.calibration import write_calibration

    cam = realistic.sim.cameras["down"]
    truth = camera_info("down", cam).intrinsics
    fitted = type(truth)(truth.width_px, truth.height_px, truth.fx * 1.002, truth.fy * 0.999,
                         truth.cx + 0.4, truth.cy - 0.3, (-0.049, 0.0058, 0.0003, 0.0002, 0.0))
    path = tmp_path / "down.yaml"
    write_calibration(path, fitted)
    assert reported_camera_info("down", cam).intrinsics == truth  # no file: the truth
    reported = reported_camera_info("down", cam.model_copy(update={"calibration": str(path)}))
    assert reported.intrinsics.fx == pytest.approx(fitted.fx)
    assert reported.intrinsics.distortion == pytest.approx(fitted.distortion)
    wrong = cam.model_copy(update={"calibration": str(path), "width_px": 320, "height_px": 240})
    with pytest.raises(ValueError, match="calibration"):
        reported_camera_info("down", wrong)


def test_detection_charge(realistic, ideal):
    assert detection_charge(ideal, ["ball"]) == pytest.approx(0.005)
    assert detection_charge(ideal, ["ball", "pad"]) == pytest.approx(0.010)
    costs = realistic.sim.compute_cost_ms
    assert detection_charge(realistic, ["image"]) == pytest.approx(costs["image"] / 1e3)
    assert detection_charge(realistic, ["unknown"]) == pytest.approx(
        realistic.runtime.lockstep_detection_s)
    slow = load_config(overrides=["sim.profile=realistic", "sim.compute_scale=4"])
    assert detection_charge(slow, ["ball", "pad"]) == pytest.approx(
        4 * (costs["ball"] + costs["pad"]) / 1e3)
    measured = load_config(overrides=["sim.profile=realistic", "sim.compute_scale=3",
                                      "sim.compute_charge=measured"])
    charge = detection_charge(measured, ["ball", "pad"])
    assert charge([(None, 7.0, None), ("det", 3.0, None)]) == pytest.approx(0.030)


def test_lockstep_job_charged_what_its_result_says():
    """A job whose charge is known from its result: time stands still while it runs, then
    its result arrives that long after it started."""

    async def main():
        clock = LockstepClock()
        clock.advance(1.0)
        stepped: list[float] = []
        results = []

        async def job():
            out = await clock.run_blocking(lambda: 0.03, budget_s=lambda r: r * 2)
            results.append((out, clock.now()))

        async def stepper():
            while True:
                await clock.settle()
                deadline = clock.next_deadline()
                target = min(deadline if deadline is not None else 2.0, clock.now() + 0.01)
                stepped.append(target)
                await clock.jobs_done(target)
                clock.advance(target)

        task = asyncio.ensure_future(job())
        drive = asyncio.ensure_future(stepper())
        await task
        drive.cancel()
        assert results == [(0.03, pytest.approx(1.06))]
        assert pytest.approx(1.06) in stepped

    asyncio.run(main())
