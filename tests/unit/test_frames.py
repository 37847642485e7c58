"""The ENU/FLU (MuJoCo) ↔ NED/FRD (PX4) conversions at the simulator boundary."""

import math

import numpy as np
import pytest

from drivers.geometry import quat_from_axis_angle, quat_from_euler, quat_rotate, yaw_from_quat
from drivers.sim.frames import (
    enu_to_ned,
    flu_to_frd,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    quat_ned_frd_to_enu_flu,
)


def test_vectors():
    assert np.allclose(enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])  # east, north, up
    assert np.allclose(ned_to_enu(enu_to_ned([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0])
    assert np.allclose(flu_to_frd([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])


def test_level_body_facing_east_in_enu_has_heading_90():
    # identity in MuJoCo: body x (forward) along ENU x = east
    q = quat_enu_flu_to_ned_frd(np.array([1.0, 0.0, 0.0, 0.0]))
    assert yaw_from_quat(q) == pytest.approx(math.pi / 2)
    assert np.allclose(quat_rotate(q, [0, 0, 1]), [0, 0, 1])  # body down is world down


def test_body_facing_north_has_heading_zero():
    q_enu = quat_from_axis_angle([0, 0, 1], math.pi / 2)  # turn left 90° from east
    q = quat_enu_flu_to_ned_frd(q_enu)
    assert yaw_from_quat(q) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(("roll", "pitch", "yaw"), [(0.1, -0.3, 1.2), (-0.6, 0.2, -2.5)])
def test_attitude_round_trip_and_consistency(roll, pitch, yaw):
    q_ned = quat_from_euler(roll, pitch, yaw)
    q_enu = quat_ned_frd_to_enu_flu(q_ned)
    back = quat_enu_flu_to_ned_frd(q_enu)
    assert np.allclose(back, q_ned) or np.allclose(back, -q_ned)
    # the same physical vector, expressed either way, agrees
    v_frd = np.array([0.5, -1.0, 2.0])
    v_ned = quat_rotate(q_ned, v_frd)
    v_enu = quat_rotate(q_enu, flu_to_frd(v_frd))
    assert np.allclose(enu_to_ned(v_enu), v_ned)
