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
from autopilot.flightlog.metrics import (
    FollowedTarget,
    TruthTrack,
    followed_targets,
    fully_in_image,
    intervals_of,
    project_target,
)
from autopilot.flightlog.truth import truth_table

Records = Mapping[str, Sequence[Mapping]]


def targets(records: Records) -> list[FollowedTarget]:
    """The followed targets of the plan's steps (one per pipeline, in step order)."""
    seen: dict[str, FollowedTarget] = {}
    for _, _, target in followed_targets(records):
        seen.setdefault(target.pipeline, target)
    # steps with a target but no standoff (hover over an image, land on a pad)
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    for step in plan.get("steps", []):
        for p in step.get("pipelines") or []:
            if p.get("truth_body"):
                seen.setdefault(p["name"], FollowedTarget(
                    p["name"], p["camera"], p["truth_body"], p.get("size_m") or 0.0, 0.0))
    return list(seen.values())


def followed_spans(records: Records, target: FollowedTarget | None
                   ) -> list[tuple[float, float]]:
    """When ``target`` was followed: the intervals of the steps that followed it."""
    if target is None:
        return []
    return [span for index, step, followed in followed_targets(records)
            if followed.pipeline == target.pipeline
            for span in intervals_of(records, index, step.get("name"))]


def _estimates(records: Records, target: FollowedTarget | None) -> list[Mapping]:
    if target is None:
        return []
    return [e for e in records.get(ch.TARGET_ESTIMATES, [])
            if e.get("pipeline", target.pipeline) == target.pipeline]


def _arr(rows: Sequence[Mapping], key: str, width: int | None = None) -> np.ndarray:
    values = [r.get(key) for r in rows]
    if width is None:
        return np.array([math.nan if v is None else v for v in values], dtype=float)
    return np.array([[math.nan] * width if v is None else
                     [math.nan if x is None else x for x in v] for v in values],
                    dtype=float).reshape(len(rows), width)


def phases(records: Records) -> list[tuple[float, float, str]]:
    """(start, end, step) for each mission step and the fallback, from the mission events."""
    events = records.get(ch.MISSION_EVENTS, [])
    end_of_log = max((r.get("time_s", 0.0) for rows in records.values() for r in rows
                      if isinstance(r.get("time_s"), (int, float))), default=0.0)
    out, current = [], None
    for e in events:
        kind = e.get("kind") or _legacy_kind(e.get("text", ""))
        if kind in ("step_started", "fallback_started"):
            if current is not None:
                out.append((current[0], e["time_s"], current[1]))
            name = e.get("step") if e.get("kind") else \
                e.get("text", "").split(" ")[1] if " " in e.get("text", "") else ""
            current = (e["time_s"], name if kind == "step_started" else f"{name} (fallback)")
        elif current is not None and kind in ("step_succeeded", "step_failed", "fallback_ended"):
            out.append((current[0], e["time_s"], current[1]))
            current = None
    if current is not None:
        out.append((current[0], end_of_log, current[1]))
    return out


def _legacy_kind(text: str) -> str:
    if text.startswith("step ") and text.endswith(" started"):
        return "step_started"
    if text.startswith("step ") and (" succeeded" in text or " failed" in text):
        return "step_succeeded"
    return ""


def trajectories(records: Records, target: FollowedTarget | None = None
                 ) -> dict[str, np.ndarray]:
    """Vehicle (telemetry and truth) and target (estimate and truth) positions, NED."""
    state = records.get(ch.VEHICLE_STATE, [])
    truth = [r for r in records.get(ch.GROUND_TRUTH, [])]
    est = _estimates(records, target)
    body = target.truth_body if target is not None else None
    rows = [r for r in truth if body in (r.get("bodies") or {})]
    return {
        "vehicle_t": _arr(state, "time_s"), "vehicle": _arr(state, "position_ned_m", 3),
        "vehicle_truth_t": _arr(truth, "time_s"),
        "vehicle_truth": _arr(truth, "vehicle_position_ned_m", 3),
        "target_estimate_t": _arr(est, "time_s"), "target_estimate": _arr(est, "position_ned_m", 3),
        "target_truth_t": _arr(rows, "time_s"),
        "target_truth": np.array([r["bodies"][body]["position_ned_m"] for r in rows],
                                 dtype=float).reshape(len(rows), 3),
    }


