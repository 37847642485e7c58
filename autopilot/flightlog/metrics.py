"""End-of-run metrics, computed from the flight log's records (scoring uses ground truth, which
only the simulator provides; the autopilot never saw it).

Follow metrics cover the intervals in which a ``follow_ball`` step ran:

* ``detection_rate`` — frames in which the ball was detected where it truly was (within
  max(3 px, half its apparent radius)) ÷ frames in which the whole ball was inside the image;
* ``rms_range_error_m`` — RMS of (true vehicle–ball distance − standoff) over the truth samples;
* ``rms_image_error_px`` — RMS distance of the ball's true image position from the image centre,
  over the frames in which it was in front of the camera, each clipped at the image's
  half-diagonal (a ball out of view counts as at the edge);
* ``max_lost_s`` — the longest time without a correct detection;
* ``false_detection_rate`` — detections that were not the ball ÷ frames processed.

Estimation metrics cover the target estimates made during those intervals, each compared with
the ball's true position and velocity at its time:

* ``rms_position_error_m`` — RMS of the 3-D position error; ``rms_position_error_ned_m`` per axis;
* ``rms_velocity_error_m_s`` — RMS of the 3-D velocity error;
* ``within_2sigma`` — the share of estimates whose error is inside ±2σ on every axis (a filter
  whose σ is honest has about 0.87 here).

Latency: for each setpoint computed from a frame, capture time → the setpoint being sent.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.estimation.pose_history import slerp
from autopilot.flightlog import records as ch
from drivers.geometry import quat_to_matrix

FOLLOW_STEP = "follow_ball"
BALL = "ball"


def follow_intervals(events: Sequence[Mapping], end_s: float) -> list[tuple[float, float]]:
    intervals, start = [], None
    for e in events:
        if e["text"] == f"step {FOLLOW_STEP} started":
            start = e["time_s"]
        elif start is not None and (e["text"].startswith(f"step {FOLLOW_STEP} ")
                                    or e["text"].startswith("aborted")):
            intervals.append((start, e["time_s"]))
            start = None
    if start is not None:
        intervals.append((start, end_s))
    return intervals


class TruthTrack:
    def __init__(self, samples: Sequence[Mapping]) -> None:
        rows = [s for s in samples if BALL in s["bodies"]]
        self.ok = bool(rows)
        if not self.ok:
            return
        self.t = np.array([s["time_s"] for s in rows])
        self.vp = np.array([s["vehicle_position_ned_m"] for s in rows])
        self.vq = np.array([s["vehicle_attitude_q"] for s in rows])
        self.bp = np.array([s["bodies"][BALL]["position_ned_m"] for s in rows])

    def at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        t = self.t
        if time_s < t[0] or time_s > t[-1]:
            return None
        i = min(int(np.searchsorted(t, time_s, side="right")) - 1, len(t) - 2)
        f = (time_s - t[i]) / (t[i + 1] - t[i]) if t[i + 1] > t[i] else 0.0
        lerp = lambda a: a[i] + f * (a[i + 1] - a[i])  # noqa: E731
        return lerp(self.vp), slerp(self.vq[i], self.vq[i + 1], f), lerp(self.bp)


def project_ball(cam: Mapping, vehicle_p, vehicle_q, ball_p, radius_m: float):
    """Pixel, apparent radius and depth of the ball's centre in a camera (None if behind)."""
    r_wb = quat_to_matrix(vehicle_q)
    r_bc = np.array(cam["rotation_body_cam"]).reshape(3, 3)
    p_cam = r_bc.T @ (r_wb.T @ (ball_p - vehicle_p) - np.array(cam["position_body_m"]))
    depth = float(np.linalg.norm(p_cam))
    if p_cam[2] <= 0.0 or depth <= radius_m:
        return None
    u = cam["fx"] * p_cam[0] / p_cam[2] + cam["cx"]
    v = cam["fy"] * p_cam[1] / p_cam[2] + cam["cy"]
    r_px = cam["fx"] * radius_m / math.sqrt(depth * depth - radius_m * radius_m)
    return u, v, r_px


def fully_in_image(cam: Mapping, u: float, v: float, r_px: float) -> bool:
    """Whether a ball imaged at (u, v) with radius ``r_px`` lies wholly inside the image."""
    return (u - r_px >= 0 and v - r_px >= 0 and u + r_px <= cam["width_px"] - 1
            and v + r_px <= cam["height_px"] - 1)


