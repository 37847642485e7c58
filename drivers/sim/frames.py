"""Frame conversions at the simulator boundary, and nowhere else.

MuJoCo's world is ENU (x east, y north, z up) and the airframe's body frame is FLU (x forward,
y left, z up). PX4, and everything above the simulator, works in NED / FRD. Both conversion
matrices are proper rotations (180° turns) and their own inverses.
"""

from __future__ import annotations

import numpy as np

from drivers.geometry import matrix_to_quat, qmul, quat_multiply

#: v_ned = NED_FROM_ENU @ v_enu (swap x/y, flip z). Also ENU_FROM_NED.
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
ENU_FROM_NED = NED_FROM_ENU
#: v_frd = FRD_FROM_FLU @ v_flu (flip y and z). Also FLU_FROM_FRD.
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])
FLU_FROM_FRD = FRD_FROM_FLU

_Q_NED_ENU = matrix_to_quat(NED_FROM_ENU)
_Q_FLU_FRD = matrix_to_quat(FLU_FROM_FRD)


def enu_to_ned(v_enu: np.ndarray) -> np.ndarray:
    v = np.asarray(v_enu, dtype=float)
    return np.array([v[1], v[0], -v[2]])


def ned_to_enu(v_ned: np.ndarray) -> np.ndarray:
    v = np.asarray(v_ned, dtype=float)
    return np.array([v[1], v[0], -v[2]])


def flu_to_frd(v_flu: np.ndarray) -> np.ndarray:
    v = np.asarray(v_flu, dtype=float)
    return np.array([v[0], -v[1], -v[2]])


frd_to_flu = flu_to_frd


def quat_enu_flu_to_ned_frd(q_enu_flu: np.ndarray) -> np.ndarray:
    """Attitude of an FLU body in ENU → attitude of the FRD body in NED (both ``(w,x,y,z)``)."""
    return quat_multiply(quat_multiply(_Q_NED_ENU, q_enu_flu), _Q_FLU_FRD)


def quat_ned_frd_to_enu_flu(q_ned_frd: np.ndarray) -> np.ndarray:
    """Inverse of :func:`quat_enu_flu_to_ned_frd`."""
    return quat_multiply(quat_multiply(_Q_NED_ENU, q_ned_frd), _Q_FLU_FRD)


_QNE = tuple(_Q_NED_ENU.tolist())
_QFF = tuple(_Q_FLU_FRD.tolist())


def q_enu_flu_to_ned_frd(q_enu_flu) -> tuple[float, float, float, float]:
    """Float-kernel version of :func:`quat_enu_flu_to_ned_frd` (tuples in and out)."""
    return qmul(qmul(_QNE, q_enu_flu), _QFF)
