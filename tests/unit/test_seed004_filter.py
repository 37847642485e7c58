"""Seed 004's fused filter (autopilot/estimation/seed004.py) against its report's chapter 4
(/work/shared/seeds/004_*.txt, quoted): one filterpy Kalman filter, PX4 local position, UWB
(pre-solved, rotated with the rover's yaw, x and y), AprilTag, rover compass and laser
altimeter; R_uwb = 2, R_tag = 0.5; update step at 10 Hz with only new measurements, in
Algorithm 8's order; prediction at half that rate; use_uwb / use_marker."""

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from autopilot.config import load_config
from autopilot.estimation.relative_types import DeckGeometry
from autopilot.estimation.seed004 import ORDER, Seed004Filter, Seed004Settings

ANCHORS = ((0.5, 0.4, -0.47), (0.5, -0.4, -0.47), (-0.5, 0.4, -0.47), (-0.55, -0.45, -1.0))
GEOMETRY = DeckGeometry((1.0, 0.8), 0.45, ANCHORS, (0.0, 0.0, 0.0))
LEVEL = np.eye(3)


def _filter(**flags) -> Seed004Filter:
    return Seed004Filter(Seed004Settings(), GEOMETRY, **flags)


def _ranges(rel_rover_frame: np.ndarray, rng=None, noise=0.0):
    """UWB ranges from the drone's tag at ``rel_rover_frame`` (FRD from the deck's top centre)
    to the anchors."""
    anchors = np.array(ANCHORS) + np.array([0.0, 0.0, 0.45])
    r = np.linalg.norm(anchors - rel_rover_frame, axis=1)
    if rng is not None:
        r = r + rng.normal(0.0, noise, r.shape)
    return (0, 1, 2, 3), tuple(r)


def test_the_seed_values_are_the_defaults_and_config_yaml_holds_them():
    # "all the following testing will be done with a value of R_uwb = 2m and R_tag = 0.5m"
    # "The following update step is requested every 10 Hz."
    # "The frequency of such timer is twice the set frequency of the prediction step."
    s = Seed004Settings()
    assert (s.r_uwb, s.r_tag, s.update_rate_hz, s.predict_rate_hz) == (2.0, 0.5, 10.0, 5.0)
    cfg = load_config().estimation.seed004
    assert Seed004Settings(**cfg.model_dump()) == s


def test_one_filterpy_kalman_filter_with_the_seeds_measurement_models():
    # "For the Kalman filter code implementation, the FilterPy Python library has been
    # employed" ... "implemented through the KalmanFilter.update(z, R) method"
    f = _filter()
    f.add_compass(0.0, 0.0)
    f.add_tag(0.0, (0.0, 0.0, -2.0))
    f.add_px4(0.0, (1.0, 2.0, -2.5))
    f.advance(0.1)
    assert isinstance(f.kf, KalmanFilter)
    x = np.arange(13, dtype=float)
    f.kf.x = x.reshape(-1, 1)
    # "Since all matrices are diagonal it is possible to define them via a single value"
    h, r, _ = f._model("uwb", np.zeros(2))
    # z_UWB = [x_rel, y_rel] (eq. 4.13): the UAV's position minus the rover's, x and y
    assert np.allclose(h @ x, x[0:2] - x[6:8])
    assert np.allclose(r, 2.0 * np.eye(2))
    h, r, _ = f._model("tag", np.zeros(3))
    assert np.allclose(h @ x, x[0:3] - x[6:9])
    assert np.allclose(r, 0.5 * np.eye(3))
    h, r, _ = f._model("px4", np.zeros(3))  # z_PX4 = [x, y, z]^NED (eq. 4.14)
    assert np.allclose(h @ x, x[0:3])
    assert np.allclose(r, Seed004Settings().r_px4 * np.eye(3))
    h, _, _ = f._model("compass", np.zeros(1))  # z_UGVyaw = ψ_UGV (eq. 4.15)
    assert np.allclose(h @ x, [x[12]])
    # "Relative altitude of the drone, acquired through a laser altimeter": deck z − UAV z
    h, _, _ = f._model("range", np.zeros(1))
    assert np.allclose(h @ x, [x[8] - x[2]])


