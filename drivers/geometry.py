"""Rotation helpers shared by the drivers and the autopilot.

Conventions (as PX4): world frame NED (x north, y east, z down), body frame FRD (x forward,
y right, z down). Quaternions are ``(w, x, y, z)``, Hamilton convention, and ``q`` rotates a
vector from the body frame into the world frame: ``v_world = R(q) @ v_body``.
Euler angles are the aerospace ZYX sequence (yaw, then pitch, then roll), in radians.

These run inside the simulator's 250 Hz control loop, so they are written for small arrays.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])


def _floats(v) -> list[float]:
    return v.tolist() if isinstance(v, np.ndarray) else [float(x) for x in v]


# Float kernels (lists/tuples in, tuples out): the simulator's control loop calls these at
# 250 Hz, where numpy's per-call overhead on 3- and 4-vectors would dominate.


def qmul(a, b) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def qconj(q) -> tuple[float, float, float, float]:
    return (q[0], -q[1], -q[2], -q[3])


def qcanon(q) -> tuple[float, float, float, float]:
    return (-q[0], -q[1], -q[2], -q[3]) if q[0] < 0.0 else tuple(q)


def q_body_z(q) -> tuple[float, float, float]:
    """Third column of R(q): the body z axis in world coordinates."""
    w, x, y, z = q
    return (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))


def q_world_z_in_body(q) -> tuple[float, float, float]:
    """Third row of R(q): the world z axis in body coordinates."""
    w, x, y, z = q
    return (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


def cross(a, b) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def qbetween(a, b) -> tuple[float, float, float, float]:
    """Shortest-arc rotation turning unit vector ``a`` onto unit vector ``b``."""
    c = cross(a, b)
    dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if dot < -1.0 + 1e-9:
        helper = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
        axis = cross(a, helper)
        n = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
        return (0.0, axis[0] / n, axis[1] / n, axis[2] / n)
    w = 1.0 + dot
    n = math.sqrt(w * w + c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    return (w / n, c[0] / n, c[1] / n, c[2] / n)


def mat_to_q(r) -> tuple[float, float, float, float]:
    """Unit quaternion (w ≥ 0) of a rotation matrix given as rows (Shepperd's method)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = math.sqrt(trace + 1.0) * 2.0
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif r00 > r11 and r00 > r22:
        s = math.sqrt(1.0 + r00 - r11 - r22) * 2.0
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif r11 > r22:
        s = math.sqrt(1.0 + r11 - r00 - r22) * 2.0
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = math.sqrt(1.0 + r22 - r00 - r11) * 2.0
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    n = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    return qcanon((q[0] / n, q[1] / n, q[2] / n, q[3] / n))


def q_to_mat(q) -> tuple[tuple[float, float, float], ...]:
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


# numpy API


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` (apply ``b`` first, then ``a``)."""
    return np.array(qmul(_floats(a), _floats(b)))


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion."""
    return np.array(qconj(_floats(q)))


def quat_normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / math.sqrt(float(np.dot(q, q)))


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """The same rotation with a non-negative scalar part."""
    return np.array(qcanon(_floats(q)))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (body → world)."""
    return np.array(q_to_mat(_floats(q)))


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w ≥ 0) of a rotation matrix."""
    rows = r.tolist() if isinstance(r, np.ndarray) else r
    return np.array(mat_to_q(rows))


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector ``v`` from body to world: ``R(q) @ v``."""
    return quat_to_matrix(q) @ np.asarray(v, dtype=float)


def quat_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Quaternion from ZYX Euler angles."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def euler_from_quat(q: np.ndarray) -> tuple[float, float, float]:
    """ZYX Euler angles ``(roll, pitch, yaw)`` of a unit quaternion, in radians."""
    w, x, y, z = _floats(q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def yaw_from_quat(q: np.ndarray) -> float:
    """Heading in radians (0 = north, +π/2 = east)."""
    w, x, y, z = _floats(q)
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quat_from_axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    ax, ay, az = _floats(axis)
    n = math.sqrt(ax * ax + ay * ay + az * az)
    if n < 1e-12:
        return IDENTITY_QUAT.copy()
    s = math.sin(angle_rad / 2) / n
    return np.array([math.cos(angle_rad / 2), ax * s, ay * s, az * s])


def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation that turns direction ``a`` onto direction ``b``."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return np.array(qbetween((a / np.linalg.norm(a)).tolist(), (b / np.linalg.norm(b)).tolist()))


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle into [-π, π)."""
    return (angle_rad + math.pi) % (2 * math.pi) - math.pi


def rot_z(yaw_rad: float) -> np.ndarray:
    """Rotation about the down axis by ``yaw_rad`` (heading-frame → NED)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def constrain_xy(v0: Sequence[float], v1: Sequence[float], max_norm: float) -> tuple[float, float]:
    """``v0 + v1`` limited to ``max_norm``, keeping as much of ``v0`` as possible (PX4's
    ControlMath::constrainXY, where ``v0`` is the position term, which has priority over the
    feed-forward ``v1``)."""
    tx, ty = v0[0] + v1[0], v0[1] + v1[1]
    if math.hypot(tx, ty) <= max_norm:
        return tx, ty
    n0 = math.hypot(v0[0], v0[1])
    if n0 >= max_norm:
        return v0[0] / n0 * max_norm, v0[1] / n0 * max_norm
    n1 = math.hypot(v1[0], v1[1])
    if math.hypot(v1[0] - v0[0], v1[1] - v0[1]) < 1e-3 or n1 < 1e-9:
        return (v0[0] / n0 * max_norm, v0[1] / n0 * max_norm) if n0 > 1e-9 else (tx, ty)
    ux, uy = v1[0] / n1, v1[1] / n1
    if n0 < 1e-3:
        return ux * max_norm, uy * max_norm
    m = ux * v0[0] + uy * v0[1]
    c = n0 * n0 - max_norm * max_norm
    s = -m + math.sqrt(m * m - c)
    return v0[0] + ux * s, v0[1] + uy * s
