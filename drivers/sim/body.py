"""The simulated airframe in MuJoCo, as the simulator's other parts need it: its true state in
the local NED / body FRD frames (MuJoCo is ENU / FLU: converted here only), its rotors (each
speed following its command with a first-order lag, thrust = T_max·(ω/ω_max)²), the external
force on it, and MuJoCo's instability warnings turned into :class:`SimulationDiverged`.
Ground truth: for the sensor models, scoring and tests, never for the vehicle interface."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from drivers.base import ConnectionLost
from drivers.sim.camera_effects import VehicleMotion
from drivers.sim.frames import q_enu_flu_to_ned_frd, quat_ned_frd_to_enu_flu
from drivers.sim.model import BuiltModel

_INSTABILITY_WARNINGS = np.array([
    int(mujoco.mjtWarning.mjWARN_BADQPOS),
    int(mujoco.mjtWarning.mjWARN_BADQVEL),
    int(mujoco.mjtWarning.mjWARN_BADQACC),
    int(mujoco.mjtWarning.mjWARN_BADCTRL),
])


class SimulationDiverged(ConnectionLost):
    """The physics went unstable (NaN or huge values); the simulated vehicle is gone."""


class VehicleBody:
    def __init__(self, built: BuiltModel, data: mujoco.MjData, dt_s: float,
                 motor_time_constant_s: float) -> None:
        model = built.model
        self.model, self.data = model, data
        self.frame = built.frame
        self.body_id = built.body_id
        self._act = built.actuator_ids
        self._qpos0 = model.jnt_qposadr[model.body_jntadr[self.body_id]]
        self._qvel0 = model.jnt_dofadr[model.body_jntadr[self.body_id]]
        self._origin = tuple(self.frame.origin_enu_m.tolist())
        n = len(self._act)
        self.thrust_max_n = built.airframe.thrust_max_n
        self.weight_n = built.airframe.mass_kg * 9.80665
        self._motor_alpha = 1.0 - math.exp(-dt_s / motor_time_constant_s)
        self._omega = np.zeros(n)  # rotor speed as a fraction of full speed
        self._omega_cmd = np.zeros(n)
        self.rotor_thrust_n = np.zeros(n)
        self._warnings0 = data.warning.number[_INSTABILITY_WARNINGS].copy()

    @property
    def rotors(self) -> int:
        return len(self._act)

    # -- true state -----------------------------------------------------------------------

    def attitude(self) -> tuple[tuple[float, ...], list[float]]:
        """The true attitude (NED→FRD quaternion) and body rates (FRD, rad/s)."""
        qw, qx, qy, qz = self.data.qpos[self._qpos0 + 3:self._qpos0 + 7].tolist()
        wx, wy, wz = self.data.qvel[self._qvel0 + 3:self._qvel0 + 6].tolist()
        # free joint: angular velocity is in body (FLU) axes
        return q_enu_flu_to_ned_frd((qw, qx, qy, qz)), [wx, -wy, -wz]

    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """True position and velocity (local NED), attitude and body rates."""
        d = self.data
        x, y, z = d.qpos[self._qpos0:self._qpos0 + 3].tolist()
        vx, vy, vz = d.qvel[self._qvel0:self._qvel0 + 3].tolist()
        q, rates = self.attitude()
        ox, oy, oz = self._origin
        return (np.array((y - oy, x - ox, oz - z)), np.array((vy, vx, -vz)), np.array(q),
                np.array(rates))

    def motion(self) -> VehicleMotion:
        """The true motion now (motion blur and rolling shutter of the cameras)."""
        return VehicleMotion(*self.state())

    def set_pose(self, position_ned_m: Sequence[float], attitude_q: Sequence[float]) -> None:
        """Teleport the airframe (at rest) to a pose in the local NED frame."""
        qp, qv = self._qpos0, self._qvel0
        self.data.qpos[qp:qp + 3] = self.frame.to_enu(np.asarray(position_ned_m, dtype=float))
        self.data.qpos[qp + 3:qp + 7] = quat_ned_frd_to_enu_flu(np.asarray(attitude_q,
                                                                           dtype=float))
        self.data.qvel[qv:qv + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def set_motion(self, velocity_ned_m_s: Sequence[float],
                   rates_frd_rad_s: Sequence[float]) -> None:
        """Set the airframe's true velocity (local NED) and body rates (FRD)."""
        vn, ve, vd = (float(v) for v in velocity_ned_m_s)
        p, q, r = (float(v) for v in rates_frd_rad_s)
        self.data.qvel[self._qvel0:self._qvel0 + 6] = (ve, vn, -vd, p, -q, -r)  # ENU, FLU

    # -- rotors and forces --------------------------------------------------------------------

    def spin(self, motor_scale: np.ndarray) -> None:
        """One physics step of the rotors: speeds towards their commands, thrust to MuJoCo
        (``motor_scale``: each motor's share of the thrust it should give)."""
        omega = self._omega
        omega += self._motor_alpha * (self._omega_cmd - omega)
        self.rotor_thrust_n = thrust = self.thrust_max_n * omega * omega * motor_scale
        self.data.ctrl[self._act] = thrust

    def command_thrust(self, thrust_n: Sequence[float], time_s: float) -> None:
        """The flight stack's thrust commands (N per rotor) as rotor speed commands."""
        for value in thrust_n:
            if not math.isfinite(value):
                raise SimulationDiverged(f"flight stack produced non-finite thrust at "
                                         f"t={time_s:.3f} s: {thrust_n}")
        self._omega_cmd = np.sqrt(np.clip(np.array(thrust_n) / self.thrust_max_n, 0.0, 1.0))

    def push(self, force_ned_n: np.ndarray) -> None:
        """The external force on the body (wind and drag), held until the next call."""
        f = force_ned_n
        self.data.xfrc_applied[self.body_id, :3] = (f[1], f[0], -f[2])  # NED → ENU

    def check_stability(self, time_s: float, flight) -> None:
        """Raise :class:`SimulationDiverged` if MuJoCo warned of instability (``flight``:
        the flight stack, whose mode the message names)."""
        counts = self.data.warning.number[_INSTABILITY_WARNINGS]
        if (counts != self._warnings0).any():
            bad = _INSTABILITY_WARNINGS[counts != self._warnings0]
            names = ", ".join(mujoco.mjtWarning(int(w)).name.removeprefix("mjWARN_") for w in bad)
            raise SimulationDiverged(
                f"MuJoCo physics diverged ({names}) at t={time_s:.3f} s; last rotor "
                f"thrust {np.round(self.rotor_thrust_n, 2).tolist()} N, mode {flight.mode.value}"
            )
