"""Seed 004's fused filter (its chapter 4, "kf_tag_uwb"), as a baseline for ``autopilot bench
landing --strategy seed004``: ONE filterpy Kalman filter fed by PX4's local position, a UWB
position pre-solved in the rover's frame, the AprilTag, the rover's compass and the laser
altimeter, updated and predicted on the seed's fixed-rate timers.

What the seed's text fixes (quoted in ``tests/unit/test_seed004_filter.py``):

* the measurements and their models — ``z_UWB`` = the UAV's (x, y) relative to the rover in NED,
  the UWB tag's position in the rover frame rotated by the rover's yaw (eqs. 4.11–4.13);
  ``z_PX4`` = the UAV's (x, y, z) in the local NED frame (4.14); ``z_UGVyaw`` = ψ_UGV (4.15);
  the AprilTag's relative position; the laser altimeter's "relative altitude of the drone";
* ``R_uwb = 2`` and ``R_tag = 0.5`` (section 4.3), every R diagonal, "defined via a single
  value" (a ROS parameter);
* the update step on a 10 Hz timer, using each source only "if it has received a new
  measurement since the last update step", in Algorithm 8's order (UWB, PX4, compass,
  altimeter, tag), UWB and tag only when requested (``use_uwb`` / ``use_marker``);
* the prediction step on its own timer, whose frequency the update timer's is "twice" (so
  5 Hz), publishing the estimate in the same callback;
* ``rover_position``: "requested automatically by the client if the usage of the ultra-wide
  band is set to false" — a rough external position of the rover (here the rover's own
  report) that the tag then corrects.

What it leaves open, chosen here and documented in ``config.yaml`` (``estimation.seed004``):
the state (it must hold the UAV's position for ``z_PX4`` and the rover's for the relative
measurements: both, with their velocities — the filter "produces the relative position and
velocity" — and the rover's yaw, constant-velocity), ``R_px4``, ``R_compass``,
``R_range``, Q and the initial covariance. The laser altimeter is fused as the height above
the deck wherever the drone is (the seed has no notion of being beside the deck).

A plain synchronous class: feed it with the ``add_*`` methods in time order; the timers run
as time passes (:meth:`advance`); :meth:`estimate` is the last published estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter

from autopilot.estimation.relative_types import DeckGeometry, RelativeEstimate

N = 13
P_D, V_D, P_R, V_R, PSI = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), 12
#: Algorithm 8's order of the update step
ORDER = ("uwb", "px4", "compass", "range", "tag")


@dataclass(frozen=True, slots=True)
class Seed004Settings:
    update_rate_hz: float = 10.0  # "The following update step is requested every 10 Hz."
    #: "The frequency of such timer [the update's] is twice the set frequency of the
    #: prediction step."
    predict_rate_hz: float = 5.0
    r_uwb: float = 2.0  # "R_uwb = 2m"
    r_tag: float = 0.5  # "R_tag = 0.5m"
    r_px4: float = 0.01  # not given by the seed
    r_compass: float = 0.01  # not given (rad²)
    r_range: float = 0.01  # not given (m²)
    #: Q: white acceleration (m²/s⁴) of the UAV (under PX4's position control) and of the
    #: rover; not given
    drone_accel_var: float = 16.0
    rover_accel_var: float = 0.25
    yaw_rate_var: float = 0.01  # Q on ψ (rad²/s per second); not given
    initial_rover_std_m: float = 3.0  # the rough rover_position's σ; not given
    initial_velocity_std_m_s: float = 2.0


class Seed004Filter:
    """See the module's notes."""

    def __init__(self, settings: Seed004Settings, geometry: DeckGeometry, *,
                 use_uwb: bool = True, use_marker: bool = True) -> None:
        self.s = settings
        self.use_uwb, self.use_marker = use_uwb, use_marker
        self._anchors = np.array(geometry.anchors_frd_m, dtype=float).reshape(-1, 3) \
            + np.array([0.0, 0.0, geometry.deck_height_m])  # from the deck's top centre
        self._tag_lever = np.array(geometry.tag_frd_m, dtype=float)
        self.kf: KalmanFilter | None = None
        self._pending: dict[str, tuple[float, np.ndarray]] = {}
        self._rover_guess: np.ndarray | None = None  # the rough rover_position
        self._yaw = math.nan  # the newest compass reading (rotates norot_pos, eq. 4.12)
        self._uwb_guess = np.array([0.0, 0.0, -3.0])
        self._t0 = math.nan  # when the timers started
        self._n_update = self._n_predict = 0  # ticks run (their times: t0 + n / rate)
        self._now = -math.inf
        self._published: RelativeEstimate | None = None
        self.updates = dict.fromkeys(ORDER, 0)
        self.last_update_s = dict.fromkeys(ORDER, -math.inf)
        self.predictions = 0

    # -- feeding (each call first runs the timers up to its time) ---------------------------

    def add_px4(self, time_s: float, position_ned_m) -> None:
        self._measure("px4", time_s, np.asarray(position_ned_m, dtype=float))

    def add_compass(self, time_s: float, heading_rad: float) -> None:
        if math.isfinite(heading_rad):
            self._yaw = float(heading_rad)
            self._measure("compass", time_s, np.array([heading_rad]))

    def add_range(self, time_s: float, range_m: float) -> None:
        if math.isfinite(range_m):
            self._measure("range", time_s, np.array([range_m]))

    def add_tag(self, time_s: float, relative_m) -> None:
        """The AprilTag estimate: the UAV relative to the deck's centre, NED."""
        if self.use_marker:
            self._measure("tag", time_s, np.asarray(relative_m, dtype=float))

    def add_rover_position(self, position_ned_m) -> None:
        """The rough rover_position (the deck's top centre, local NED) the client supplies."""
        if self._rover_guess is None:
            self._rover_guess = np.asarray(position_ned_m, dtype=float).copy()

    def add_uwb(self, time_s: float, anchor_ids, ranges_m, r_world_body: np.ndarray) -> None:
        """UWB ranges, pre-solved into the UAV's tag position in the rover's frame
        (``norot_pos``), rotated into NED with the rover's yaw (eqs. 4.11–4.12); the filter
        takes its (x, y) (eq. 4.13)."""
        if not self.use_uwb or not math.isfinite(self._yaw) or len(anchor_ids) < 3:
            return
        norot = self._multilaterate(anchor_ids, ranges_m)
        if norot is None:
            return
        relative = self.rotation(self._yaw) @ norot - r_world_body @ self._tag_lever
        self._measure("uwb", time_s, relative[:2])

    @staticmethod
    def rotation(psi: float) -> np.ndarray:
        """Eq. 4.11: R_UGV^NED."""
        c, s = math.cos(psi), math.sin(psi)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def _multilaterate(self, anchor_ids, ranges_m) -> np.ndarray | None:
        from scipy.optimize import least_squares

        ids = [i for i in anchor_ids if 0 <= i < len(self._anchors)]
        if len(ids) < 3:
            return None
        anchors = self._anchors[ids]
        ranges = np.asarray([r for i, r in zip(anchor_ids, ranges_m, strict=True)
                             if 0 <= i < len(self._anchors)], dtype=float)
        fit = least_squares(lambda p: np.linalg.norm(anchors - p, axis=1) - ranges,
                            self._uwb_guess, method="lm")
        if not fit.success:
            return None
        # above the anchors, not the mirror image below them
        self._uwb_guess = fit.x if fit.x[2] < 0.0 else fit.x * np.array([1.0, 1.0, -1.0])
        return self._uwb_guess.copy()

    def _measure(self, source: str, time_s: float, z: np.ndarray) -> None:
        self.advance(time_s)
        self._pending[source] = (time_s, z)  # only the newest since the last update step

    # -- the timers -------------------------------------------------------------------------

    def advance(self, time_s: float) -> None:
        """Run the update (10 Hz) and prediction (5 Hz) timers up to ``time_s``: at a shared
        instant the prediction (and its publishing) first."""
        if not math.isfinite(time_s) or time_s <= self._now:
            return
        if not math.isfinite(self._t0):
            self._t0 = time_s
        eps = 1e-9  # (tick times computed, not accumulated)
        while True:
            t_update = self._t0 + self._n_update / self.s.update_rate_hz
            t_predict = self._t0 + self._n_predict / self.s.predict_rate_hz
            if min(t_update, t_predict) > time_s + eps:
                break
            if t_predict <= t_update + eps:
                self._predict_tick(t_predict)
                self._n_predict += 1
            else:
                self._update_tick(t_update)
                self._n_update += 1
        self._now = time_s

    def _transition(self) -> tuple[np.ndarray, np.ndarray]:
        dt = 1.0 / self.s.predict_rate_hz
        f = np.eye(N)
        f[P_D, V_D] = np.eye(3) * dt
        f[P_R, V_R] = np.eye(3) * dt
        q = np.zeros((N, N))
        for pos, vel, var in ((0, 3, self.s.drone_accel_var), (6, 9, self.s.rover_accel_var)):
            q1 = Q_discrete_white_noise(2, dt=dt, var=var)
            for axis in range(3):
                idx = [pos + axis, vel + axis]
                q[np.ix_(idx, idx)] = q1
        q[PSI, PSI] = self.s.yaw_rate_var * dt
        return f, q

    def _predict_tick(self, t: float) -> None:
        if self.kf is None:
            return
        f, q = self._transition()
        self.kf.predict(F=f, Q=q)
        self.predictions += 1
        self._published = self._relative(t)

    def _update_tick(self, t: float) -> None:
        if self.kf is None and not self._initialise(t):
            return
        kf = self.kf
        for source in ORDER:
            if source not in self._pending:
                continue
            _, z = self._pending.pop(source)
            h, r, z = self._model(source, z)
            kf.update(z.reshape(-1, 1), R=r, H=h)
            self.updates[source] += 1
            self.last_update_s[source] = t

    def _model(self, source: str, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """H, R and z of one source."""
        s = self.s
        if source == "px4":  # eq. 4.14
            h = np.zeros((3, N))
            h[:, P_D] = np.eye(3)
            return h, np.eye(3) * s.r_px4, z
        if source == "uwb":  # eq. 4.13: the horizontal relative position
            h = np.zeros((2, N))
            h[:, 0:2], h[:, 6:8] = np.eye(2), -np.eye(2)
            return h, np.eye(2) * s.r_uwb, z
        if source == "tag":
            h = np.zeros((3, N))
            h[:, P_D], h[:, P_R] = np.eye(3), -np.eye(3)
            return h, np.eye(3) * s.r_tag, z
        if source == "compass":  # eq. 4.15 (the reading unwrapped next to the state's ψ)
            h = np.zeros((1, N))
            h[0, PSI] = 1.0
            psi = float(self.kf.x[PSI, 0])
            return h, np.array([[s.r_compass]]), \
                np.array([psi + math.remainder(float(z[0]) - psi, 2.0 * math.pi)])
        # the altimeter: the height above the deck (deck's z − UAV's z, NED)
        h = np.zeros((1, N))
        h[0, 2], h[0, 8] = -1.0, 1.0
        return h, np.array([[s.r_range]]), z

    def _initialise(self, t: float) -> bool:
        """At the first update step with PX4's position and something placing the rover: a
        UWB position, the tag, or the rough rover_position."""
        if "px4" not in self._pending:
            return False
        drone = self._pending["px4"][1]
        rover = None
        if "uwb" in self._pending:  # its height: the altimeter's, else the rough guess's
            rover = drone.copy() if self._rover_guess is None else self._rover_guess.copy()
            rover[:2] = drone[:2] - self._pending["uwb"][1]
            if "range" in self._pending:
                rover[2] = drone[2] + float(self._pending["range"][1][0])
        elif "tag" in self._pending:
            rover = drone - self._pending["tag"][1]
        elif self._rover_guess is not None:
            rover = self._rover_guess.copy()
        if rover is None:
            return False
        s = self.s
        kf = KalmanFilter(dim_x=N, dim_z=3)
        x = np.zeros(N)
        x[P_D], x[P_R] = drone, rover
        x[PSI] = self._yaw if math.isfinite(self._yaw) else 0.0
        kf.x = x.reshape(N, 1)
        p = np.zeros((N, N))
        p[P_D, P_D] = np.eye(3) * s.r_px4
        p[P_R, P_R] = np.eye(3) * s.initial_rover_std_m ** 2
        p[V_D, V_D] = p[V_R, V_R] = np.eye(3) * s.initial_velocity_std_m_s ** 2
        p[PSI, PSI] = s.r_compass if math.isfinite(self._yaw) else math.pi ** 2
        kf.P = p
        self.kf = kf
        self._published = self._relative(t)
        return True

    # -- reading ----------------------------------------------------------------------------

    def _relative(self, t: float) -> RelativeEstimate:
        x, p = self.kf.x[:, 0], self.kf.P
        j = np.zeros((6, N))
        j[0:3, P_D], j[0:3, P_R] = np.eye(3), -np.eye(3)
        j[3:6, V_D], j[3:6, V_R] = np.eye(3), -np.eye(3)
        last = {"uwb": self.last_update_s["uwb"], "tag": self.last_update_s["tag"],
                "rover": self.last_update_s["compass"], "range": self.last_update_s["range"]}
        return RelativeEstimate(
            time_s=t, position_m=x[P_D] - x[P_R], velocity_m_s=x[V_D] - x[V_R],
            covariance=j @ p @ j.T, heading_rad=math.remainder(float(x[PSI]), 2.0 * math.pi),
            heading_std_rad=math.sqrt(max(float(p[PSI, PSI]), 0.0)), yaw_rate_rad_s=0.0,
            bias_m=np.zeros(3), rover_acceleration_m_s2=np.zeros(3), last_update_s=last)

    def estimate(self, time_s: float | None = None) -> RelativeEstimate | None:
        """The last published estimate (at the newest prediction step up to ``time_s``): the
        landing action reads what the filter node last published."""
        if time_s is not None:
            self.advance(time_s)
        return self._published

    @property
    def rover_position_ned_m(self) -> np.ndarray | None:
        return None if self.kf is None else self.kf.x[P_R, 0].copy()
