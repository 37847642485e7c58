"""Target filter and pose history, driven with synthetic measurements."""

import math

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise

from autopilot.estimation.pose_history import PoseHistory
from autopilot.estimation.target import (
    PositionMeasurement,
    TargetFilter,
    TargetFilterSettings,
    camera_measurement,
    process_noise,
)
from drivers.geometry import quat_from_euler

from ..factories import front_camera, vehicle_state

SETTINGS = TargetFilterSettings(accel_noise_m_s2=2.0, gate_chi2=16.3, stale_after_s=1.0,
                                initial_velocity_std_m_s=2.0, max_extrapolation_s=1.0,
                                pixel_noise_px=1.0, radius_noise_px=0.5)
SIGMA = 0.05
COV = np.eye(3) * SIGMA ** 2


def _target(t):  # 1.5 m/s north-east, steady
    return np.array([2.0, 1.0, -1.5]) + np.array([1.2, 0.9, 0.0]) * t


def _feed(f, rng, times, truth=_target):
    for t in times:
        f.update(PositionMeasurement(t, truth(t) + rng.normal(0, SIGMA, 3), COV))


def test_converges_on_a_constant_velocity_target():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(0)
    _feed(f, rng, np.arange(0.0, 3.0, 1 / 30))
    est = f.estimate(3.0 - 1 / 30)
    assert np.linalg.norm(est.position_ned_m - _target(3.0 - 1 / 30)) < 3 * SIGMA
    assert np.linalg.norm(est.velocity_ned_m_s - [1.2, 0.9, 0.0]) < 0.15
    assert est.position_std_m.max() < SIGMA


def test_measurements_apply_at_capture_time_and_estimates_extrapolate_to_now():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(1)
    _feed(f, rng, np.arange(0.0, 3.0, 1 / 30))
    now = 3.0 - 1 / 30 + 0.06  # 60 ms after the last capture
    est = f.estimate(now)
    assert est.time_s == now
    assert est.age_s == pytest.approx(0.06)
    assert np.linalg.norm(est.position_ned_m - _target(now)) < 3 * SIGMA
    # extrapolation is capped
    far = f.estimate(now + 10.0)
    assert np.allclose(far.position_ned_m, f.estimate(3.0 - 1 / 30 + 1.0).position_ned_m)
    assert far.stale


def test_an_outlier_is_gated_out():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(2)
    _feed(f, rng, np.arange(0.0, 2.0, 1 / 30))
    before = f.estimate(2.0)
    result = f.update(PositionMeasurement(2.0, _target(2.0) + np.array([3.0, 0.0, 0.0]), COV))
    assert not result.accepted
    assert result.mahalanobis2 > SETTINGS.gate_chi2
    assert np.allclose(f.estimate(2.0).position_ned_m, before.position_ned_m)


def test_consistent_rejections_restart_the_track():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(3)
    _feed(f, rng, np.arange(0.0, 2.0, 1 / 30))
    jumped = lambda t: _target(t) + np.array([4.0, -2.0, 0.0])  # noqa: E731
    results = [f.update(PositionMeasurement(t, jumped(t), COV))
               for t in np.arange(2.0, 2.0 + 5 / 30, 1 / 30)]
    assert not results[0].accepted
    assert any(r.reinitialised for r in results)
    est = f.estimate(2.0 + 4 / 30)
    assert np.linalg.norm(est.position_ned_m - jumped(2.0 + 4 / 30)) < 0.1
    assert np.linalg.norm(est.velocity_ned_m_s - [1.2, 0.9, 0.0]) < 0.5


def test_a_shift_moves_the_estimate_and_the_rejections_so_a_restart_still_fires():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(3)
    _feed(f, rng, np.arange(0.0, 2.0, 1 / 30))
    delta = np.array([0.3, -0.2, 0.1])
    before = f.estimate(2.0).position_ned_m
    f.shift(delta)
    assert np.allclose(f.estimate(2.0).position_ned_m, before + delta)
    jumped = lambda t: _target(t) + delta + np.array([4.0, -2.0, 0.0])  # noqa: E731
    times = np.arange(2.0, 2.0 + 5 / 30, 1 / 30)
    results = [f.update(PositionMeasurement(times[0], jumped(times[0]), COV))]
    f.shift(np.array([0.01, 0.0, 0.0]))  # a moved frame moves the rejections along
    jumped_after = lambda t: jumped(t) + np.array([0.01, 0.0, 0.0])  # noqa: E731
    for t in times[1:]:
        f.shift(np.zeros(3))  # the frame unchanged, every frame: the rejections are kept
        results.append(f.update(PositionMeasurement(t, jumped_after(t), COV)))
    assert not results[0].accepted
    assert any(r.reinitialised for r in results)
    assert np.linalg.norm(f.estimate(times[-1]).position_ned_m - jumped_after(times[-1])) < 0.1


