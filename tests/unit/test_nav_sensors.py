"""The simulated vehicle's navigation grades (EKF output error models) and its rangefinder's
imperfections, by their statistics over long synthetic runs."""

import functools
import math

import numpy as np
import pytest

from autopilot.config import load_config
from drivers.sim.sensors import EstimatorModel, Rangefinder


@functools.cache
def _sim(*overrides: str):
    return load_config(overrides=["sim.profile=realistic", *overrides]).sim


def _estimator(grade: str, seed: int = 0, **changes) -> EstimatorModel:
    overrides = [f"sim.estimator.grade={grade}"]
    overrides += [f"sim.estimator.grades.{grade}.{k}={v}" for k, v in changes.items()]
    return EstimatorModel(_sim(*overrides).estimator, np.random.default_rng(seed))


def _errors(model: EstimatorModel, duration_s: float, dt_s: float,
            velocity=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position error, velocity error and heading error (rad) at every step."""
    n = int(duration_s / dt_s)
    velocity = np.asarray(velocity, float)
    pos, vel, yaw = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for i in range(n):
        model.step(dt_s, velocity)
        est = model.estimate(np.zeros(3), np.asarray(velocity, float), q, np.zeros(3))
        pos[i], vel[i] = est.position_ned_m, est.velocity_ned_m_s - velocity
        w, x, y, z = est.q_ned_frd
        yaw[i] = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return pos, vel, yaw


def _autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x))


def test_gnss_grade_wanders_by_half_a_metre_over_minutes():
    model = _estimator("gnss")
    g = model.grade
    dt = 0.5
    pos, vel, yaw = _errors(model, 400 * g.horizontal_time_constant_s, dt)
    horizontal = pos[:, :2]
    assert np.std(horizontal, axis=0) == pytest.approx([0.5, 0.5], rel=0.15)
    # correlated over a minute or more: e^-1 after one time constant (100 s)
    lag = int(g.horizontal_time_constant_s / dt)
    for axis in (0, 1):
        assert _autocorrelation(horizontal[:, axis], lag) == pytest.approx(math.exp(-1), abs=0.1)
        assert _autocorrelation(horizontal[:, axis], int(60 / dt)) > 0.45
    # centimetre white noise on top of a smooth wander: in half a second the error moves by
    # that noise and a centimetre or so of wander — unsmoothed, the wander alone would step by
    # 0.5 √(2 × 0.5 / 100) = 5 cm
    steps = np.diff(horizontal, axis=0)
    assert math.sqrt(2) * 0.01 < np.std(steps) < 0.025
    assert np.std(pos[:, 2]) == pytest.approx(0.2, rel=0.2)  # the barometer's decimetres
    assert np.std(vel) == pytest.approx(0.05, rel=0.1)
    assert np.degrees(np.std(yaw)) == pytest.approx(1.5, rel=0.25)


def test_rtk_grade_keeps_centimetres():
    pos, vel, _ = _errors(_estimator("rtk"), 8000.0, 0.5)
    assert np.std(pos) == pytest.approx(0.015, rel=0.15)
    assert np.std(vel) == pytest.approx(0.02, rel=0.15)


def test_optical_flow_drifts_in_proportion_to_the_distance_flown():
    """Straight legs at 2 m/s over many flights (a scale error and a heading error each): the
    drift's RMS grows with the distance, at the few per cent the scale and heading errors give;
    a hover drifts far less."""
    speed = 2.0

    def drift(distance_m: float, seeds: range, velocity) -> np.ndarray:
        out = []
        for seed in seeds:
            pos, _, _ = _errors(_estimator("optical_flow", seed), distance_m / speed, 0.5,
                                np.asarray(velocity, float))
            out.append(np.linalg.norm(pos[-1, :2]))
        return np.array(out)

    seeds = range(100)
    short = np.sqrt(np.mean(drift(40.0, seeds, [speed, 0, 0]) ** 2))
    long = np.sqrt(np.mean(drift(160.0, seeds, [speed, 0, 0]) ** 2))
    g = _estimator("optical_flow").grade
    per_metre = math.hypot(g.flow_scale_error, math.radians(g.yaw_error_deg))
    assert long / 160.0 == pytest.approx(per_metre, rel=0.25)
    assert long / short == pytest.approx(4.0, rel=0.25)
    hover = np.sqrt(np.mean(drift(160.0, range(30), [0, 0, 0]) ** 2))
    assert hover < 0.2 * long
    assert hover > 0.05  # but it does drift: the velocity bias integrates


def test_optical_flow_without_flow_errors_does_not_drift():
    pos, _, _ = _errors(_estimator("optical_flow", flow_scale_error=0.0, yaw_error_deg=0.0,
                                   flow_velocity_bias_m_s=0.0), 80.0, 0.1,
                        np.array([2.0, 0.0, 0.0]))
    assert np.max(np.abs(pos[:, :2])) < 0.05  # white noise only


def _rangefinder(seed: int = 0, **changes) -> Rangefinder:
    overrides = [f"sim.rangefinder.{k}={v}" for k, v in changes.items()]
    return Rangefinder(_sim(*overrides).rangefinder, np.random.default_rng(seed), 0)


def test_rangefinder_outliers_limits_and_dropouts():
    rf = _rangefinder()
    cfg = rf.cfg
    n = 40000
    readings = np.array([rf.reading(3.0, 1.0) for _ in range(n)])
    absent = np.isnan(readings)
    assert absent.mean() == pytest.approx(cfg.dropout_fraction, abs=0.004)
    valid = readings[~absent]
    good = np.abs(valid - 3.0) < 5 * cfg.noise_m
    assert np.std(valid[good]) == pytest.approx(cfg.noise_m, rel=0.05)
    wrong = valid[~good]
    assert len(wrong) / len(valid) == pytest.approx(cfg.outlier_fraction, rel=0.25)
    at_max = wrong == cfg.max_m
    assert at_max.mean() == pytest.approx(0.5, abs=0.12)  # missed returns read max range
    assert np.all((wrong[~at_max] >= cfg.min_m) & (wrong[~at_max] < 3.0))  # debris: short


def test_rangefinder_reads_nothing_outside_its_range_or_beyond_its_incidence():
    rf = _rangefinder(outlier_fraction=0.0, dropout_fraction=0.0)
    cfg = rf.cfg
    assert math.isnan(rf.reading(0.5 * cfg.min_m, 1.0))
    assert math.isnan(rf.reading(cfg.max_m + 0.5, 1.0))
    assert math.isnan(rf.reading(math.inf, 1.0))
    tilt = math.radians(cfg.max_incidence_deg)
    assert math.isnan(rf.reading(3.0, math.cos(tilt + 0.02)))
    assert rf.reading(3.0, math.cos(tilt - 0.02)) == pytest.approx(3.0, abs=5 * cfg.noise_m)


def test_rangefinder_outliers_stay_within_its_range():
    rf = _rangefinder(outlier_fraction=0.5, dropout_fraction=0.0)
    readings = np.array([rf.reading(20.0, 1.0) for _ in range(2000)])  # ground beyond range
    valid = readings[~np.isnan(readings)]
    assert len(valid) > 0  # spurious returns (max range, debris) even with nothing in range
    assert np.all((valid >= rf.cfg.min_m) & (valid <= rf.cfg.max_m))


def test_the_landings_height_ignores_the_rangefinders_outliers():
    """Descending at 0.5 m/s with the realistic rangefinder (5 × its outliers, to see many,
    and its dropouts) read at 50 Hz: the voted height strays from the truth only by what its
    tolerance lets through (0.1 m + 2 %), where single readings are metres off."""
    from autopilot.estimation.range_median import RangeMedian

    worst_raw = worst_voted = 0.0
    for seed in range(20):
        rf = _rangefinder(seed=seed, outlier_fraction=0.05)
        votes = RangeMedian()
        for k in range(460):  # down to 0.4 m
            t = 0.02 * k
            height = 5.0 - 0.5 * t
            raw = rf.reading(height, 1.0)
            voted = votes.add(t, raw, 0.5)
            if math.isfinite(raw):
                worst_raw = max(worst_raw, abs(raw - height))
            if k >= 3:  # (the first readings have nothing to be checked against)
                assert math.isfinite(voted)
                worst_voted = max(worst_voted, abs(voted - height))
    assert worst_raw > 5.0
    assert worst_voted < 0.1 + 0.02 * 5.0 + 3 * rf.cfg.noise_m
    # the surface lost for good: no height (the landing falls back on its estimate)
    for k in range(10):
        voted = votes.add(10.0 + 0.02 * k, math.nan)
    assert math.isnan(voted)


def test_a_target_filter_that_knows_the_navigation_keeps_a_still_pad_through_its_wander():
    """A pad lying still, seen at 30 Hz with 3 mm of measurement noise from a vehicle on GNSS
    navigation: in the navigation's frame the pad wanders with its error. The filter told of
    the navigation (its white noise, its wander) accepts nearly every frame; one that is not
    rejects many and loses the pad."""
    import dataclasses

    from autopilot.estimation.target import PositionMeasurement, TargetFilter
    from autopilot.perception.ball_pipeline import filter_settings

    cfg = load_config(overrides=["sim.profile=realistic"])
    told = dataclasses.replace(filter_settings(cfg), accel_noise_m_s2=0.5)
    blind = dataclasses.replace(told, navigation_noise_m=0.0,
                                navigation_drift_m2_s=(0.0, 0.0, 0.0))
    noise = 0.003
    rates = {}
    for name, settings in (("told", told), ("blind", blind)):
        nav = _estimator("gnss", seed=5)
        rng = np.random.default_rng(1)
        f, accepted, n = TargetFilter(settings), 0, 1800
        for k in range(n):
            t = k / 30.0
            nav.step(1 / 30.0)
            seen = nav.position_error_ned_m + rng.normal(0.0, noise, 3)
            cov = np.eye(3) * noise ** 2
            if settings.navigation_noise_m:
                cov = cov + np.eye(3) * settings.navigation_noise_m ** 2
            accepted += f.update(PositionMeasurement(t, seen, cov)).accepted
        rates[name] = accepted / n
    assert rates["told"] > 0.97
    assert rates["blind"] < 0.8


def test_target_filters_drift_rate_matches_the_simulated_wander():
    """The autopilot's random walk for its navigation's wander (``navigation_drift_rate`` from
    config.yaml's ``estimation.navigation``) is what the simulator's GNSS grade does over the
    filters' memory: the smoothed error's mean squared change over 1 s — several times less
    than the unsmoothed 2σ²/τ once charged (which left every estimate's σ too wide)."""
    from autopilot.estimation.target import navigation_drift_rate
    from autopilot.perception.ball_pipeline import filter_settings

    settings = filter_settings(load_config(overrides=["sim.profile=realistic"]))
    nav = load_config(overrides=["sim.profile=realistic"]).estimation.navigation
    grade = _sim().estimator.grades["gnss"]
    assert (nav.position_std_m, nav.position_time_constant_s, nav.position_smoothing_s) == \
        (grade.horizontal_error_m, grade.horizontal_time_constant_s,
         grade.position_smoothing_s)
    dt, window = 0.05, 1.0
    lag = round(window / dt)
    changes = []
    for seed in range(6):
        pos, _, _ = _errors(_estimator("gnss", seed, position_noise_m=0.0), 600.0, dt)
        changes.append(pos[lag:] - pos[:-lag])
    changes = np.concatenate(changes)
    measured = (changes ** 2).mean(axis=0) / window
    horizontal, height = settings.navigation_drift_m2_s[0], settings.navigation_drift_m2_s[2]
    assert measured[:2].mean() == pytest.approx(horizontal, rel=0.2)
    assert measured[2] == pytest.approx(height, rel=0.25)
    assert 2 * nav.position_std_m ** 2 / nav.position_time_constant_s > 4 * measured[:2].mean()
    # without the lag the old random walk is the limit
    assert navigation_drift_rate(0.5, 100.0, 0.0, 1e-3) == pytest.approx(2 * 0.25 / 100, rel=1e-3)
    assert navigation_drift_rate(0.5, 3.0, 3.0, 1.0) == pytest.approx(
        navigation_drift_rate(0.5, 3.0, 3.0 + 1e-6, 1.0), rel=1e-4)
