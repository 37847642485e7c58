"""The realistic profile's cameras on real renders: frames report a calibration fitted on
simulated board views (close to the truth, not the truth) and the nominal mount, carry the
codec's artefacts and the auto-exposure's gain, and arrive with drops and jitter, the same for
a seed."""

import contextlib
import hashlib

import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.sim_calibration import with_fitted_calibrations
from drivers.sim.model import camera_info
from drivers.sim.scenario import Geom, MocapBody, Static
from drivers.sim.simulator import Simulator

from ..conftest import sim_with
from .simtools import run, simulator, take_off

POLE = MocapBody("pole", [Geom("box", (0.02, 0.15, 1.2), (1.0, 0.0, 0.0, 1.0))],
                 Static((3.0, 0.0, -1.2)))


def test_frames_report_the_fitted_calibration_close_to_the_truth(sim_config, tmp_path,
                                                                 monkeypatch):
    monkeypatch.setenv("AUTOPILOT_CACHE_DIR", str(tmp_path))
    cfg = sim_with(sim_config, **{"cameras.front.sim_calibration": "fitted",
                                  "cameras.down.enabled": False})
    fitted = with_fitted_calibrations(cfg)
    path = fitted.cameras["front"].calibration
    assert path is not None
    assert path.startswith(str(tmp_path))
    mtime = (tmp_path / path).stat().st_mtime_ns
    # cached: the same file, not fitted again
    assert with_fitted_calibrations(cfg).cameras["front"].calibration == path
    assert (tmp_path / path).stat().st_mtime_ns == mtime
    sim = Simulator(fitted)
    try:
        reported = sim.capture("front").camera.intrinsics
        truth = sim.camera_infos()["front"].intrinsics
    finally:
        sim.close()
    assert reported != truth
    assert reported.fx == pytest.approx(truth.fx, rel=0.005)
    assert reported.fy == pytest.approx(truth.fy, rel=0.005)
    assert abs(reported.cx - truth.cx) < 2.0
    assert abs(reported.cy - truth.cy) < 2.0
    assert reported.distortion[0] == pytest.approx(truth.distortion[0], abs=0.02)


def _still(cfg, gain=1.0):
    sim = Simulator(cfg, scenario=[POLE])
    try:
        sim.set_vehicle_pose((0.0, 0.0, -2.0), (1.0, 0.0, 0.0, 0.0))
        cam = sim.cameras["front"]
        return sim.rig.finish(sim.rig.submit(sim.data, cam, 0.0, gain=gain)).image
    finally:
        sim.close()


@pytest.mark.parametrize("codec", ["jpeg", "h264"])
def test_codec_artefacts_and_exposure_gain(sim_config, codec):
    clean = {"cameras.front.noise_std_dn": 0.0, "cameras.front.exposure_s": 0.0}
    raw = _still(sim_with(sim_config, **clean))
    coded = _still(sim_with(sim_config, **clean, **{"cameras.front.codec": codec}))
    assert coded.shape == raw.shape
    diff = np.abs(raw.astype(int) - coded.astype(int))
    assert diff.max() > 5  # blocks and ringing at the pole's edges
    assert 0.2 < diff.mean() < 3.0  # but the image is the same
    brighter = _still(sim_with(sim_config, **clean), gain=1.12)
    unsaturated = raw < 200
    ratio = brighter[unsaturated].mean() / raw[unsaturated].mean()
    assert ratio == pytest.approx(1.12, abs=0.01)


def _stream(cfg, seed, count=60):
    async def main():
        async with simulator(cfg, seed=seed) as drv:
            await take_off(drv, 1.5)
            frames = []
            async with contextlib.aclosing(drv.frames("front")) as stream:
                async for frame in stream:
                    frames.append((frame.seq, frame.time_s, drv.clock.now(), frame.camera,
                                   hashlib.sha1(frame.image.tobytes()).hexdigest()))
                    if len(frames) == count:
                        break
            return frames

    return run(main())


def test_frames_arrive_with_drops_and_jitter_describing_the_nominal_mount():
    cfg = load_config(overrides=[
        "sim.profile=realistic", "vehicle.cameras.front.sim_calibration=truth",
        "vehicle.cameras.down.enabled=false", "vehicle.cameras.front.drop_fraction=0.1",
        "vehicle.cameras.front.latency_jitter_s=0.01",
        "vehicle.cameras.front.codec=h264"]).sim  # (stateful: deterministic too)
    frames = _stream(cfg, 7)
    seqs = np.array([f[0] for f in frames])
    assert np.all(np.diff(seqs) >= 1)
    assert np.any(np.diff(seqs) > 1)  # dropped frames: gaps in the sequence numbers
    stamps = np.array([f[1] for f in frames])
    arrivals = np.array([f[2] for f in frames])
    assert np.all(np.diff(arrivals) >= 0)  # in order
    delays = arrivals - stamps - cfg.cameras["front"].latency_s
    assert delays.min() >= -0.0021  # (up to a physics step early: delivery on the step grid)
    assert np.ptp(delays) > 0.01  # jitter
    nominal = camera_info("front", cfg.cameras["front"]).rotation_body_cam
    assert all(np.allclose(f[3].rotation_body_cam, nominal) for f in frames)
    again = _stream(cfg, 7)  # deterministic: drops, jitter, exposure, noise and codec
    assert [(f[0], f[1], f[2], f[4]) for f in again] == [(f[0], f[1], f[2], f[4]) for f in frames]


def test_the_true_cameras_are_those_of_the_simulator_s_own_seed(realistic_sim_config):
    """The mount errors the log scores against are drawn from the seed the simulator was
    started with (a driver given its own seed), not from the configuration's."""
    from drivers.sim.driver import SimDriver

    cfg = realistic_sim_config
    seed = cfg.seed + 5
    sim = Simulator(cfg, seed=seed)
    try:
        flown = sim.cameras["front"].info.rotation_body_cam
    finally:
        sim.close()
    scored = SimDriver(cfg, seed=seed).true_cameras()["front"].rotation_body_cam
    np.testing.assert_allclose(scored, flown, atol=1e-12)
    assert np.abs(SimDriver(cfg).true_cameras()["front"].rotation_body_cam - flown).max() > 1e-3
