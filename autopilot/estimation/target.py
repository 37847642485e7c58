"""Target tracking: a constant-velocity Kalman filter (filterpy) on the target's position in
world NED.

* Each measurement is applied at its capture time: the filter predicts to that time, so the
  estimate carries no camera or processing latency; :meth:`TargetFilter.estimate` extrapolates
  to "now" for the controller.
* Outliers are gated on the Mahalanobis distance of the innovation (χ², 3 degrees of freedom).
* An estimate has an age (time since the last accepted measurement); past ``stale_after_s`` the
  track is stale and the next measurement starts a new one, whatever its distance.
* ``restart_after`` consecutive rejected measurements that agree with one another mean the
  filter, not the measurements, is wrong (the target manoeuvred beyond the model): the track
  restarts from them, with their velocity.
* A track is *confirmed* once ``confirm_after`` measurements have updated it; a lone false
  detection starts a track that never gets there.

Data flow: detections (camera frame) + the vehicle pose at capture time → world-frame position
measurements → this filter → :class:`TargetEstimate` for behaviours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from filterpy.kalman import KalmanFilter

from autopilot.estimation.pose_history import Pose
from drivers.base import CameraInfo
from drivers.geometry import quat_to_matrix


@dataclass(frozen=True, slots=True)
class TargetFilterSettings:
    accel_noise_m_s2: float  # white-acceleration process noise (target manoeuvres)
    gate_chi2: float  # Mahalanobis² gate (3 dof: 16.3 ≈ 99.9 %)
    stale_after_s: float
    initial_velocity_std_m_s: float
    max_extrapolation_s: float  # estimates are not extrapolated further than this
    pixel_noise_px: float  # bearing noise of a detection
    radius_noise_px: float  # apparent-radius noise (drives the range noise)
    restart_after: int = 4  # consecutive consistent rejections that restart the track
    confirm_after: int = 5  # updates before a track is trusted
    #: the vehicle's navigation seen from the filter: its white position noise (added to each
    #: measurement) and its wander (a random walk of the whole frame, m²/s per axis NED, which
    #: a still target then seems to make)
    navigation_noise_m: float = 0.0
    navigation_drift_m2_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True, eq=False)
class PositionMeasurement:
    time_s: float
    position_ned_m: np.ndarray
    covariance: np.ndarray  # 3 × 3


@dataclass(frozen=True, slots=True, eq=False)
class TargetEstimate:
    """The target at ``time_s`` (NED), with its uncertainty and the age of its last update."""

    time_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    covariance: np.ndarray  # 6 × 6, position then velocity
    age_s: float
    stale: bool
    updates: int
    confirmed: bool
    kind: str = "point"  # what is tracked: "point" (a ball), "marker" (with a face), …
    #: for a target with a face (a marker): the horizontal direction its face points (NED
    #: heading, rad), its rate and 1σ; None when it has none or it is unknown
    heading_rad: float | None = None
    heading_rate_rad_s: float = 0.0
    heading_std_rad: float | None = None
    #: its acceleration (NED), for a target whose filter estimates one (a rover's deck)
    acceleration_ned_m_s2: np.ndarray | None = None

    @property
    def position_std_m(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance)[:3])


@dataclass(frozen=True, slots=True)
class UpdateResult:
    accepted: bool
    mahalanobis2: float
    reinitialised: bool


@dataclass
class TargetFilter:
    settings: TargetFilterSettings
    _kf: KalmanFilter | None = field(default=None, init=False)
    _time: float = field(default=-math.inf, init=False)
    _last_update: float = field(default=-math.inf, init=False)
    _updates: int = field(default=0, init=False)
    _rejected: list[PositionMeasurement] = field(default_factory=list, init=False)

    @property
    def initialised(self) -> bool:
        return self._kf is not None

    def is_stale(self, now_s: float) -> bool:
        return self._kf is None or now_s - self._last_update > self.settings.stale_after_s

    def reset(self) -> None:
        self._kf = None
        self._updates = 0

    def shift(self, delta_ned_m: np.ndarray) -> None:
        """The frame the measurements are placed in moved by ``delta_ned_m`` (a camera's
        mount learned anew): the estimate moves with it, instead of rejecting the measurements
        that now sit elsewhere until the track restarts; measurements already rejected move too,
        so a restart from consistent rejections still fires."""
        delta = np.asarray(delta_ned_m, dtype=float)
        if self._kf is None or not np.any(delta):
            return
        self._kf.x[:3] += delta
        self._rejected = [replace(m, position_ned_m=m.position_ned_m + delta)
                          for m in self._rejected]

    def update(self, meas: PositionMeasurement) -> UpdateResult:
        if self.is_stale(meas.time_s):
            self._initialise(meas)
            return UpdateResult(True, 0.0, True)
        if meas.time_s < self._time:
            return UpdateResult(False, math.inf, False)  # older than the state: ignore
        self._predict_to(meas.time_s)
        kf = self._kf
        innovation = meas.position_ned_m - kf.H @ kf.x
        s = kf.H @ kf.P @ kf.H.T + meas.covariance
        d2 = float(innovation @ np.linalg.solve(s, innovation))
        if d2 > self.settings.gate_chi2:
            self._rejected.append(meas)
            if len(self._rejected) >= self.settings.restart_after and self._consistent():
                self._restart()
                return UpdateResult(True, d2, True)
            return UpdateResult(False, d2, False)
        self._rejected.clear()
        kf.update(meas.position_ned_m, R=meas.covariance)
        self._last_update = meas.time_s
        self._updates += 1
        return UpdateResult(True, d2, False)

    def estimate(self, now_s: float) -> TargetEstimate | None:
        """The estimate extrapolated to ``now_s`` (at most ``max_extrapolation_s`` past the last
        update); None before the first measurement."""
        kf = self._kf
        if kf is None:
            return None
        horizon = min(now_s, self._last_update + self.settings.max_extrapolation_s)
        dt = max(0.0, horizon - self._time)
        f, q = self._transition(dt)
        x = f @ kf.x
        p = f @ kf.P @ f.T + q
        return TargetEstimate(
            time_s=now_s,
            position_ned_m=x[:3].copy(),
            velocity_ned_m_s=x[3:].copy(),
            covariance=p,
            age_s=now_s - self._last_update,
            stale=self.is_stale(now_s),
            updates=self._updates,
            confirmed=self._updates >= self.settings.confirm_after,
        )

    # -- internals --------------------------------------------------------------------------

    def _consistent(self) -> bool:
        """Do the rejected measurements lie on one straight, constant-speed track?"""
        t, p, v = self._line_fit(self._rejected[-self.settings.restart_after:])
        for m in self._rejected[-self.settings.restart_after:]:
            residual = m.position_ned_m - (p + v * (m.time_s - t))
            if residual @ np.linalg.solve(m.covariance, residual) > self.settings.gate_chi2:
                return False
        return True

    @staticmethod
    def _line_fit(ms: list[PositionMeasurement]) -> tuple[float, np.ndarray, np.ndarray]:
        """Least-squares position (at the last time) and velocity through measurements."""
        times = np.array([m.time_s for m in ms])
        pos = np.array([m.position_ned_m for m in ms])
        t_last = times[-1]
        a = np.column_stack((np.ones(len(ms)), times - t_last))
        coef = np.linalg.lstsq(a, pos, rcond=None)[0]
        return t_last, coef[0], coef[1]

    def _restart(self) -> None:
        recent = self._rejected[-self.settings.restart_after:]
        t, p, v = self._line_fit(recent)
        self._initialise(PositionMeasurement(t, p, recent[-1].covariance))
        self._kf.x[3:] = v
        span = max(recent[-1].time_s - recent[0].time_s, 1e-3)
        pos_std = float(np.sqrt(np.max(np.diag(recent[-1].covariance))))
        self._kf.P[3:, 3:] = np.eye(3) * (2.0 * pos_std / span) ** 2
        self._updates = len(recent)  # these measurements agree: the new track is as good
        self._rejected.clear()

    def _initialise(self, meas: PositionMeasurement) -> None:
        kf = KalmanFilter(dim_x=6, dim_z=3)
        kf.x = np.concatenate((meas.position_ned_m, np.zeros(3)))
        kf.P = np.zeros((6, 6))
        kf.P[:3, :3] = meas.covariance
        kf.P[3:, 3:] = np.eye(3) * self.settings.initial_velocity_std_m_s ** 2
        kf.H = np.hstack((np.eye(3), np.zeros((3, 3))))
        self._kf = kf
        self._time = meas.time_s
        self._last_update = meas.time_s
        self._updates = 1
        self._rejected = []

    def _predict_to(self, time_s: float) -> None:
        dt = time_s - self._time
        if dt > 0.0:
            f, q = self._transition(dt)
            self._kf.predict(F=f, Q=q)
            self._time = time_s

    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        f = np.eye(6)
        f[:3, 3:] = np.eye(3) * dt
        q = process_noise(dt, self.settings.accel_noise_m_s2)
        drift = self.settings.navigation_drift_m2_s
        if any(drift):
            q[:3, :3] += np.diag(drift) * dt
        return f, q


_EYE3 = np.eye(3)


def process_noise(dt: float, accel_std_m_s2: float) -> np.ndarray:
    """Discrete white-noise-acceleration covariance for state (x, y, z, vx, vy, vz): what
    filterpy's ``Q_discrete_white_noise(dim=2, dt, var, block_size=3, order_by_dim=False)``
    returns, in closed form (this runs several times per frame)."""
    var = accel_std_m_s2 * accel_std_m_s2
    q = np.empty((6, 6))
    q[:3, :3] = _EYE3 * (0.25 * dt ** 4 * var)
    q[:3, 3:] = q[3:, :3] = _EYE3 * (0.5 * dt ** 3 * var)
    q[3:, 3:] = _EYE3 * (dt * dt * var)
    return q


def camera_measurement(position_cam_m: np.ndarray, range_m: float, radius_px: float,
                       camera: CameraInfo, pose: Pose, settings: TargetFilterSettings,
                       time_s: float, noise_scale: float = 1.0) -> PositionMeasurement:
    """A target position in the optical frame → world NED, with its covariance.

    Bearing noise is ``pixel_noise_px`` across the line of sight; range noise follows from the
    apparent-radius noise (δr/r = δR_px/R_px). Both are expressed in the camera frame and rotated
    into NED with the vehicle's attitude at capture time.
    """
    r_world_body = quat_to_matrix(pose.attitude_q)
    r_world_cam = r_world_body @ camera.rotation_body_cam
    position = pose.position_ned_m + r_world_body @ camera.position_body_m + \
        r_world_cam @ position_cam_m
    f = camera.intrinsics.fx
    lateral = range_m * settings.pixel_noise_px / f
    along = range_m * settings.radius_noise_px / max(radius_px, 1.0)
    # the optical frame's z is (almost) the line of sight to a centred target
    los = position_cam_m / np.linalg.norm(position_cam_m)
    cov_cam = lateral ** 2 * np.eye(3) + (along ** 2 - lateral ** 2) * np.outer(los, los)
    cov = r_world_cam @ cov_cam @ r_world_cam.T * noise_scale ** 2
    if settings.navigation_noise_m:
        cov = cov + settings.navigation_noise_m ** 2 * _EYE3
    return PositionMeasurement(time_s, position, cov)


def navigation_drift_rate(std_m: float, time_constant_s: float, smoothing_s: float,
                          window_s: float) -> float:
    """The random-walk rate (m²/s) that stands, in a target filter, for the navigation error's
    wander: the mean squared change of that error over ``window_s`` (the filter's memory),
    per second of it.

    The error is a Gauss–Markov process (σ ``std_m``, correlation ``time_constant_s``) seen
    through the EKF output's first-order lag (``smoothing_s``, 0: none) with its σ kept, as
    the simulator models PX4's. Unsmoothed, its change over W is 2σ²(1 − e^(−W/τ)) ≈ 2σ²W/τ, a
    random walk of 2σ²/τ; smoothed, it moves like a slow velocity (≈ σ/√(τT)) and changes over
    one second several times less than that random walk says (σ 0.5 m, τ 100 s, T 3 s: 6.7×).
    """
    if std_m <= 0.0:
        return 0.0
    tau, lag, w = time_constant_s, smoothing_s, window_s
    if lag <= 0.0:
        correlation = math.exp(-w / tau)
    elif abs(tau - lag) < 1e-9 * tau:
        correlation = (1.0 + w / tau) * math.exp(-w / tau)
    else:
        correlation = (tau * math.exp(-w / tau) - lag * math.exp(-w / lag)) / (tau - lag)
    return 2.0 * std_m * std_m * (1.0 - correlation) / w


@dataclass(frozen=True, slots=True)
class NavigationUncertainty:
    """The vehicle's own pose errors (1σ): they drift slowly, so averaging many frames of a
    target does not reduce what they add to its world position."""

    position_std_m: float = 0.0
    attitude_std_rad: float = 0.0  # roll and pitch
    yaw_std_rad: float = 0.0
    height_std_m: float | None = None  # None: as position_std_m


def navigation_covariance(relative_ned_m: np.ndarray, nav: NavigationUncertainty) -> np.ndarray:
    """Covariance (NED, 3 × 3) that the vehicle's pose errors add to a target at
    ``relative_ned_m`` from it: its position error, plus the target's lever arm turned by the
    attitude errors (a yaw error moves it horizontally across the line of sight; roll and pitch
    errors, across the line of sight in any direction)."""
    height = nav.position_std_m if nav.height_std_m is None else nav.height_std_m
    cov = np.diag([nav.position_std_m ** 2, nav.position_std_m ** 2, height ** 2])
    rel = np.asarray(relative_ned_m, dtype=float)
    distance = float(np.linalg.norm(rel))
    if distance > 1e-6 and nav.attitude_std_rad > 0.0:
        los = rel / distance
        cov += (distance * nav.attitude_std_rad) ** 2 * (np.eye(3) - np.outer(los, los))
    horizontal = math.hypot(rel[0], rel[1])
    if horizontal > 1e-6 and nav.yaw_std_rad > 0.0:
        across = np.array([-rel[1], rel[0], 0.0]) / horizontal
        cov += (horizontal * nav.yaw_std_rad) ** 2 * np.outer(across, across)
    return cov


def with_navigation(estimate: TargetEstimate, vehicle_position_ned_m: np.ndarray,
                    nav: NavigationUncertainty) -> TargetEstimate:
    """``estimate`` with the vehicle's navigation errors added to its position covariance: the
    uncertainty of the target's world position as the autopilot's frame knows it (the filter
    alone only knows the scatter of its measurements)."""
    cov = estimate.covariance.copy()
    cov[:3, :3] += navigation_covariance(
        estimate.position_ned_m - np.asarray(vehicle_position_ned_m, dtype=float), nav)
    return replace(estimate, covariance=cov)
