"""What the flight report plots, extracted from a flight log's records (plain functions of the
records, so that each is tested on its own and the report can draw whatever a log holds).

Every series is a dict of numpy arrays keyed by name; times are the run's clock in seconds.
Ground-truth series are empty for flights that had none (real vehicles).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import TruthTrack, fully_in_image, project_ball

BALL = "ball"
Records = Mapping[str, Sequence[Mapping]]


def _arr(rows: Sequence[Mapping], key: str, width: int | None = None) -> np.ndarray:
    values = [r.get(key) for r in rows]
    if width is None:
        return np.array([math.nan if v is None else v for v in values], dtype=float)
    return np.array([[math.nan] * width if v is None else
                     [math.nan if x is None else x for x in v] for v in values],
                    dtype=float).reshape(len(rows), width)


def phases(records: Records) -> list[tuple[float, float, str]]:
    """(start, end, step) for each mission step, from the mission events."""
    events = records.get(ch.MISSION_EVENTS, [])
    end_of_log = max((r.get("time_s", 0.0) for rows in records.values() for r in rows
                      if isinstance(r.get("time_s"), (int, float))), default=0.0)
    out, current = [], None
    for e in events:
        text = e.get("text", "")
        if text.startswith("step ") and text.endswith(" started"):
            if current is not None:
                out.append((current[0], e["time_s"], current[1]))
            current = (e["time_s"], text[len("step "):-len(" started")])
        elif current is not None and text.startswith(f"step {current[1]} "):
            out.append((current[0], e["time_s"], current[1]))
            current = None
    if current is not None:
        out.append((current[0], end_of_log, current[1]))
    return out


def trajectories(records: Records) -> dict[str, np.ndarray]:
    """Vehicle (telemetry and truth) and target (estimate and truth) positions, NED."""
    state = records.get(ch.VEHICLE_STATE, [])
    truth = [r for r in records.get(ch.GROUND_TRUTH, [])]
    est = records.get(ch.TARGET_ESTIMATES, [])
    ball = [r for r in truth if BALL in (r.get("bodies") or {})]
    return {
        "vehicle_t": _arr(state, "time_s"), "vehicle": _arr(state, "position_ned_m", 3),
        "vehicle_truth_t": _arr(truth, "time_s"),
        "vehicle_truth": _arr(truth, "vehicle_position_ned_m", 3),
        "target_estimate_t": _arr(est, "time_s"), "target_estimate": _arr(est, "position_ned_m", 3),
        "target_truth_t": _arr(ball, "time_s"),
        "target_truth": np.array([r["bodies"][BALL]["position_ned_m"] for r in ball],
                                 dtype=float).reshape(len(ball), 3),
    }


def standoff_error(records: Records) -> dict[str, np.ndarray]:
    """True vehicle–target distance minus the standoff (truth), and the autopilot's own view
    (estimate minus telemetry)."""
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    standoff = float(plan.get("standoff_m") or 0.0)
    tr = trajectories(records)
    out = {"t": tr["target_truth_t"], "error_m": np.empty(0), "estimated_t": np.empty(0),
           "estimated_error_m": np.empty(0)}
    if len(tr["target_truth_t"]) and len(tr["vehicle_truth_t"]):
        truth = [r for r in records.get(ch.GROUND_TRUTH, []) if BALL in (r.get("bodies") or {})]
        vehicle = _arr(truth, "vehicle_position_ned_m", 3)
        out["error_m"] = np.linalg.norm(tr["target_truth"] - vehicle, axis=1) - standoff
    if len(tr["target_estimate_t"]) and len(tr["vehicle_t"]):
        t = tr["target_estimate_t"]
        vehicle = np.stack([np.interp(t, tr["vehicle_t"], tr["vehicle"][:, i])
                            for i in range(3)], axis=1)
        out["estimated_t"] = t
        out["estimated_error_m"] = np.linalg.norm(tr["target_estimate"] - vehicle, axis=1) \
            - standoff
    return out


def detection_timeline(records: Records) -> dict[str, np.ndarray]:
    """Per processed frame: its time, whether the ball was detected, and (from ground truth,
    when the log has it) whether the whole ball was truly in the image; ``in_view`` is all
    False without truth, and ``has_truth`` says which."""
    rows = records.get(ch.BALL_DETECTIONS, [])
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    cams = {c.get("name"): c for c in records.get(ch.CAMERA_INFO, [])}
    truth = TruthTrack(records.get(ch.GROUND_TRUTH, []))
    in_view = np.zeros(len(rows), dtype=bool)
    has_truth = truth.ok and plan.get("ball_diameter_m") is not None
    if has_truth:
        radius_m = plan["ball_diameter_m"] / 2.0
        for i, r in enumerate(rows):
            cam = cams.get(r.get("camera", plan.get("camera")))
            pose = truth.at(r["time_s"]) if cam is not None else None
            proj = project_ball(cam, *pose, radius_m) if pose is not None else None
            in_view[i] = proj is not None and fully_in_image(cam, *proj)
    return {"t": _arr(rows, "time_s"),
            "detected": np.array([bool(r.get("detected")) for r in rows], dtype=bool),
            "in_view": in_view, "has_truth": np.array(has_truth)}


def estimate_vs_truth(records: Records) -> dict[str, np.ndarray]:
    """Target estimate with its standard deviation, and the truth at the estimate's times."""
    est = records.get(ch.TARGET_ESTIMATES, [])
    tr = trajectories(records)
    t = tr["target_estimate_t"]
    truth = np.full((len(t), 3), math.nan)
    if len(tr["target_truth_t"]) >= 2 and len(t):
        truth = np.stack([np.interp(t, tr["target_truth_t"], tr["target_truth"][:, i],
                                    left=math.nan, right=math.nan) for i in range(3)], axis=1)
    return {"t": t, "estimate": tr["target_estimate"], "std": _arr(est, "position_std_m", 3),
            "truth": truth}


def velocity_tracking(records: Records) -> dict[str, np.ndarray]:
    """Commanded velocity (NED; body-frame setpoints turned by the vehicle's yaw) and the
    vehicle's velocity from telemetry."""
    sp = records.get(ch.SETPOINTS, [])
    state = records.get(ch.VEHICLE_STATE, [])
    st_t, yaw = _arr(state, "time_s"), _arr(state, "yaw_rad")
    t = _arr(sp, "time_s")
    cmd = _arr(sp, "velocity_m_s", 3)
    body = np.array([r.get("frame") == "body_frd" for r in sp], dtype=bool)
    if body.any() and len(st_t):
        psi = np.interp(t[body], st_t, np.unwrap(yaw))
        fwd, right = cmd[body, 0].copy(), cmd[body, 1].copy()
        cmd[body, 0] = np.cos(psi) * fwd - np.sin(psi) * right
        cmd[body, 1] = np.sin(psi) * fwd + np.cos(psi) * right
    return {"command_t": t, "command": cmd, "actual_t": st_t,
            "actual": _arr(state, "velocity_ned_m_s", 3)}


def latencies_ms(records: Records) -> np.ndarray:
    """Frame capture → setpoint, per setpoint computed from a frame."""
    values = [r.get("latency_ms") for r in records.get(ch.SETPOINTS, [])]
    return np.array([v for v in values if v is not None], dtype=float)