def standoff_error(records: Records, target: FollowedTarget | None
                   ) -> dict[str, np.ndarray]:
    """True vehicle–target distance minus the standoff (truth), and the autopilot's own view
    (estimate minus telemetry)."""
    standoff = target.standoff_m if target is not None else 0.0
    tr = trajectories(records, target)
    out = {"t": tr["target_truth_t"], "error_m": np.empty(0), "estimated_t": np.empty(0),
           "estimated_error_m": np.empty(0)}
    if len(tr["target_truth_t"]) and len(tr["vehicle_truth_t"]):
        truth = [r for r in records.get(ch.GROUND_TRUTH, [])
                 if target.truth_body in (r.get("bodies") or {})]
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


def over_target(records: Records, target: FollowedTarget | None) -> dict[str, np.ndarray]:
    """The vehicle's horizontal offset from a target on the ground (north, east; truth), and
    as the autopilot saw it (telemetry minus the target's estimate)."""
    tr = trajectories(records, target)
    out = {"t": np.empty(0), "offset_ne": np.empty((0, 2)), "estimated_t": np.empty(0),
           "estimated_offset_ne": np.empty((0, 2)), "height_m": np.empty(0)}
    if len(tr["target_truth_t"]) >= 2 and len(tr["vehicle_truth_t"]):
        t = tr["vehicle_truth_t"]
        inside = (t >= tr["target_truth_t"][0]) & (t <= tr["target_truth_t"][-1])
        t = t[inside]
        target_ne = np.stack([np.interp(t, tr["target_truth_t"], tr["target_truth"][:, i])
                              for i in range(3)], axis=1)
        vehicle = tr["vehicle_truth"][inside]
        out.update(t=t, offset_ne=vehicle[:, :2] - target_ne[:, :2],
                   height_m=target_ne[:, 2] - vehicle[:, 2])
    if len(tr["target_estimate_t"]) and len(tr["vehicle_t"]):
        t = tr["target_estimate_t"]
        vehicle = np.stack([np.interp(t, tr["vehicle_t"], tr["vehicle"][:, i])
                            for i in range(2)], axis=1)
        out.update(estimated_t=t, estimated_offset_ne=vehicle - tr["target_estimate"][:, :2])
    return out


def detection_timeline(records: Records, target: FollowedTarget | None
                       ) -> dict[str, np.ndarray]:
    """Per processed frame: its time, whether the target was detected, and (from ground truth,
    when the log has it) whether the whole target was truly in the image; ``in_view`` is all
    False without truth, and ``has_truth`` says which."""
    rows = records.get(ch.detection_topic(target.pipeline), []) if target is not None else []
    cams = {c.get("name"): c for c in records.get(ch.CAMERA_INFO, [])}
    truth = TruthTrack(truth_table(records).body(target.truth_body if target is not None
                                                 else ""))
    in_view = np.zeros(len(rows), dtype=bool)
    has_truth = truth.ok
    if has_truth:
        radius_m = target.size_m / 2.0
        for i, r in enumerate(rows):
            cam = cams.get(r.get("camera", target.camera))
            pose = truth.at(r["time_s"]) if cam is not None else None
            proj = project_target(cam, *pose, radius_m) if pose is not None else None
            in_view[i] = proj is not None and fully_in_image(cam, *proj)
    return {"t": _arr(rows, "time_s"),
            "detected": np.array([bool(r.get("detected")) for r in rows], dtype=bool),
            "in_view": in_view, "has_truth": np.array(has_truth)}


def estimate_vs_truth(records: Records, target: FollowedTarget | None
                      ) -> dict[str, np.ndarray]:
    """The target estimate the behaviour flew on (at each control tick, coasting included;
    the filter's updates for logs without those) with its standard deviation, and the truth at
    the same times."""
    rows = [r for r in records.get(ch.CONTROL_TARGET, [])
            if target is not None and r.get("pipeline") == target.pipeline and r.get("present")]
    if not rows:
        rows = _estimates(records, target)
    tr = trajectories(records, target)
    t = _arr(rows, "time_s")
    truth = np.full((len(t), 3), math.nan)
    if len(tr["target_truth_t"]) >= 2 and len(t):
        truth = np.stack([np.interp(t, tr["target_truth_t"], tr["target_truth"][:, i],
                                    left=math.nan, right=math.nan) for i in range(3)], axis=1)
    return {"t": t, "estimate": _arr(rows, "position_ned_m", 3),
            "std": _arr(rows, "position_std_m", 3), "truth": truth}


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