def test_uwb_is_rotated_from_the_rover_frame_with_its_yaw_and_gives_x_and_y():
    # R_UGV^NED = [[cos ψ, −sin ψ, 0], [sin ψ, cos ψ, 0], [0, 0, 1]] (eq. 4.11)
    psi = 0.7
    assert np.allclose(Seed004Filter.rotation(psi), [[math.cos(psi), -math.sin(psi), 0],
                                                     [math.sin(psi), math.cos(psi), 0],
                                                     [0, 0, 1]])
    f = _filter(use_marker=False)
    f.add_compass(0.0, math.pi / 2)  # the rover faces east
    rel_rover = np.array([1.0, 0.0, -3.0])  # 1 m ahead of the deck's centre, 3 m up
    f.add_uwb(0.0, *_ranges(rel_rover), LEVEL)
    _t, z = f._pending["uwb"]
    # p_UAV^NED = R · p_UAV^UGV (eq. 4.12): ahead of an east-facing rover is east
    assert z.shape == (2,)
    assert np.allclose(z, [0.0, 1.0], atol=1e-6)


def test_the_update_step_runs_at_10_hz_on_new_measurements_only_and_prediction_at_5_hz():
    # "It will update the Kalman filter only if it has received a new measurement since the
    # last update step"
    f = _filter()
    f.add_compass(0.0, 0.0)
    f.add_tag(0.0, (0.0, 0.0, -3.0))
    for k in range(101):  # PX4 at 50 Hz for 2 s
        f.add_px4(k * 0.02, (0.0, 0.0, -3.0))
    assert f.updates["px4"] == 20  # 10 Hz (at 0.0, 0.1, ..., 1.9)
    assert f.updates["tag"] == 1
    assert f.updates["compass"] == 1
    assert f.predictions == 10  # 5 Hz (at 0.2, ..., 2.0; the filter began at 0.1)
    # the estimate is the one the prediction step published ("In the same callback ... that
    # contains the predict() method it is present the publishing section")
    assert f.estimate(2.05).time_s == pytest.approx(2.0)
    assert f.estimate(2.19).time_s == pytest.approx(2.0)
    assert f.estimate(2.21).time_s == pytest.approx(2.2)


def test_only_the_newest_measurement_since_the_last_update_step_is_fused():
    f = _filter()
    f.add_compass(0.0, 0.0)
    f.add_tag(0.0, (0.0, 0.0, -3.0))
    f.add_px4(0.0, (0.0, 0.0, -3.0))
    f.advance(0.01)
    before = f.updates["tag"]
    for k, north in enumerate((5.0, 5.0, 5.0, 0.3)):
        f.add_tag(0.02 + 0.02 * k, (north, 0.0, -3.0))
    f.advance(0.1)
    assert f.updates["tag"] == before + 1
    rel = f.kf.x[0:3, 0] - f.kf.x[6:9, 0]
    assert 0.0 < rel[0] < 0.3 + 1e-6  # pulled toward the newest (0.3), never toward 5 m


def test_algorithm_8s_order_uwb_px4_compass_altimeter_tag(monkeypatch):
    # "if UWB measurements are available ... if PX4 measurements are available ... if UGV
    # compass measurement is available ... if Altimeter measurement is available ... if
    # Apriltag measurements are available"
    f = _filter()
    f.add_compass(0.0, 0.0)
    f.add_px4(0.0, (0.0, 0.0, -3.0))
    f.add_tag(0.0, (0.0, 0.0, -3.0))
    f.advance(0.01)
    seen = []
    model = f._model
    monkeypatch.setattr(f, "_model", lambda source, z: seen.append(source) or model(source, z))
    f.add_tag(0.05, (0.0, 0.0, -3.0))
    f.add_range(0.05, 3.0)
    f.add_compass(0.05, 0.0)
    f.add_px4(0.05, (0.0, 0.0, -3.0))
    f.add_uwb(0.05, *_ranges(np.array([0.0, 0.0, -3.0])), LEVEL)
    f.advance(0.1)
    assert tuple(seen) == ORDER == ("uwb", "px4", "compass", "range", "tag")