def test_stale_track_restarts_on_the_next_measurement():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(4)
    _feed(f, rng, np.arange(0.0, 1.0, 1 / 30))
    assert f.is_stale(2.5)
    result = f.update(PositionMeasurement(2.5, np.array([10.0, 10.0, -1.0]), COV))
    assert result.reinitialised
    assert result.accepted
    assert np.allclose(f.estimate(2.5).position_ned_m, [10.0, 10.0, -1.0])


def test_older_measurements_are_ignored():
    f, rng = TargetFilter(SETTINGS), np.random.default_rng(5)
    _feed(f, rng, np.arange(0.0, 1.0, 1 / 30))
    assert not f.update(PositionMeasurement(0.5, _target(0.5), COV)).accepted


@pytest.mark.parametrize("dt", [0.0, 1 / 30, 0.4])
def test_process_noise_matches_filterpy(dt):
    expected = Q_discrete_white_noise(dim=2, dt=dt, var=4.0, block_size=3, order_by_dim=False)
    assert np.allclose(process_noise(dt, 2.0), expected)


def test_camera_measurement_geometry_and_covariance():
    from autopilot.estimation.pose_history import Pose

    pose = Pose(0.0, np.array([1.0, 2.0, -3.0]), quat_from_euler(0.0, 0.0, math.pi / 2))
    meas = camera_measurement(np.array([0.0, 0.0, 4.0]), 4.0, 16.0, front_camera(), pose, SETTINGS,
                              0.0)
    # 4 m straight ahead of a vehicle facing east
    assert np.allclose(meas.position_ned_m, [1.0, 6.0, -3.0])
    w, vecs = np.linalg.eigh(meas.covariance)
    along = vecs[:, np.argmax(w)]
    assert abs(along @ [0.0, 1.0, 0.0]) == pytest.approx(1.0)  # longest along the sight line
    assert math.sqrt(w.max()) == pytest.approx(4.0 * 0.5 / 16.0)
    assert math.sqrt(w.min()) == pytest.approx(4.0 * 1.0 / 320.0)


def _state(t, north, yaw):
    return vehicle_state(t, (north, 0.0, -2.0), (1.0, 0.0, 0.0), yaw)


def test_pose_history_interpolates_and_extrapolates():
    h = PoseHistory(max_extrapolation_s=0.1)
    h.add(_state(1.0, 0.0, 0.0))
    h.add(_state(1.02, 0.02, 0.2))
    mid = h.pose_at(1.01)
    assert mid.position_ned_m[0] == pytest.approx(0.01)
    from drivers.geometry import yaw_from_quat

    assert yaw_from_quat(mid.attitude_q) == pytest.approx(0.1)
    ahead = h.pose_at(1.07)  # past the newest sample: extrapolated with its velocity
    assert ahead.position_ned_m[0] == pytest.approx(0.07)
    assert h.pose_at(1.5) is None
    assert h.pose_at(0.5) is None


def test_pose_history_places_the_attitude_at_its_own_capture_time():
    """Over MAVLink the attitude travels apart from the position (ArduPilot: ATTITUDE and
    LOCAL_POSITION_NED at their own rates): a sample's attitude may be a message older than
    its position, and is placed at its own time."""
    import dataclasses

    from drivers.geometry import quat_from_euler

    h = PoseHistory(max_extrapolation_s=0.1)
    rate = 1.0  # rad/s of roll
    for k in range(10):
        t = 1.0 + 0.04 * k
        state = vehicle_state(t, (0.0, 0.0, -5.0))
        att_t = t - 0.02  # the attitude in each sample is 20 ms older than its position
        h.add(dataclasses.replace(state, attitude_q=quat_from_euler(rate * (att_t - 1.0), 0, 0),
                                  angular_velocity_frd_rad_s=(rate, 0.0, 0.0),
                                  attitude_time_s=att_t))
    from drivers.geometry import euler_from_quat

    roll = euler_from_quat(h.pose_at(1.2).attitude_q)[0]
    assert roll == pytest.approx(0.2, abs=1e-6)  # not 0.18, the attitude that came with it
    # past the newest attitude (at 1.34): turned on at its rates
    roll = euler_from_quat(h.pose_at(1.37).attitude_q)[0]
    assert roll == pytest.approx(0.37, abs=1e-6)
