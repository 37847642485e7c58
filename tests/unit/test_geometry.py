import math

import numpy as np
import pytest

from drivers.geometry import (
    euler_from_quat,
    matrix_to_quat,
    quat_between,
    quat_conjugate,
    quat_from_euler,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
    wrap_pi,
    yaw_from_quat,
)

ANGLES = [(0.1, -0.2, 0.3), (-0.5, 0.4, 2.9), (0.0, 0.0, -3.0), (1.0, -1.2, 0.0)]


@pytest.mark.parametrize(("roll", "pitch", "yaw"), ANGLES)
def test_euler_round_trip(roll, pitch, yaw):
    q = quat_from_euler(roll, pitch, yaw)
    assert np.allclose(euler_from_quat(q), (roll, pitch, yaw))
    assert yaw_from_quat(q) == pytest.approx(yaw)


@pytest.mark.parametrize(("roll", "pitch", "yaw"), ANGLES)
def test_matrix_round_trip_and_orthonormal(roll, pitch, yaw):
    q = quat_from_euler(roll, pitch, yaw)
    r = quat_to_matrix(q)
    assert np.allclose(r @ r.T, np.eye(3))
    assert np.linalg.det(r) == pytest.approx(1.0)
    q2 = matrix_to_quat(r)
    assert np.allclose(q2, q) or np.allclose(q2, -q)


def test_yaw_rotates_north_to_east():
    # heading +90° (east): the body's forward axis points east in NED
    q = quat_from_euler(0.0, 0.0, math.pi / 2)
    assert np.allclose(quat_rotate(q, [1, 0, 0]), [0, 1, 0])


def test_positive_pitch_is_nose_up():
    q = quat_from_euler(0.0, 0.3, 0.0)
    forward = quat_rotate(q, [1, 0, 0])
    assert forward[2] < 0  # NED: up is negative z


def test_multiply_composes_rotations():
    a = quat_from_euler(0.2, 0.0, 0.0)
    b = quat_from_euler(0.0, 0.0, 0.7)
    v = np.array([0.3, -1.0, 2.0])
    assert np.allclose(quat_rotate(quat_multiply(b, a), v), quat_rotate(b, quat_rotate(a, v)))
    assert np.allclose(quat_multiply(a, quat_conjugate(a)), [1, 0, 0, 0])


@pytest.mark.parametrize("b", [[0, 0, 1], [1, 1, 0], [-1, 0, 0], [0.2, -0.4, -1]])
def test_quat_between(b):
    a = np.array([1.0, 0.0, 0.0])
    q = quat_between(a, b)
    assert np.allclose(quat_rotate(q, a), np.array(b) / np.linalg.norm(b))


def test_wrap_pi():
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_pi(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_pi(0.5) == pytest.approx(0.5)
