"""The ``land_on_rover`` step kind: precision landing on a moving rover's deck (seed 004).

Its behaviour is :class:`~autopilot.behaviors.land_on_rover.LandOnRover`, its pipeline the deck
pipeline (:mod:`autopilot.perception.deck_pipeline`: the relative-state filter fusing UWB, the
deck's tag, the rangefinder and the rover's reports; ``use_uwb`` / ``use_marker`` choose).

Its metrics (simulator ground truth, scoring only):

``landing``
    ``on_deck`` — the vehicle came to rest on the deck (standing on it, inside its edges,
    carried at the rover's speed); ``error_m`` — at touchdown (first contact), the body's
    horizontal distance from the deck's centre (``error_deck_m``: along and across the rover);
    ``rest_error_m`` — the same where it came to rest; ``relative_speed_m_s`` /
    ``relative_horizontal_speed_m_s`` — against the deck over the last 0.3 s before contact;
    ``time_to_land_s``; ``retries`` (aborts and climbs); ``landed`` (the step succeeded).
``relative``
    The relative estimate the behaviour flew on (``/control/target``: the deck in the drone's
    own frame, minus the drone's own position estimate) against the true relative position:
    horizontal and vertical RMS, p95 and worst; ``within_2sigma`` (both horizontal axes within
    2σ); the share of control ticks without a usable estimate; and each source's availability
    (the share of the step with an update from it within the last 0.5 s).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.behaviors.land_on_rover import (
    LandOnRover,
    LandOnRoverParams,
    LandOnRoverSettings,
    Seed004LandOnRover,
)
from autopilot.flightlog import records as ch
from autopilot.perception.deck_pipeline import ROVER_BODY, deck_spec
from autopilot.steps.follow_ball import camera_of
from autopilot.steps.registry import StepContext, StepKind, register
from drivers.geometry import yaw_from_quat as _yaw_of

#: resting: within this of the height the vehicle finally rests at over the deck
_REST_BAND_M = 0.015
SOURCES = ("uwb", "tag", "range", "rover")


def _behavior(params: LandOnRoverParams, ctx: StepContext) -> LandOnRover:
    config = ctx.config
    if params.use_marker:
        camera_of(ctx, config.rover.camera, "rover.camera")
    settings = LandOnRoverSettings(tuple(config.rover.deck_size_m), config.rover.deck_height_m)
    if params.strategy == "seed004":
        return Seed004LandOnRover(params, settings, config.control.trajectory.seed004_pid)
    return LandOnRover(params, settings)


def _spec(params: LandOnRoverParams, config):
    return (deck_spec(config, params.use_uwb, params.use_marker, params.strategy),)


def _check(params: LandOnRoverParams, config) -> None:
    if params.commit_height_m >= params.approach_height_m:
        raise ValueError(f"commit_height_m ({params.commit_height_m}) must be below "
                         f"approach_height_m ({params.approach_height_m})")
    if params.touchdown_height_m >= params.commit_height_m:
        raise ValueError(f"touchdown_height_m ({params.touchdown_height_m}) must be below "
                         f"commit_height_m ({params.commit_height_m})")
    if params.use_marker and config.rover.camera not in config.vehicle.cameras:
        raise ValueError(f"use_marker: the deck's tag is read by rover.camera "
                         f"{config.rover.camera!r}, which the vehicle does not have")


def _interp(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, times, values[:, i]) for i in range(values.shape[1])],
                    axis=1)


def landing_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                    step: Mapping) -> dict:
    pipelines = step.get("pipelines") or []
    if not pipelines or not intervals:
        return {}
    p = pipelines[0]
    body = p.get("truth_body") or ROVER_BODY
    params = LandOnRoverParams(**step["params"])
    start, end = intervals[0][0], intervals[-1][1]
    succeeded = any(e.get("kind") == "step_succeeded" and e.get("step_index") == step["index"]
                    for e in log.get(ch.MISSION_EVENTS, []))
    until = end + 2.0 if succeeded else math.inf
    truth = [s for s in log.get(ch.GROUND_TRUTH, [])
             if body in s["bodies"] and start <= s["time_s"] <= until]
    if len(truth) < 2:
        return {}
    config = _config(log)
    deck_l, deck_w = config.get("deck_size_m", (1.0, 0.8))
    t = np.array([s["time_s"] for s in truth])
    drone = np.array([s["vehicle_position_ned_m"] for s in truth], dtype=float)
    drone_v = np.array([s["vehicle_velocity_ned_m_s"] for s in truth], dtype=float)
    deck = np.array([s["bodies"][body]["position_ned_m"] for s in truth], dtype=float)
    deck_v = np.array([s["bodies"][body]["velocity_ned_m_s"] for s in truth], dtype=float)
    yaw = np.array([_yaw_of(s["bodies"][body]["attitude_q"]) for s in truth])
    rel = drone - deck
    rel_v = drone_v - deck_v
    # in the rover's axes (along, across)
    c, s_ = np.cos(yaw), np.sin(yaw)
    along = c * rel[:, 0] + s_ * rel[:, 1]
    across = -s_ * rel[:, 0] + c * rel[:, 1]
    height = -rel[:, 2]
    phases = [r.get("phase") for r in log.get(ch.SETPOINTS, [])
              if start <= r["time_s"] <= end and r.get("step") == step["name"]]
    retries = sum(1 for a, b in itertools.pairwise(phases)
                  if b == "aborting" and a != "aborting")
    landing: dict = {
        "landed": succeeded, "on_deck": False, "error_m": None, "error_deck_m": None,
        "rest_error_m": None, "relative_speed_m_s": None,
        "relative_horizontal_speed_m_s": None, "time_to_land_s": None, "retries": retries,
        "rover_speed_m_s": float(np.hypot(*deck_v[-1][:2])),
        "use_uwb": params.use_uwb, "use_marker": params.use_marker}
    rest_h = float(height[-1])
    still = float(np.linalg.norm(rel_v[-1])) < 0.1
    inside = abs(float(along[-1])) <= deck_l / 2.0 and abs(float(across[-1])) <= deck_w / 2.0
    on_deck = still and inside and 0.0 < rest_h < 0.3
    if on_deck:
        k = len(height) - 1
        while k > 0 and height[k - 1] <= rest_h + _REST_BAND_M:
            k -= 1
        before = (t >= t[k] - 0.3) & (t <= t[k])
        landing.update({
            "on_deck": True,
            "error_m": float(math.hypot(along[k], across[k])),
            "error_deck_m": [float(along[k]), float(across[k])],
            "rest_error_m": float(math.hypot(along[-1], across[-1])),
            "relative_speed_m_s": float(np.max(np.linalg.norm(rel_v[before], axis=1))),
            "relative_horizontal_speed_m_s": float(np.max(np.linalg.norm(
                rel_v[before][:, :2], axis=1))),
            "time_to_land_s": float(t[k] - start)})
    out = {"landing": landing}
    rel_metrics = relative_metrics(log, intervals, p["name"], t, rel)
    if rel_metrics:
        out["relative"] = rel_metrics
    return out


def _config(log: Mapping[str, Sequence[Mapping]]) -> dict:
    plans = log.get(ch.MISSION_PLAN, [])
    if not plans:
        return {}
    return (plans[-1].get("config") or {}).get("rover") or {}


def relative_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                     pipeline: str, truth_t: np.ndarray, truth_rel: np.ndarray) -> dict:
    """The relative estimate flown on (see the module's notes) against the truth."""
    start, end = intervals[0][0], intervals[-1][1]
    states = [r for r in log.get(ch.VEHICLE_STATE, [])]
    ticks = [r for r in log.get(ch.CONTROL_TARGET, [])
             if r.get("pipeline") == pipeline and any(a <= r["time_s"] <= b
                                                      for a, b in intervals)]
    if not ticks or len(states) < 2:
        return {}
    usable = [r for r in ticks if r.get("present") and not r.get("stale")]
    out: dict = {"ticks": len(ticks), "lost_share": 1.0 - len(usable) / len(ticks)}
    if usable:
        st = np.array([r["time_s"] for r in states])
        sp = np.array([r["position_ned_m"] for r in states], dtype=float)
        tt = np.array([r["time_s"] for r in usable])
        covered = (tt >= truth_t[0]) & (tt <= truth_t[-1]) & (tt >= st[0])
        tt = tt[covered]
        rows = [r for r, c in zip(usable, covered, strict=True) if c]
        if len(rows):
            # the drone's own estimate at each tick (its telemetry carried to the tick)
            own = _interp(tt, st, sp)
            deck = np.array([r["position_ned_m"] for r in rows], dtype=float)
            est = own - deck
            true = _interp(tt, truth_t, truth_rel)
            err = est - true
            std = np.array([r["position_std_m"] for r in rows], dtype=float)
            horiz = np.hypot(err[:, 0], err[:, 1])
            within = (np.abs(err[:, 0]) <= 2.0 * std[:, 0]) & \
                (np.abs(err[:, 1]) <= 2.0 * std[:, 1])
            out.update({
                "rms_horizontal_error_m": float(np.sqrt(np.mean(horiz ** 2))),
                "p95_horizontal_error_m": float(np.percentile(horiz, 95)),
                "max_horizontal_error_m": float(np.max(horiz)),
                "rms_vertical_error_m": float(np.sqrt(np.mean(err[:, 2] ** 2))),
                "within_2sigma": float(np.mean(within)),
                "final_horizontal_error_m": float(horiz[-1])})
    records = [r for r in log.get(ch.RELATIVE_ESTIMATES, [])
               if r.get("pipeline") == pipeline and r.get("accepted")]
    grid = np.arange(start, end, 0.1)
    availability = {}
    for source in SOURCES:
        times = np.array(sorted(r["measurement_time_s"] for r in records
                                if r.get("source") == source))
        if not len(times) or not len(grid):
            availability[source] = 0.0
            continue
        idx = np.searchsorted(times, grid, side="right") - 1
        fresh = (idx >= 0) & (grid - times[np.maximum(idx, 0)] <= 0.5)
        availability[source] = float(np.mean(fresh))
    out["availability"] = availability
    out["updates"] = {source: sum(1 for r in records if r.get("source") == source)
                      for source in SOURCES}
    return out


def relative_tracks(log: Mapping[str, Sequence[Mapping]], body: str = ROVER_BODY) -> dict | None:
    """What the report's rover panel draws: the drone relative to the deck in the rover's axes
    (along, across, height above the deck) — truth, and the estimate flown on — and the
    relative filter's updates per source with their horizontal error against truth."""
    truth = [s for s in log.get(ch.GROUND_TRUTH, []) if body in s.get("bodies", {})]
    if len(truth) < 2:
        return None
    t = np.array([s["time_s"] for s in truth])
    rel = np.array([np.subtract(s["vehicle_position_ned_m"],
                                s["bodies"][body]["position_ned_m"]) for s in truth])
    yaw = np.array([_yaw_of(s["bodies"][body]["attitude_q"]) for s in truth])

    def axes(r: np.ndarray, psi: np.ndarray) -> np.ndarray:
        c, s_ = np.cos(psi), np.sin(psi)
        return np.column_stack((c * r[:, 0] + s_ * r[:, 1], -s_ * r[:, 0] + c * r[:, 1],
                                -r[:, 2]))

    out: dict = {"deck_size_m": tuple(_config(log).get("deck_size_m", (1.0, 0.8))),
                 "truth": axes(rel, yaw)}
    states = log.get(ch.VEHICLE_STATE, [])
    ticks = [r for r in log.get(ch.CONTROL_TARGET, [])
             if r.get("present") and str(r.get("pipeline", "")).startswith("deck")]
    flown = np.zeros((0, 3))
    if ticks and len(states) >= 2:
        st = np.array([r["time_s"] for r in states])
        sp = np.array([r["position_ned_m"] for r in states], dtype=float)
        tt = np.array([r["time_s"] for r in ticks])
        keep = (tt >= max(st[0], t[0])) & (tt <= t[-1])
        if keep.any():
            tt = tt[keep]
            deck = np.array([r["position_ned_m"] for r, k in zip(ticks, keep, strict=True)
                             if k], dtype=float)
            flown = axes(_interp(tt, st, sp) - deck, np.interp(tt, t, np.unwrap(yaw)))
    out["flown"] = flown
    updates, rejected = {}, {}
    records = [r for r in log.get(ch.RELATIVE_ESTIMATES, []) if t[0] <= r["time_s"] <= t[-1]]
    for source in SOURCES:
        rows = [r for r in records if r.get("source") == source and r.get("accepted")]
        times = np.array([r["time_s"] for r in rows])
        if len(rows):
            est = np.array([r["relative_position_m"] for r in rows], dtype=float)
            true = _interp(times, t, rel)
            error = np.hypot(est[:, 0] - true[:, 0], est[:, 1] - true[:, 1])
        else:
            error = np.zeros(0)
        updates[source] = {"t": times, "error_m": np.maximum(error, 1e-4)}
        rejected[source] = np.array([r["measurement_time_s"] for r in records
                                     if r.get("source") == source and not r.get("accepted")])
    out["updates"], out["rejected"] = updates, rejected
    sig = [r for r in records if r.get("accepted")]
    out["sigma_t"] = np.array([r["time_s"] for r in sig])
    out["two_sigma_m"] = np.array([2.0 * max(r["position_std_m"][0], r["position_std_m"][1])
                                   for r in sig]) if sig else np.zeros(0)
    return out


register(StepKind(
    "land_on_rover", LandOnRoverParams, _behavior, pipelines=_spec, metrics=landing_metrics,
    report=("trajectory", "rover", "latency"), check=_check,
    description="land on a moving rover's deck: UWB, its tag and its reports fused "
                "(seed 004)",
    status=(8, 9)))
