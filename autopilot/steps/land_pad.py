"""The ``land_pad`` step kind: precision landing on a pad seen by the down camera (seed 001).

Its behaviour is :class:`~autopilot.behaviors.land_pad.LandPad`, its pipeline the pad pipeline
(:mod:`autopilot.perception.pad_pipeline`) on ``perception.pad.camera``. Its metrics
(``metrics.landing``) score where the vehicle truly came to rest against the pad's true centre
(simulator ground truth), how fast it touched down, how long it took and how many times it had
to climb and look again; ``metrics.estimation`` scores the pad estimate it flew on.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.behaviors.base import Behavior
from autopilot.behaviors.land_pad import LandPad, LandPadParams, LandPadSettings
from autopilot.behaviors.land_pad_seed001 import Seed001LandPad
from autopilot.config import ConfigError, Problem
from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import FollowedTarget, estimation_metrics, phase_entries
from autopilot.flightlog.truth import truth_table
from autopilot.perception.pad_pipeline import pad_spec
from autopilot.planning.footprint import footprint_width_per_m
from autopilot.status import register_status
from autopilot.steps.follow_ball import camera_of
from autopilot.steps.registry import (
    ESTIMATE_FIGURES,
    LANDING_REPLAY_KEYS,
    Figure,
    StepContext,
    StepKind,
    register,
)

#: resting: within this of the height the vehicle finally rests at
_REST_BAND_M = 0.015


def search_footprint_per_m(ctx: StepContext, name: str, key: str) -> float:
    """The width of ground camera ``name`` sees under the vehicle per metre of height, what a
    down-camera step's search spaces its rings by; a camera that does not see the ground under
    the vehicle cannot search."""
    camera = camera_of(ctx, name, key)
    width = footprint_width_per_m(camera.intrinsics, camera.rotation_body_cam,
                                  camera.position_body_m)
    if width <= 0.0:
        raise ConfigError([Problem("config", None, key,
                                   f"camera {name!r} does not see the ground under the vehicle "
                                   "(a down-camera step searches with it)")])
    return width


#: a search stays this far below the vehicle's own ceiling (``vehicle.max_altitude_m``)
CEILING_MARGIN_M = 0.2


def search_altitude_m(requested_m: float, config) -> float:
    """The height a down-camera step searches at: as asked, but below the vehicle's own
    ceiling (an AR.Drone's ``control:altitude_max``), which it could never climb to."""
    ceiling = config.vehicle.max_altitude_m
    if ceiling is None:
        return requested_m
    return min(requested_m, ceiling - CEILING_MARGIN_M)


def search_warnings(params, config) -> tuple[str, ...]:
    """A search asked above the vehicle's ceiling, said before the flight."""
    used = search_altitude_m(params.search_altitude_m, config)
    if used >= params.search_altitude_m:
        return ()
    return (f"search_altitude_m {params.search_altitude_m:g} m is above the vehicle's ceiling "
            f"(vehicle.max_altitude_m {config.vehicle.max_altitude_m:g} m): it searches at "
            f"{used:g} m, seeing less of the ground",)


def within_ceiling(params, config):
    """``params`` with the search altitude the vehicle can reach."""
    used = search_altitude_m(params.search_altitude_m, config)
    if used == params.search_altitude_m:
        return params
    return params.model_copy(update={"search_altitude_m": used})


#: the step's landers (``lander``): ours, and seed 001's own logic (a baseline)
LANDERS = {
    "ours": lambda params, settings, camera: LandPad(params, settings),
    "seed001": Seed001LandPad,
}


def _behavior(params: LandPadParams, ctx: StepContext) -> Behavior:
    config = ctx.config
    camera = camera_of(ctx, config.perception.pad.camera, "perception.pad.camera")
    footprint = search_footprint_per_m(ctx, config.perception.pad.camera,
                                       "perception.pad.camera")
    settings = LandPadSettings(config.control.follow.lost_after_s, footprint)
    return LANDERS[params.lander](within_ceiling(params, config), settings, camera)


def _spec(params: LandPadParams, config):
    if params.lander == "seed001" and params.method == "vehicle_precland":
        raise ValueError("lander: seed001 lands with its own logic: method vehicle_precland "
                         "(px4_precland) does not apply (use method: offboard)")
    if config.perception.pad.detector == "seed001" and params.pad != "circle":
        raise ValueError(f"pad: {params.pad} cannot be found by perception.pad.detector "
                         "seed001 (template matching of a disc): use a circle pad or the "
                         "detector 'ours'")
    return (pad_spec(config, params.pad, params.size_m, color=params.color, ids=params.ids),)


def landing_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                    step: Mapping) -> dict:
    """``landing``: whether the step landed (``landed``); where the vehicle came to rest on the
    ground — after the step's landing, or after the mission's fallback when the step failed —
    as the true resting point's horizontal distance from the pad's true centre (``error_m``)
    and whether that is on the pad; the descent speed at touchdown, the time from the step's
    start to touchdown, the climbs to look again (``retries``); detection figures.
    ``estimation``: the pad estimate flown on, against truth."""
    pipelines = step.get("pipelines") or []
    if not pipelines or not intervals:
        return {}
    p = pipelines[0]
    params = LandPadParams(**step["params"])
    body = p["truth_body"]
    start, end = intervals[0][0], intervals[-1][1]
    succeeded = any(e.get("kind") == "step_succeeded" and e.get("step_index") == step["index"]
                    for e in log.get(ch.MISSION_EVENTS, []))
    # where the vehicle came to rest: after its own landing, or after what the mission did
    # when the step failed (its fallback's landing): to the end of the log
    until = end + 0.5 if succeeded else math.inf
    track = truth_table(log).body(body)
    truth = track.window((track.t >= start) & (track.t <= until))
    if not len(truth):
        return {}
    frames = detected = 0
    first_found = None
    times_ms = array("d")
    for f in log.get(ch.detection_topic(p["name"]), []):
        if start <= f["time_s"] <= end:
            frames += 1
            if f["detected"]:
                detected += 1
                first_found = f["time_s"] if first_found is None else first_found
            if f.get("processing_ms") is not None:
                times_ms.append(f["processing_ms"])
    retries = phase_entries(log.get(ch.SETPOINTS, []), step["name"], start, end, "reacquiring")
    z = truth.vehicle_p[:, 2]
    t = truth.t
    vz = truth.vehicle_v[:, 2]
    rest_z = float(z[-1])
    landing: dict = {
        "landed": False, "error_m": None, "on_pad": False, "touchdown_speed_m_s": None,
        "touchdown_horizontal_speed_m_s": None, "time_to_land_s": None, "retries": retries,
        "found_after_s": (first_found - start) if first_found is not None else None,
        "frames": frames, "detected_frames": detected,
        "time_per_frame_ms_p50": float(np.percentile(times_ms, 50)) if times_ms else None,
        "time_per_frame_ms_p95": float(np.percentile(times_ms, 95)) if times_ms else None,
    }
    still = abs(float(vz[-1])) < 0.05 and float(np.hypot(*truth.vehicle_v[-1, :2])) < 0.05
    pad_down = float(truth.p[-1, 2])
    on_ground = still and abs(rest_z - pad_down) < 0.3
    if on_ground:
        k = len(z) - 1
        while k > 0 and z[k - 1] >= rest_z - _REST_BAND_M:
            k -= 1
        before = (t >= t[k] - 0.3) & (t <= t[k])
        rest = truth.vehicle_p[-1]
        pad = truth.p[-1]
        error = float(np.hypot(*(rest[:2] - pad[:2])))
        vh = [float(np.hypot(*v[:2])) for v in truth.vehicle_v[before]]
        landing.update({
            "landed": succeeded, "error_m": error, "on_pad": error <= params.size_m / 2.0,
            "touchdown_speed_m_s": float(np.max(vz[before])) if before.any() else None,
            "touchdown_horizontal_speed_m_s": max(vh) if vh else None,
            "time_to_land_s": float(t[k] - start)})
    target = FollowedTarget(p["name"], p["camera"], body, p["size_m"], 0.0)
    return {"landing": landing, "estimation": estimation_metrics(log, intervals, target)}


#: its status codes (autopilot.status)
IN_PROGRESS = register_status(19, "land pad in progress")
COMPLETED = register_status(20, "land pad completed", stays_landed=True)

register(StepKind(
    "land_pad", LandPadParams, _behavior, pipelines=_spec, metrics=landing_metrics,
    warnings=search_warnings,
    needs=lambda params, config: ("precision_landing",) if params.method == "vehicle_precland"
    else (),
    summary=((Figure("landing", "on_pad", "on the pad"),
              Figure("landing", "error_m", "touchdown error", "m"),
              Figure("landing", "touchdown_speed_m_s", "touchdown speed", "m/s"),
              Figure("landing", "time_to_land_s", "time to land", "s"),
              Figure("landing", "retries", "retries")), ESTIMATE_FIGURES),
    report=("trajectory", "over_target", "detections", "estimate", "latency"),
    description="search for a landing pad with the down camera, descend onto it, disarm",
    replay={"landing": LANDING_REPLAY_KEYS},
    status=(int(IN_PROGRESS), int(COMPLETED))))