def test_use_uwb_and_use_marker_select_the_sources():
    # "use_uwb: Which is a boolean value related to the usage of the ultra-wide band sensor"
    # "use_tag: A boolean value expressing whether the node will be employing the apriltag"
    for use_uwb, use_marker in ((True, False), (False, True), (False, False)):
        f = _filter(use_uwb=use_uwb, use_marker=use_marker)
        f.add_rover_position((2.0, 0.0, 0.0))
        for k in range(30):
            t = 0.05 * k
            f.add_compass(t, 0.0)
            f.add_px4(t, (0.0, 0.0, -3.0))
            f.add_uwb(t, *_ranges(np.array([-2.0, 0.0, -3.0])), LEVEL)
            f.add_tag(t, (-2.0, 0.0, -3.0))
        assert (f.updates["uwb"] > 0) == use_uwb
        assert (f.updates["tag"] > 0) == use_marker


def _fly(rover_speed: float, *, use_uwb=True, use_marker=True, seconds=12.0, seed=3):
    """A drone hovering 3 m over a rover that drives north; sensors at their simulated
    rates with noise; the estimate's horizontal errors over the last 4 s."""
    rng = np.random.default_rng(seed)
    f = _filter(use_uwb=use_uwb, use_marker=use_marker)
    errors = []
    t = 0.0
    while t < seconds:
        rover = np.array([5.0 + rover_speed * t, 0.0, -0.45])
        drone = np.array([5.0 + rover_speed * t - 0.5, 0.2, -3.45])
        rel = drone - rover
        k = round(t / 0.02)
        f.add_px4(t, drone + rng.normal(0.0, 0.02, 3))
        if k % 5 == 0:  # 10 Hz: the rover's compass, UWB, the altimeter; the tag at 10 Hz
            f.add_rover_position(rover + rng.normal(0.0, 1.0, 3))
            f.add_compass(t, rng.normal(0.0, 0.03))
            f.add_uwb(t, *_ranges(rel, rng, 0.08), LEVEL)
            f.add_range(t, 3.0 + rng.normal(0.0, 0.02))
            f.add_tag(t, rel + rng.normal(0.0, 0.02, 3))
        est = f.estimate(t)
        if est is not None and t > seconds - 4.0:
            truth_then = np.array([-0.5, 0.2, -3.0])  # constant relative position
            errors.append(np.hypot(*(est.position_m - truth_then)[:2]))
        t += 0.02
    return np.array(errors)


def test_the_fused_filter_estimates_the_relative_position_on_a_static_and_a_moving_rover():
    # "This solution showed good estimation performance with a precision in the landing phase
    # which was between the 10 cm confidence band"
    assert np.max(_fly(0.0)) < 0.10
    assert np.max(_fly(1.5)) < 0.10
    assert np.max(_fly(0.0, use_marker=False)) < 0.25  # UWB alone: R = 2, a noisier estimate
    # without either: the rough rover_position only, off by its metre
    assert np.median(_fly(0.0, use_uwb=False, use_marker=False)) > 0.1


def test_use_flags_are_validated_as_parameters_of_the_seed004_strategy():
    from pydantic import ValidationError

    from autopilot.behaviors.land_on_rover import LandOnRoverParams

    p = LandOnRoverParams(strategy="seed004", use_uwb=False, use_marker=True)
    assert (p.use_uwb, p.use_marker, p.strategy) == (False, True, "seed004")
    with pytest.raises(ValidationError):
        LandOnRoverParams(strategy="seed004", use_uwb="sometimes")
    with pytest.raises(ValidationError):
        LandOnRoverParams(strategy="seed005")