def follow_metrics(log: Mapping[str, Sequence[Mapping]]) -> dict:
    plan = (log.get(ch.MISSION_PLAN) or [{}])[0]
    events = log.get(ch.MISSION_EVENTS, [])
    truth_samples = log.get(ch.GROUND_TRUTH, [])
    frames = log.get(ch.BALL_DETECTIONS, [])
    end = max([r["time_s"] for r in truth_samples] + [r["time_s"] for r in frames] + [0.0])
    intervals = follow_intervals(events, end)
    cams = {c["name"]: c for c in log.get(ch.CAMERA_INFO, [])}
    cam = cams.get(plan.get("camera"))
    truth = TruthTrack(truth_samples)
    if not intervals or cam is None or not truth.ok:
        return {}
    radius_m = plan["ball_diameter_m"] / 2.0
    standoff = plan["standoff_m"]

    def following(t: float) -> bool:
        return any(a <= t <= b for a, b in intervals)

    in_view = correct = wrong = processed = 0
    image_errors, detection_times = [], []
    for rec in frames:
        t = rec["time_s"]
        if not following(t):
            continue
        processed += 1
        pose = truth.at(t)
        proj = project_ball(cam, *pose, radius_m) if pose is not None else None
        if proj is not None:
            u, v, r_px = proj
            half_diagonal = 0.5 * math.hypot(cam["width_px"], cam["height_px"])
            image_errors.append(min(math.hypot(u - cam["cx"], v - cam["cy"]), half_diagonal))
            visible = fully_in_image(cam, u, v, r_px)
            in_view += visible
        if rec["detected"]:
            hit = proj is not None and math.hypot(rec["u_px"] - proj[0], rec["v_px"] - proj[1]) \
                <= max(3.0, 0.5 * proj[2])
            if hit:
                detection_times.append(t)
                correct += visible
            else:
                wrong += 1

    ranges = []
    for s in truth_samples:
        if following(s["time_s"]) and BALL in s["bodies"]:
            d = np.linalg.norm(np.array(s["bodies"][BALL]["position_ned_m"])
                               - np.array(s["vehicle_position_ned_m"]))
            ranges.append(d - standoff)

    lost = 0.0
    for a, b in intervals:
        times = [a] + [t for t in detection_times if a <= t <= b] + [b]
        lost = max(lost, max(np.diff(times)))

    return {
        "detection_rate": correct / in_view if in_view else None,
        "frames_in_view": in_view,
        "frames_processed": processed,
        "false_detection_rate": wrong / processed if processed else None,
        "rms_range_error_m": _rms(ranges),
        "mean_range_error_m": float(np.mean(ranges)) if ranges else None,
        "rms_image_error_px": _rms(image_errors),
        "max_lost_s": float(lost),
        "follow_time_s": float(sum(b - a for a, b in intervals)),
        "standoff_m": standoff,
    }


def estimation_metrics(log: Mapping[str, Sequence[Mapping]]) -> dict:
    events = log.get(ch.MISSION_EVENTS, [])
    truth_samples = [s for s in log.get(ch.GROUND_TRUTH, []) if BALL in s["bodies"]]
    estimates = log.get(ch.TARGET_ESTIMATES, [])
    if len(truth_samples) < 2 or not estimates:
        return {}
    end = max(r["time_s"] for r in truth_samples)
    intervals = follow_intervals(events, end)
    t = np.array([s["time_s"] for s in truth_samples])
    bp = np.array([s["bodies"][BALL]["position_ned_m"] for s in truth_samples], dtype=float)
    bv = np.array([s["bodies"][BALL]["velocity_ned_m_s"] for s in truth_samples], dtype=float)
    rows = [e for e in estimates if t[0] <= e["time_s"] <= t[-1]
            and any(a <= e["time_s"] <= b for a, b in intervals)]
    if not rows:
        return {}
    et = np.array([e["time_s"] for e in rows])
    interp = lambda a: np.stack([np.interp(et, t, a[:, i]) for i in range(3)], axis=1)  # noqa: E731
    nan = lambda v: [math.nan if x is None else x for x in v]  # noqa: E731
    pos_err = np.array([nan(e["position_ned_m"]) for e in rows], dtype=float) - interp(bp)
    vel_err = np.array([nan(e["velocity_ned_m_s"]) for e in rows], dtype=float) - interp(bv)
    std = np.array([nan(e["position_std_m"]) for e in rows], dtype=float)
    return {
        "rms_position_error_m": float(np.sqrt(np.mean(np.sum(pos_err ** 2, axis=1)))),
        "rms_position_error_ned_m": np.sqrt(np.mean(pos_err ** 2, axis=0)).tolist(),
        "rms_velocity_error_m_s": float(np.sqrt(np.mean(np.sum(vel_err ** 2, axis=1)))),
        "within_2sigma": float(np.mean(np.all(np.abs(pos_err) <= 2.0 * std, axis=1))),
        "estimates": len(rows),
    }


def latency_metrics(log: Mapping[str, Sequence[Mapping]]) -> dict:
    lat = [r["latency_ms"] for r in log.get(ch.SETPOINTS, []) if r.get("latency_ms") is not None]
    if not lat:
        return {"p50": None, "p95": None, "samples": 0}
    return {"p50": float(np.percentile(lat, 50)), "p95": float(np.percentile(lat, 95)),
            "max": float(np.max(lat)), "samples": len(lat)}


def _rms(values: Sequence[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else None
