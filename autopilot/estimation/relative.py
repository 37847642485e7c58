"""The drone relative to a moving rover's deck: a multi-sensor Kalman filter (filterpy), after
seed 004's, with each sensor's own model, gating, and delayed measurements fused at their
capture time.

**State** (14): ``r`` — the drone's body origin relative to the deck's top centre (NED, 3);
``v`` — their relative velocity (3); ``b`` — the offset between the rover's reported position
and the drone's own (two GNSS errors; 3); ``ψ`` — the rover's heading; ``ω`` — its turn rate;
``a`` — the rover's horizontal acceleration (2: braking, pulling away, turning), which the
controller feeds forward; ``β`` — its compass's bias (a compass is off by a few degrees for a
long time, and through the UWB anchors' geometry a few degrees of heading are tens of
centimetres of position when the drone is high above them).

**Motion.** ``r' = v``, ``v' = a_drone − a``; the drone's own velocity changes (its telemetry,
50 Hz) enter ``v`` as a known input, so what is left is the rover's acceleration — a
Gauss–Markov state driven by jerk (``jerk_noise_m_s3``) — plus a little white acceleration
(``accel_noise_m_s2``) and the noise of those changes; ``b`` is a slow Gauss–Markov process;
``ψ' = ω`` with a random walk on ``ω``.

**Measurements**, each with its own noise and gate:

* UWB ranges, fused one range at a time (an EKF on the range itself, not a pre-solved
  position): ``|r + R_body·tag − R(ψ)·anchor|``; a non-line-of-sight range (only ever longer)
  fails its gate;
* the deck's tag seen by the down camera: ``r`` from the detection and the drone's attitude at
  capture time (noise growing with range), and ``ψ`` from the tag's top;
* the rangefinder: height above the deck while surely over it, above the ground beside it while
  surely not, nothing in between;
* the rover's own reports: its velocity (relative velocity with the drone's at the same time),
  its compass heading (``ψ + β``), its course over the ground while it drives (a wheeled
  rover goes where it points, or the opposite way when it reverses: ``ψ``, without the
  compass's bias), and its position — the rough fallback — which observes ``r + b``.

**Delays.** Every measurement carries its capture time. The filter keeps the last
``history_s`` of inputs and measurements with its state after each; a measurement older than
the newest is inserted in time order and everything after it is replayed, so a UWB range that
arrives 30 ms late or a rover report 150 ms late is fused where it belongs. Older than the
history: dropped (counted).

``use_uwb`` / ``use_tag`` (seed 004's per-landing ``use_uwb`` / ``use_marker``) switch sources
off; the rover's reports are always used (without UWB and tag they are all there is).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from autopilot.estimation.delayed import DelayedFusion
from autopilot.estimation.relative_model import A_, B_, BETA, PSI, R_, V_, W_, N, transition
from autopilot.estimation.relative_types import (
    DeckGeometry,
    FusionResult,
    RelativeEstimate,
    RelativeSettings,
)
from drivers.geometry import rot_z as _yaw

SOURCES = ("uwb", "tag", "range", "rover")


@dataclass(slots=True)
class _Event:
    time_s: float
    seq: int
    kind: str  # "velocity" or a source
    data: tuple


def _dyaw(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])


@dataclass
class _Snapshot:
    x: np.ndarray
    P: np.ndarray
    time_s: float
    velocity: np.ndarray | None  # the drone's last velocity sample (the input's reference)


class RelativeFilter:
    """See the module's notes. Feed it with the ``add_*`` methods (any order; each with its
    capture time); read it with :meth:`estimate`."""

    def __init__(self, settings: RelativeSettings, geometry: DeckGeometry, *,
                 use_uwb: bool = True, use_tag: bool = True) -> None:
        self.s = settings
        self.geometry = geometry
        self.use_uwb = use_uwb
        self.use_tag = use_tag
        self._kf = KalmanFilter(dim_x=N, dim_z=1)
        self._initialised = False
        self._time = -math.inf
        self._velocity: np.ndarray | None = None  # the drone's, at the last input
        self._history = DelayedFusion(settings.history_s, self._apply, self._snapshot,
                                      self._restore)
        self._seq = itertools.count()
        self.last_update_s = dict.fromkeys(SOURCES, -math.inf)
        self.updates = dict.fromkeys(SOURCES, 0)
        self.dropped_late = 0
        self._anchors = np.array(geometry.anchors_frd_m, dtype=float).reshape(-1, 3) \
            + np.array([0.0, 0.0, geometry.deck_height_m])  # from the deck's top centre
        self._tag = np.array(geometry.tag_frd_m, dtype=float)
        self.results: list[FusionResult] = []  # since the last take_results()

    # -- feeding --------------------------------------------------------------------------

    @property
    def initialised(self) -> bool:
        return self._initialised

    def add_velocity(self, time_s: float, velocity_ned_m_s) -> None:
        """The drone's own velocity estimate (telemetry): the input of the motion model."""
        self._add(_Event(time_s, next(self._seq), "velocity",
                         (np.array(velocity_ned_m_s, dtype=float),)))

    def add_uwb(self, time_s: float, anchor_ids: Sequence[int], ranges_m: Sequence[float],
                drone_attitude_q) -> None:
        if not self.use_uwb or not len(self._anchors):
            return
        from drivers.geometry import quat_to_matrix

        self._add(_Event(time_s, next(self._seq), "uwb",
                         (tuple(anchor_ids), tuple(ranges_m),
                          quat_to_matrix(np.asarray(drone_attitude_q, dtype=float)))))

    def add_tag(self, time_s: float, relative_m, covariance, heading_rad: float | None = None,
                heading_std_rad: float = math.inf) -> None:
        """The deck's tag seen: the drone relative to the deck's centre (NED) and its
        covariance; the heading of the tag's top (the rover's front)."""
        if not self.use_tag:
            return
        self._add(_Event(time_s, next(self._seq), "tag",
                         (np.array(relative_m, dtype=float), np.array(covariance, dtype=float),
                          heading_rad, heading_std_rad)))

    def add_range(self, time_s: float, height_m: float) -> None:
        """The rangefinder's reading projected on the vertical (body origin to the surface)."""
        self._add(_Event(time_s, next(self._seq), "range", (float(height_m),)))

    def add_rover(self, time_s: float, rough_relative_m, relative_velocity_m_s,
                  heading_rad: float, *, velocity_std_m_s: float = math.nan,
                  heading_std_rad: float = math.nan, rover_velocity_m_s=None) -> None:
        """The rover's report: the drone's position minus the deck's as the rover reports it
        (the rough position), the drone's velocity minus the rover's (both at the report's
        capture time), the rover's compass heading, and its own velocity (its course over
        the ground while it drives; None: not used)."""
        self._add(_Event(time_s, next(self._seq), "rover",
                         (np.array(rough_relative_m, dtype=float),
                          np.array(relative_velocity_m_s, dtype=float), float(heading_rad),
                          velocity_std_m_s, heading_std_rad,
                          None if rover_velocity_m_s is None
                          else np.array(rover_velocity_m_s, dtype=float))))

    def take_results(self) -> list[FusionResult]:
        out, self.results = self.results, []
        return out

    # -- reading --------------------------------------------------------------------------

    def estimate(self, time_s: float | None = None) -> RelativeEstimate | None:
        """The state predicted to ``time_s`` (at most ``max_extrapolation_s`` past the newest
        data; default: at the newest data); None before the first rover report or tag."""
        if not self._initialised:
            return None
        kf = self._kf
        t = self._time if time_s is None else min(time_s,
                                                  self._time + self.s.max_extrapolation_s)
        dt = max(0.0, t - self._time)
        f, q = transition(self.s, dt)
        x, p = (f @ kf.x)[:, 0], f @ kf.P @ f.T + q
        return RelativeEstimate(
            time_s=self._time + dt if time_s is None else time_s, position_m=x[R_].copy(),
            velocity_m_s=x[V_].copy(), covariance=p[:6, :6].copy(),
            heading_rad=math.remainder(float(x[PSI]), 2.0 * math.pi),
            heading_std_rad=math.sqrt(max(float(p[PSI, PSI]), 0.0)),
            yaw_rate_rad_s=float(x[W_]), bias_m=x[B_].copy(),
            rover_acceleration_m_s2=np.array([x[11], x[12], 0.0]),
            last_update_s=dict(self.last_update_s))

    # -- time ordering and replay ----------------------------------------------------------

    def _add(self, event: _Event) -> None:
        if math.isfinite(event.time_s) and not self._history.add(event):
            self.dropped_late += 1

    def _snapshot(self) -> _Snapshot:
        kf = self._kf
        return _Snapshot(kf.x.copy(), kf.P.copy(), self._time,
                         None if self._velocity is None else self._velocity.copy(),
                         ) if self._initialised else _Snapshot(
            np.zeros((N, 1)), np.zeros((N, N)), self._time,
            None if self._velocity is None else self._velocity.copy())

    def _restore(self, snap: _Snapshot | None) -> None:
        if snap is None or not np.any(snap.P):
            self._initialised = False
            self._kf.x = np.zeros((N, 1))
            self._kf.P = np.eye(N)
            self._time = -math.inf if snap is None else snap.time_s
            self._velocity = None if snap is None else snap.velocity
            return
        self._initialised = True
        self._kf.x = snap.x.copy()
        self._kf.P = snap.P.copy()
        self._time = snap.time_s
        self._velocity = None if snap.velocity is None else snap.velocity.copy()

    # -- the model ------------------------------------------------------------------------

    def _predict_to(self, time_s: float, dv: np.ndarray | None = None) -> None:
        dt = time_s - self._time
        if dt <= 0.0 and dv is None:
            return
        dt = max(dt, 0.0)
        f, q = transition(self.s, dt)
        kf = self._kf
        if dv is not None:  # the drone's velocity change over the interval: a known input
            b = np.zeros((N, 3))
            b[R_] = np.eye(3) * 0.5 * dt
            b[V_] = np.eye(3)
            var = self.s.drone_velocity_noise_m_s ** 2
            q = q + b @ (np.eye(3) * var) @ b.T
            kf.predict(u=dv.reshape(3, 1), B=b, F=f, Q=q)
        else:
            kf.predict(F=f, Q=q)
        self._time = time_s

    def _apply(self, event: _Event, late: bool) -> None:
        kind = event.kind
        if kind == "velocity":
            (v,) = event.data
            if self._initialised:
                dv = None if self._velocity is None else v - self._velocity
                self._predict_to(event.time_s, dv)
            else:
                self._time = event.time_s
            self._velocity = v
            return
        if not self._initialised:
            if kind == "rover" and not np.all(np.isfinite(event.data[0])):
                return  # a report without a position cannot start the estimate
            if kind in ("rover", "tag"):
                (self._initialise_rover if kind == "rover" else self._initialise_tag)(event)
                self._record(kind, event.time_s, (True, 0.0, 1), late)
            return
        self._predict_to(event.time_s)
        handler = {"uwb": self._fuse_uwb, "tag": self._fuse_tag, "range": self._fuse_range,
                   "rover": self._fuse_rover}[kind]
        result = handler(event)
        if not np.all(np.isfinite(self._kf.x)) or not np.all(np.isfinite(self._kf.P)):
            self._initialised = False  # never fly on a broken estimate: start again
            self._record(kind, event.time_s, (False, math.inf, 0), late)
            return
        if result is not None:
            self._record(kind, event.time_s, result, late)

    def _record(self, source: str, time_s: float, result: tuple[bool, float, int],
                late: bool) -> None:
        accepted, d2, parts = result
        if accepted:
            self.last_update_s[source] = max(self.last_update_s[source], time_s)
        if self._history.replaying:  # already counted and reported when first fused
            return
        self.results.append(FusionResult(source, time_s, accepted, d2, parts, late))
        if accepted:
            self.updates[source] += 1

    # -- initialisation --------------------------------------------------------------------

    def _initialise(self, x: np.ndarray, p: np.ndarray, time_s: float) -> None:
        self._kf.x = x.reshape(N, 1)
        self._kf.P = p
        self._time = time_s
        self._initialised = True

    def _initialise_rover(self, event: _Event) -> None:
        rough, v_rel, heading, v_std, h_std, _ = event.data
        s = self.s
        x = np.zeros(N)
        x[R_] = rough
        x[V_] = np.where(np.isfinite(v_rel), v_rel, 0.0)
        x[PSI] = heading if math.isfinite(heading) else 0.0
        p = np.zeros((N, N))
        bias = np.diag(np.square(np.array(s.rough_position_std_m)))
        white = np.eye(3) * s.rough_white_std_m ** 2
        p[R_, R_] = bias + white
        p[R_, B_] = p[B_, R_] = -bias  # r = z − b
        p[B_, B_] = bias
        p[V_, V_] = np.eye(3) * max(self._rover_velocity_var(v_std),
                                    s.initial_velocity_std_m_s ** 2 * 0.25)
        if math.isfinite(heading):
            p[PSI, PSI] = self._rover_heading_var(h_std) + s.compass_bias_std_rad ** 2
            p[PSI, BETA] = p[BETA, PSI] = -s.compass_bias_std_rad ** 2  # ψ = z − β
        else:  # no compass in the report: the heading is unknown until something tells
            p[PSI, PSI] = math.pi ** 2
        p[BETA, BETA] = s.compass_bias_std_rad ** 2
        p[W_, W_] = s.initial_yaw_rate_std_rad_s ** 2
        p[A_, A_] = np.eye(2) * 1.0
        self._initialise(x, p, event.time_s)

    def _initialise_tag(self, event: _Event) -> None:
        rel, cov, heading, h_std = event.data
        s = self.s
        x = np.zeros(N)
        x[R_] = rel
        p = np.zeros((N, N))
        p[R_, R_] = cov
        p[V_, V_] = np.eye(3) * s.initial_velocity_std_m_s ** 2
        p[B_, B_] = np.diag(np.square(np.array(s.rough_position_std_m)))
        if heading is not None and math.isfinite(heading):
            x[PSI] = heading
            p[PSI, PSI] = h_std ** 2
        else:
            p[PSI, PSI] = math.pi ** 2
        p[W_, W_] = s.initial_yaw_rate_std_rad_s ** 2
        p[A_, A_] = np.eye(2) * 1.0
        p[BETA, BETA] = s.compass_bias_std_rad ** 2
        self._initialise(x, p, event.time_s)

    def _rover_velocity_var(self, reported_std: float) -> float:
        floor = self.s.rover_velocity_noise_m_s
        std = max(floor, reported_std) if math.isfinite(reported_std) else floor
        return std * std + self.s.drone_velocity_noise_m_s ** 2

    def _rover_heading_var(self, reported_std: float) -> float:
        floor = self.s.rover_heading_noise_rad
        std = max(floor, reported_std) if math.isfinite(reported_std) else floor
        return std * std

    # -- updates ---------------------------------------------------------------------------

    def _update(self, z: np.ndarray, h: np.ndarray, r: np.ndarray, hx: np.ndarray,
                gate: float) -> tuple[bool, float]:
        """One (linearised) update: ``z`` measured, ``hx`` predicted, Jacobian ``h``."""
        kf = self._kf
        y = (z - hx).reshape(-1, 1)
        s = h @ kf.P @ h.T + r
        d2 = float((y.T @ np.linalg.solve(s, y))[0, 0])
        if not d2 <= gate:
            return False, d2
        # as filterpy's update, with the innovation linearised about the current state
        kf.update((h @ kf.x + y).reshape(-1, 1), R=r, H=h)
        return True, d2

    def _fuse_uwb(self, event: _Event):
        ids, ranges, r_wb = event.data
        lever = r_wb @ self._tag
        used, worst = 0, 0.0
        var = self.s.uwb_range_noise_m ** 2
        for anchor_id, rho in zip(ids, ranges, strict=True):
            if not 0 <= anchor_id < len(self._anchors):
                continue
            a = self._anchors[anchor_id]
            x = self._kf.x[:, 0]
            psi = float(x[PSI])  # (each range's update moves it: linearise at the newest)
            rot, drot = _yaw(psi), _dyaw(psi)
            d = x[R_] + lever - rot @ a
            dist = float(np.linalg.norm(d))
            if dist < 1e-3:
                continue
            u = d / dist
            h = np.zeros((1, N))
            h[0, R_] = u
            h[0, PSI] = -u @ (drot @ a)
            # a range longer than predicted may be a reflection (non-line-of-sight paths only
            # ever lengthen it): on that side the gate is 2σ, not 3σ
            gate = self.s.uwb_gate_chi2 if rho <= dist else min(self.s.uwb_gate_chi2, 4.0)
            ok, d2 = self._update(np.array([rho]), h, np.array([[var]]), np.array([dist]),
                                  gate)
            worst = max(worst, d2)
            used += ok
        return used > 0, worst, used

    def _fuse_tag(self, event: _Event):
        rel, cov, heading, h_std = event.data
        h = np.zeros((3, N))
        h[:, R_] = np.eye(3)
        x = self._kf.x[:, 0]
        ok, d2 = self._update(rel, h, cov, x[R_], self.s.gate_chi2)
        if ok and heading is not None and math.isfinite(heading) and math.isfinite(h_std):
            hp = np.zeros((1, N))
            hp[0, PSI] = 1.0
            psi = float(self._kf.x[PSI, 0])
            z = psi + math.remainder(heading - psi, 2.0 * math.pi)
            self._update(np.array([z]), hp, np.array([[h_std ** 2]]), np.array([psi]), 16.0)
        return ok, d2, 1

    def over_deck(self, margin_m: float = 0.0) -> bool | None:
        """True: surely over the deck (within ``margin_m`` plus 2σ inside its edges); False:
        surely beside it; None: cannot tell."""
        x, p = self._kf.x[:, 0], self._kf.P
        psi = float(x[PSI])
        local = _yaw(psi).T @ x[R_]
        sigma = math.sqrt(max(p[0, 0], p[1, 1], 0.0))
        half_l, half_w = self.geometry.deck_size_m[0] / 2.0, self.geometry.deck_size_m[1] / 2.0
        m = margin_m + 2.0 * sigma
        if abs(local[0]) < half_l - m and abs(local[1]) < half_w - m:
            return True
        if abs(local[0]) > half_l + m or abs(local[1]) > half_w + m:
            return False
        return None

    def _fuse_range(self, event: _Event):
        (height,) = event.data
        where = self.over_deck(0.05)
        if where is None:
            return None
        x = self._kf.x[:, 0]
        h = np.zeros((1, N))
        h[0, 2] = -1.0
        predicted = -x[2] + (0.0 if where else self.geometry.deck_height_m)
        ok, d2 = self._update(np.array([height]), h,
                              np.array([[self.s.rangefinder_noise_m ** 2]]),
                              np.array([predicted]), self.s.range_gate_chi2)
        return ok, d2, 1

    def _fuse_rover(self, event: _Event):
        rough, v_rel, heading, v_std, h_std, rover_velocity = event.data
        s = self.s
        worst = 0.0
        ok_v = ok_p = False
        course = None
        if rover_velocity is not None and np.all(np.isfinite(rover_velocity[:2])):
            speed = float(np.hypot(*rover_velocity[:2]))
            if speed >= s.course_min_speed_m_s:
                var = self._rover_velocity_var(v_std) / (speed * speed) + s.course_noise_rad ** 2
                course = (math.atan2(rover_velocity[1], rover_velocity[0]), var)
        # velocity (horizontal: the rover's vertical speed is not reported as well)
        h = np.zeros((2, N))
        h[0, 3], h[1, 4] = 1.0, 1.0
        x = self._kf.x[:, 0]
        if np.all(np.isfinite(v_rel[:2])):
            ok_v, d2 = self._update(v_rel[:2], h, np.eye(2) * self._rover_velocity_var(v_std),
                                    x[3:5], s.gate_chi2)
            worst = max(worst, d2)
        if math.isfinite(heading):  # the compass: ψ + β
            hp = np.zeros((1, N))
            hp[0, PSI] = hp[0, BETA] = 1.0
            x = self._kf.x[:, 0]
            predicted = float(x[PSI] + x[BETA])
            z = predicted + math.remainder(heading - predicted, 2.0 * math.pi)
            _, d2 = self._update(np.array([z]), hp, np.array([[self._rover_heading_var(
                h_std)]]), np.array([predicted]), s.gate_chi2)
            worst = max(worst, d2)
        if course is not None:  # its course over the ground: ψ (or ψ + π reversing)
            course_rad, course_var = course
            hp = np.zeros((1, N))
            hp[0, PSI] = 1.0
            psi = float(self._kf.x[PSI, 0])
            if abs(math.remainder(course_rad - psi, 2.0 * math.pi)) > math.pi / 2.0:
                course_rad += math.pi
            z = psi + math.remainder(course_rad - psi, 2.0 * math.pi)
            _, d2 = self._update(np.array([z]), hp, np.array([[course_var]]),
                                 np.array([psi]), s.gate_chi2)
            worst = max(worst, d2)
        # the rough position: r + b
        hr = np.zeros((3, N))
        hr[:, R_] = np.eye(3)
        hr[:, B_] = np.eye(3)
        x = self._kf.x[:, 0]
        if np.all(np.isfinite(rough)):
            ok_p, d2 = self._update(rough, hr, np.eye(3) * s.rough_white_std_m ** 2,
                                    x[R_] + x[B_], s.gate_chi2)
            worst = max(worst, d2)
        return ok_v or ok_p, worst, 1

