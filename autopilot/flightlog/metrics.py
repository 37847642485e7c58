"""End-of-run metrics, computed from the flight log's records (scoring uses ground truth, which
only the simulator provides; the autopilot never saw it).

Follow metrics cover the intervals in which a follow step (``follow_ball``, ``follow_marker``,
…) ran, and mean the same for any followed target (its pipeline, camera, truth body and size
come from the step's plan record):

* ``detection_rate`` — frames in which the target was detected where it truly was (within
  max(3 px, half its apparent radius)) ÷ frames in which the whole target was inside the image;
* ``rms_range_error_m`` — RMS of (true vehicle–target distance − standoff) over the truth
  samples; ``p95_abs_range_error_m`` and ``max_abs_range_error_m`` its worst;
* ``rms_image_error_px`` — RMS distance of the target's true image position from the image
  centre over the frames processed; a target out of the image or behind the camera counts as
  the worst case, the image's half-diagonal; ``p95_image_error_px`` its 95th percentile;
* ``max_lost_s`` — the longest time without a correct detection (from the step's start);
* ``false_detection_rate`` — detections that were not the target ÷ frames processed.

Estimation metrics score the target estimate *the behaviour flew on*: the step's target as the
runtime handed it over at every control tick (``/control/target``), extrapolated to that moment,
coasting stretches included, against the target's true position and velocity then:

* ``rms_position_error_m`` (and per axis, ``p95_``/``max_``), ``rms_velocity_error_m_s`` — over
  the ticks that had a usable (not stale) estimate;
* ``within_2sigma`` — the share of those ticks whose error is inside ±2σ on every axis (a filter
  whose σ is honest has about 0.87 here: 0.954³);
* ``rms_relative_position_error_m`` — the estimate's error relative to the vehicle: the
  estimate minus where the vehicle's navigation put it, against the truth minus the vehicle's
  true position. The estimate lives in the navigation's frame, which is off the true one by
  the navigation's error (decimetres on GNSS): the absolute figures above include it (and so
  does the σ of ``within_2sigma``), this one is what a relative behaviour (follow, land) flies;
  ``relative_within_2sigma`` judges it against σ without the navigation's position part (in
  one flight the navigation's error is one slow draw, so the absolute share is mostly 0 or 1);
  ``relative_normalised_error_rms_ned`` the RMS of that error ÷ σ per axis (N, E, D): about 1
  on each axis where σ is honest, below where it is timid — over several seeds, since an error
  that is a fixed bias in one flight (a camera's mount) is one draw per flight;
* ``coasting_share`` — ticks flown on a prediction more than three frame periods old, and
  ``rms_position_error_coasting_m`` their error; ``lost_share`` — ticks with no usable estimate;
* ``at_update`` — the same errors right after each measurement update (the filter at its best;
  older logs without control-time records are scored this way only).

Latency: for each setpoint computed from a frame, capture time → the setpoint being sent.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.estimation.pose_history import slerp
from autopilot.flightlog import records as ch
from autopilot.flightlog.truth import BodyTrack, extend_floats, truth_table
from drivers.base import CameraIntrinsics
from drivers.camera_model import project_points
from drivers.geometry import quat_to_matrix


@dataclass(frozen=True, slots=True)
class FollowedTarget:
    """What scoring a follow step needs to know, from its plan record: the pipeline whose
    detections and estimates to score, its camera, the target's body in the ground truth and
    its size, and the standoff the step flew."""

    pipeline: str
    camera: str
    truth_body: str
    size_m: float
    standoff_m: float


def step_intervals(events: Sequence[Mapping], end_s: float, *, step_index: int | None = None,
                   step: str | None = None) -> list[tuple[float, float]]:
    """When a step ran: by its place in the plan (``step_index``) or by kind (``step``).
    From a step's ``step_started`` event to its ``step_succeeded``/``step_failed`` (a goal's
    ``goal_cancelled``) or the mission's ``aborted``. (Logs from before events had kinds: by
    their text.)"""
    intervals, start = [], None
    for e in events:
        kind = e.get("kind")
        if kind is None:  # an older log
            kind = _legacy_kind(e.get("text", ""))
        ours = (step_index is None or e.get("step_index", step_index) == step_index) and \
            (step is None or e.get("step") == step)
        if kind == "step_started" and ours:
            start = e["time_s"]
        elif start is not None and (kind == "aborted" or
                                    (kind in ("step_succeeded", "step_failed",
                                              "goal_cancelled") and ours)):
            intervals.append((start, e["time_s"]))
            start = None
    if start is not None:
        intervals.append((start, end_s))
    return intervals


def _legacy_kind(text: str) -> str:
    if text.startswith("step ") and text.endswith(" started"):
        return "step_started"
    if text.startswith("step ") and " succeeded" in text:
        return "step_succeeded"
    if text.startswith("step ") and " failed" in text:
        return "step_failed"
    return "aborted" if text.startswith("aborted") else ""


def followed_targets(log: Mapping[str, Sequence[Mapping]]
                     ) -> list[tuple[int, Mapping, FollowedTarget]]:
    """The plan's follow steps (those with a target pipeline and a standoff): (index, step
    record, target)."""
    plan = (log.get(ch.MISSION_PLAN) or [{}])[0]
    found = []
    for index, step in enumerate(plan.get("steps", [])):
        pipelines = step.get("pipelines") or []
        if pipelines and step.get("standoff_m") is not None:
            p = pipelines[0]
            found.append((index, step, FollowedTarget(p["name"], p["camera"], p["truth_body"],
                                                      p["size_m"], step["standoff_m"])))
    return found


def _first_follow(log) -> tuple[list[tuple[float, float]], FollowedTarget] | None:
    targets = followed_targets(log)
    if not targets:
        return None
    index, step, target = targets[0]
    return intervals_of(log, index, step.get("name")), target


def intervals_of(log, index: int, name: str | None) -> list[tuple[float, float]]:
    events = log.get(ch.MISSION_EVENTS, [])
    end = max((r["time_s"] for topic in (ch.GROUND_TRUTH, ch.VEHICLE_STATE)
               for r in log.get(topic, [])), default=0.0)
    legacy = events and "kind" not in events[0]
    return step_intervals(events, max(end, 0.0), step_index=None if legacy else index,
                          step=name)


def follow_step_metrics(log: Mapping[str, Sequence[Mapping]],
                        intervals: list[tuple[float, float]], step: Mapping) -> dict:
    """The metric groups of a follow step (its registered metrics function)."""
    pipelines = step.get("pipelines") or []
    if not pipelines:
        return {}
    p = pipelines[0]
    target = FollowedTarget(p["name"], p["camera"], p["truth_body"], p["size_m"],
                            step["standoff_m"])
    return {"follow": follow_metrics(log, intervals, target),
            "estimation": estimation_metrics(log, intervals, target)}


class TruthTrack:
    """The vehicle's pose and a body's position at any time within the samples that had the
    body (interpolated; the attitude by slerp)."""

    def __init__(self, track: BodyTrack) -> None:
        self.ok = len(track) > 0
        self.t, self.vp, self.vq, self.bp = track.t, track.vehicle_p, track.vehicle_q, track.p

    def at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        t = self.t
        if time_s < t[0] or time_s > t[-1]:
            return None
        if len(t) < 2:
            return self.vp[0], self.vq[0], self.bp[0]
        i = min(int(np.searchsorted(t, time_s, side="right")) - 1, len(t) - 2)
        f = (time_s - t[i]) / (t[i + 1] - t[i]) if t[i + 1] > t[i] else 0.0
        lerp = lambda a: a[i] + f * (a[i + 1] - a[i])  # noqa: E731
        return lerp(self.vp), slerp(self.vq[i], self.vq[i + 1], f), lerp(self.bp)


def camera_intrinsics(cam: Mapping) -> CameraIntrinsics:
    """A logged camera record's intrinsics (the plan record's ``cameras``)."""
    return CameraIntrinsics(int(cam["width_px"]), int(cam["height_px"]), cam["fx"], cam["fy"],
                            cam["cx"], cam["cy"], tuple(cam.get("distortion") or (0.0,) * 5))


def scoring_camera(log: Mapping[str, Sequence[Mapping]], name: str) -> Mapping | None:
    """The camera to score a detection with: as it really was (the simulator's true
    intrinsics and mount, ``/sim/camera_info``), else as its frames reported it (a log from a
    real vehicle, or from before the realistic world's calibration and mount errors)."""
    for topic in (ch.CAMERA_TRUTH, ch.CAMERA_INFO):
        cam = next((c for c in log.get(topic, []) if c["name"] == name), None)
        if cam is not None:
            return cam
    return None


def pixel_of(cam: Mapping, point_cam_m) -> tuple[float, float]:
    """Pixel of a point in a camera's optical frame, lens distortion applied (as the camera
    info record describes it)."""
    u, v = project_points(camera_intrinsics(cam), np.asarray(point_cam_m, dtype=float))
    return float(u), float(v)


def project_target(cam: Mapping, vehicle_p, vehicle_q, target_p, radius_m: float):
    """Pixel (lens distortion applied, as the camera info describes it), apparent radius and
    position in the optical frame of a target's centre; None if it is behind the camera."""
    r_wb = quat_to_matrix(vehicle_q)
    r_bc = np.array(cam["rotation_body_cam"]).reshape(3, 3)
    p_cam = r_bc.T @ (r_wb.T @ (np.asarray(target_p) - vehicle_p)
                      - np.array(cam["position_body_m"]))
    depth = float(np.linalg.norm(p_cam))
    if p_cam[2] <= 0.0 or depth <= radius_m:
        return None
    u, v = project_points(camera_intrinsics(cam), p_cam)
    r_px = cam["fx"] * radius_m / math.sqrt(depth * depth - radius_m * radius_m)
    return float(u), float(v), r_px


def fully_in_image(cam: Mapping, u: float, v: float, r_px: float) -> bool:
    """Whether a target imaged at (u, v) with radius ``r_px`` lies wholly inside the image."""
    return (u - r_px >= 0 and v - r_px >= 0 and u + r_px <= cam["width_px"] - 1
            and v + r_px <= cam["height_px"] - 1)


def in_image(cam: Mapping, u: float, v: float) -> bool:
    return 0 <= u <= cam["width_px"] - 1 and 0 <= v <= cam["height_px"] - 1


def follow_metrics(log: Mapping[str, Sequence[Mapping]],
                   intervals: list[tuple[float, float]] | None = None,
                   target: FollowedTarget | None = None) -> dict:
    """Follow figures of a step (by default the plan's first follow step)."""
    if target is None:
        found = _first_follow(log)
        if found is None:
            return {}
        intervals, target = found
    frames = log.get(ch.detection_topic(target.pipeline), [])
    cam = scoring_camera(log, target.camera)
    track = truth_table(log).body(target.truth_body)
    truth = TruthTrack(track)
    if not intervals or cam is None or not truth.ok:
        return {}
    radius_m = target.size_m / 2.0
    standoff = target.standoff_m
    half_diagonal = 0.5 * math.hypot(cam["width_px"], cam["height_px"])

    def following(t: float) -> bool:
        return any(a <= t <= b for a, b in intervals)

    in_view = correct = wrong = processed = 0
    image_errors, detection_times = array("d"), array("d")
    for rec in frames:
        t = rec["time_s"]
        pose = truth.at(t) if following(t) else None
        if pose is None:
            continue
        processed += 1
        proj = project_target(cam, *pose, radius_m)
        visible = False
        if proj is not None and in_image(cam, proj[0], proj[1]):
            image_errors.append(math.hypot(proj[0] - cam["cx"], proj[1] - cam["cy"]))
            visible = fully_in_image(cam, *proj)
            in_view += visible
        else:  # out of the image or behind the camera: the worst case
            image_errors.append(half_diagonal)
        if rec["detected"]:
            hit = proj is not None and math.hypot(rec["u_px"] - proj[0], rec["v_px"] - proj[1]) \
                <= max(3.0, 0.5 * proj[2])
            if hit:
                detection_times.append(t)
                correct += visible
            else:
                wrong += 1

    followed = _within(track.t, intervals)
    ranges = np.linalg.norm(track.p[followed] - track.vehicle_p[followed], axis=1) - standoff

    lost = 0.0
    detected_at = _floats(detection_times)
    for a, b in intervals:
        inside = detected_at[(detected_at >= a) & (detected_at <= b)]
        lost = max(lost, float(np.max(np.diff(np.concatenate(([a], inside, [b]))))))

    # how fast the target really moved while followed (truth): the scenario as flown
    speeds = []
    if len(truth.t) > 1:
        dt = np.diff(truth.t)
        ok = dt > 0
        v = np.linalg.norm(np.diff(truth.bp, axis=0)[ok], axis=1) / dt[ok]
        mid = (truth.t[1:][ok] + truth.t[:-1][ok]) / 2.0
        speeds = v[_within(mid, intervals)]

    abs_ranges = np.abs(ranges)
    return {
        "target_speed_mps_rms": _rms(speeds),
        "target_speed_mps_max": float(np.max(speeds)) if len(speeds) else None,
        "detection_rate": correct / in_view if in_view else None,
        "frames_in_view": in_view,
        "frames_processed": processed,
        "false_detection_rate": wrong / processed if processed else None,
        "rms_range_error_m": _rms(ranges),
        "mean_range_error_m": float(np.mean(ranges)) if len(ranges) else None,
        "p95_abs_range_error_m": float(np.percentile(abs_ranges, 95)) if len(ranges) else None,
        "max_abs_range_error_m": float(np.max(abs_ranges)) if len(ranges) else None,
        "rms_image_error_px": _rms(image_errors),
        "p95_image_error_px": float(np.percentile(image_errors, 95)) if image_errors else None,
        "max_lost_s": float(lost),
        "follow_time_s": float(sum(b - a for a, b in intervals)),
        "standoff_m": standoff,
    }


class _TruthInterp:
    def __init__(self, track: BodyTrack) -> None:
        self.ok = len(track) >= 2
        self.t, self.p, self.v = track.t, track.p, track.v

    def covers(self, time_s: float) -> bool:
        return bool(self.t[0] <= time_s <= self.t[-1])

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        def interp(a):
            return np.stack([np.interp(times, self.t, a[:, i]) for i in range(3)], axis=1)
        return interp(self.p), interp(self.v)


class Estimates:
    """Target estimate records as columns: time, position, velocity and position σ (NaN for
    null), and the estimate's age (NaN where the record had none)."""

    def __init__(self) -> None:
        self._t, self._p, self._v = array("d"), array("d"), array("d")
        self._std, self._age = array("d"), array("d")

    def add(self, r: Mapping) -> None:
        self._t.append(r["time_s"])
        extend_floats(self._p, r.get("position_ned_m"), 3)
        extend_floats(self._v, r.get("velocity_ned_m_s"), 3)
        extend_floats(self._std, r.get("position_std_m"), 3)
        age = r.get("age_s")
        self._age.append(math.nan if age is None else age)

    def __len__(self) -> int:
        return len(self._t)

    @property
    def age(self) -> np.ndarray:
        return _floats(self._age)

    def columns(self, keep: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(time, position, velocity, σ), of the rows ``keep`` selects (all by default)."""
        cols = (_floats(self._t), _floats(self._p).reshape(-1, 3),
                _floats(self._v).reshape(-1, 3), _floats(self._std).reshape(-1, 3))
        return cols if keep is None else tuple(c[keep] for c in cols)


def _floats(column: array) -> np.ndarray:
    """An ``array('d')`` as a numpy array without a copy (its length fixed from then on)."""
    return np.frombuffer(column, dtype=float) if len(column) else np.zeros(0)


def _errors(columns: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
            truth: _TruthInterp) -> dict:
    """Position/velocity errors of estimates (:meth:`Estimates.columns`) against the truth at
    their times."""
    times, position, velocity, std = columns
    true_p, true_v = truth.at(times)
    pos_err = position - true_p
    vel_err = velocity - true_v
    norm = np.linalg.norm(pos_err, axis=1)
    return {
        "rms_position_error_m": float(np.sqrt(np.mean(norm ** 2))),
        "rms_position_error_ned_m": np.sqrt(np.mean(pos_err ** 2, axis=0)).tolist(),
        "p95_position_error_m": float(np.percentile(norm, 95)),
        "max_position_error_m": float(np.max(norm)),
        "rms_velocity_error_m_s": float(np.sqrt(np.mean(np.sum(vel_err ** 2, axis=1)))),
        "within_2sigma": float(np.mean(np.all(np.abs(pos_err) <= 2.0 * std, axis=1))),
    }


def estimation_metrics(log: Mapping[str, Sequence[Mapping]],
                       intervals: list[tuple[float, float]] | None = None,
                       target: FollowedTarget | None = None) -> dict:
    """Estimate figures of a step's target (by default the plan's first follow step): at
    control time (what the behaviour flew on), and ``at_update``."""
    if target is None:
        found = _first_follow(log)
        if found is None:
            return {}
        intervals, target = found
    truth = _TruthInterp(truth_table(log).body(target.truth_body))
    if not truth.ok or not intervals:
        return {}

    def scored(t: float) -> bool:
        return truth.covers(t) and any(a <= t <= b for a, b in intervals)

    updates = _scored_estimates(
        (e for e in log.get(ch.TARGET_ESTIMATES, [])
         if e.get("pipeline", target.pipeline) == target.pipeline), scored)
    at_update = {**_errors(updates.columns(), truth), "estimates": len(updates)} \
        if len(updates) else {}
    ticks = 0
    usable = Estimates()  # the ticks with an estimate that is not stale
    for r in log.get(ch.CONTROL_TARGET, []):
        if r["pipeline"] == target.pipeline and scored(r["time_s"]):
            ticks += 1
            if r["present"] and not r["stale"]:
                usable.add(r)
    if not ticks:  # a log from before control-time records: the updates are all there is
        return at_update
    cams = {c["name"]: c for c in log.get(ch.CAMERA_INFO, [])}
    rate = (cams.get(target.camera) or {}).get("rate_hz") or 30.0
    coast_after_s = 3.0 / rate
    coasting = usable.age > coast_after_s
    relative = _relative_error(log, usable.columns(), truth) if len(usable) else None
    result = {**(_errors(usable.columns(), truth) if len(usable) else {}),
              **(relative or {}),
              "ticks": ticks,
              "lost_share": 1.0 - len(usable) / ticks,
              "coasting_share": int(coasting.sum()) / ticks,
              "rms_position_error_coasting_m":
                  _errors(usable.columns(coasting), truth)["rms_position_error_m"]
                  if coasting.any() else None,
              "at_update": at_update}
    return result


def _navigation_std(log: Mapping[str, Sequence[Mapping]]) -> np.ndarray | None:
    """The navigation's position σ (N, E, D) the flight's configuration gave its estimates."""
    for plan in log.get(ch.MISSION_PLAN, []):
        nav = ((plan.get("config") or {}).get("estimation") or {}).get("navigation") or {}
        p = nav.get("position_std_m")
        if p is not None:
            h = nav.get("height_std_m", p)
            return np.array([p, p, h], dtype=float)
    return None


def _relative_error(log: Mapping[str, Sequence[Mapping]],
                    columns: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                    truth: _TruthInterp) -> dict | None:
    """The estimate's error relative to the vehicle (see the module's docstring): its RMS,
    and the share within ±2σ on every axis, σ without the navigation's position error (which
    the relative error does not contain)."""
    nav_t, nav_p = [], []
    for r in log.get(ch.VEHICLE_STATE, []):
        p = r.get("position_ned_m")
        if p is not None and all(v is not None and math.isfinite(v) for v in p):
            nav_t.append(r["time_s"])
            nav_p.append(p)
    table = truth_table(log)
    vehicle = table.has_vehicle
    if len(nav_t) < 2 or vehicle.sum() < 2:
        return None
    times, position = columns[0], columns[1]
    nav_t, nav_p = np.asarray(nav_t, dtype=float), np.asarray(nav_p, dtype=float)
    true_t, true_p = table.t[vehicle], table.p[vehicle]

    def at(t, p):
        return np.stack([np.interp(times, t, p[:, i]) for i in range(3)], axis=1)

    target, _ = truth.at(times)
    err = (position - at(nav_t, nav_p)) - (target - at(true_t, true_p))
    out = {"rms_relative_position_error_m": float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))}
    nav_std = _navigation_std(log)
    if nav_std is not None:
        std = np.sqrt(np.maximum(columns[3] ** 2 - nav_std ** 2, 0.0))
        out["relative_within_2sigma"] = float(np.mean(np.all(np.abs(err) <= 2.0 * std,
                                                             axis=1)))
        ok = np.all(std > 0.0, axis=1)
        if ok.any():  # N, E, D: 1.0 where σ is honest, below it where σ is timid
            out["relative_normalised_error_rms_ned"] = np.sqrt(
                np.mean((err[ok] / std[ok]) ** 2, axis=0)).tolist()
    return out


def _scored_estimates(rows: Iterable[Mapping], scored) -> Estimates:
    out = Estimates()
    for r in rows:
        if scored(r["time_s"]):
            out.add(r)
    return out


def phase_entries(setpoints: Iterable[Mapping], step: str, start_s: float, end_s: float,
                  phase: str) -> int:
    """How many times a step's setpoints (those within [start_s, end_s]) went into ``phase``
    from another phase (the first one's phase is not an entry): its retries."""
    count, previous, first = 0, None, True
    for r in setpoints:
        if start_s <= r["time_s"] <= end_s and r.get("step") == step:
            current = r.get("phase")
            count += not first and current == phase and previous != phase
            previous, first = current, False
    return count


def latency_metrics(log: Mapping[str, Sequence[Mapping]]) -> dict:
    lat = np.fromiter((r["latency_ms"] for r in log.get(ch.SETPOINTS, [])
                       if r.get("latency_ms") is not None), dtype=float)
    if not len(lat):
        return {"p50": None, "p95": None, "samples": 0}
    return {"p50": float(np.percentile(lat, 50)), "p95": float(np.percentile(lat, 95)),
            "max": float(np.max(lat)), "samples": len(lat)}


def _rms(values: Sequence[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else None


def _within(times: np.ndarray, intervals: Sequence[tuple[float, float]]) -> np.ndarray:
    """Which of ``times`` lie in one of the (closed) intervals."""
    inside = np.zeros(len(times), dtype=bool)
    for a, b in intervals:
        inside |= (times >= a) & (times <= b)
    return inside
