"""The heading filter (a marker face's direction) and the navigation errors a world-frame
target inherits."""

import math

import numpy as np
import pytest

from autopilot.estimation.heading import HeadingFilter, HeadingSettings
from autopilot.estimation.target import (
    NavigationUncertainty,
    TargetEstimate,
    navigation_covariance,
    with_navigation,
)

SETTINGS = HeadingSettings(accel_noise_rad_s2=math.radians(90), initial_rate_std_rad_s=1.0,
                           gate_chi2=10.8, stale_after_s=1.0)


def test_heading_tracks_a_turn_across_the_wrap():
    f = HeadingFilter(SETTINGS)
    rate = math.radians(30.0)
    rng = np.random.default_rng(3)
    accepted = 0
    for k in range(120):  # 4 s at 30 Hz, from 170° through ±180° to −130°
        t = k / 30.0
        truth = math.radians(170.0) + rate * t
        accepted += f.update(t, truth + rng.normal(0.0, math.radians(2.0)), math.radians(2.0))
    assert accepted >= 117  # the gate (3.3σ) lets through all but the rare outlier
    est = f.estimate(4.0, max_extrapolation_s=1.0)
    truth = math.atan2(math.sin(math.radians(170.0) + rate * 4.0),
                       math.cos(math.radians(170.0) + rate * 4.0))
    assert abs(math.remainder(est.heading_rad - truth, 2 * math.pi)) < math.radians(2.0)
    assert est.rate_rad_s == pytest.approx(rate, abs=math.radians(5.0))
    assert 0 < est.std_rad < math.radians(2.0)


def test_a_flipped_heading_is_gated_out_and_a_stale_track_restarts():
    f = HeadingFilter(SETTINGS)
    for k in range(30):
        f.update(k / 30.0, 0.0, math.radians(3.0))
    flipped = math.radians(40.0)  # the other IPPE pose of an ambiguous marker
    assert f.innovation2(1.0, flipped, math.radians(3.0)) > SETTINGS.gate_chi2
    assert not f.update(1.0, flipped, math.radians(3.0))
    assert f.update(3.0, flipped, math.radians(3.0))  # 2 s later: a new track
    assert f.estimate(3.0, 1.0).heading_rad == pytest.approx(flipped)


def test_navigation_errors_widen_the_estimate_across_the_line_of_sight():
    nav = NavigationUncertainty(position_std_m=0.01, attitude_std_rad=math.radians(1.0),
                                yaw_std_rad=math.radians(2.0))
    cov = navigation_covariance(np.array([3.0, 0.0, 0.0]), nav)  # 3 m north, level
    along, east, down = np.sqrt(np.diag(cov))
    assert along == pytest.approx(0.01)  # a lever arm does not change its own length
    assert east == pytest.approx(math.hypot(0.01, 3 * math.radians(1.0), 3 * math.radians(2.0)))
    assert down == pytest.approx(math.hypot(0.01, 3 * math.radians(1.0)))
    est = TargetEstimate(0.0, np.array([3.0, 0.0, -2.0]), np.zeros(3), np.eye(6) * 1e-4, 0.0,
                         False, 10, True)
    wider = with_navigation(est, np.array([0.0, 0.0, -2.0]), nav)
    assert np.allclose(wider.covariance[:3, :3], est.covariance[:3, :3] + cov)
    assert np.allclose(wider.covariance[3:, 3:], est.covariance[3:, 3:])
