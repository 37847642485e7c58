"""The relative filter's state layout and motion model (:mod:`autopilot.estimation.relative`):
the state transition and process noise over an interval."""

from __future__ import annotations

import math

import numpy as np

from autopilot.estimation.relative_types import RelativeSettings

N = 14
R_, V_, B_, PSI, W_, A_, BETA = slice(0, 3), slice(3, 6), slice(6, 9), 9, 10, slice(11, 13), 13


def transition(s: RelativeSettings, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The motion model over ``dt``: the state transition F and the process noise Q (see
    :mod:`autopilot.estimation.relative`)."""
    f = np.eye(N)
    f[R_, V_] = np.eye(3) * dt
    a = math.exp(-dt / s.bias_time_constant_s)
    f[B_, B_] = np.eye(3) * a
    f[PSI, W_] = dt
    # the rover's acceleration a: v' = −a (the drone's own is the input), r'' = −a
    tau = s.accel_time_constant_s
    g = math.exp(-dt / tau)
    f[A_, A_] = np.eye(2) * g
    c = math.exp(-dt / s.compass_bias_time_constant_s)
    f[BETA, BETA] = c
    # a decays over the interval: its integrals, exactly
    f[3:5, A_] = -np.eye(2) * tau * (1.0 - g)
    f[0:2, A_] = -np.eye(2) * tau * (dt - tau * (1.0 - g))
    q = np.zeros((N, N))
    for axis, sigma in ((0, s.accel_noise_m_s2), (1, s.accel_noise_m_s2),
                        (2, s.vertical_accel_noise_m_s2)):
        var = sigma * sigma
        q[axis, axis] = var * dt ** 3 / 3.0
        q[axis, 3 + axis] = q[3 + axis, axis] = var * dt ** 2 / 2.0
        q[3 + axis, 3 + axis] = var * dt
    bias = np.square(np.array(s.rough_position_std_m)) * (1.0 - a * a)
    q[B_, B_] = np.diag(bias)
    var = s.yaw_accel_noise_rad_s2 ** 2
    q[PSI, PSI] = var * dt ** 3 / 3.0
    q[PSI, W_] = q[W_, PSI] = var * dt ** 2 / 2.0
    q[W_, W_] = var * dt
    q[BETA, BETA] = s.compass_bias_std_rad ** 2 * (1.0 - c * c)
    # jerk noise on a (integrated into v and r: the discrete white-jerk model, truncated)
    var = s.jerk_noise_m_s3 ** 2
    for axis in (0, 1):
        ia, iv, ir = 11 + axis, 3 + axis, axis
        q[ia, ia] += var * dt
        q[iv, iv] += var * dt ** 3 / 3.0
        q[ia, iv] = q[iv, ia] = -var * dt ** 2 / 2.0
        q[ir, ir] += var * dt ** 5 / 20.0
        q[ir, ia] = q[ia, ir] = -var * dt ** 3 / 6.0
        q[ir, iv] += var * dt ** 4 / 8.0
        q[iv, ir] += var * dt ** 4 / 8.0
    return f, q
