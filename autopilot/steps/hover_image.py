"""The ``hover_image`` step kind: hover over a known image on the ground (seed 000).

Its behaviour is :class:`~autopilot.behaviors.hover_image.HoverImage`, its pipeline the image
pipeline on ``perception.image.camera`` (the down camera), looking for the step's ``image``
(``size_m`` wide). Its metrics (``metrics.hover``) score the vehicle's true pose against the
hover point over the image's true pose (simulator ground truth), from the moment the image was
first found plus a settling time (and, as ``rms_horizontal_error_from_start_m``, from the
step's start: the approach included, so finding the image late costs), the time it took to
find it (``found_after_s``), and the detector's rate and cost.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.behaviors.hover_image import (
    HoverImage,
    HoverImageParams,
    HoverSettings,
    hover_point,
)
from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import (
    FollowedTarget,
    estimation_metrics,
    in_image,
    project_target,
    scoring_camera,
)
from autopilot.flightlog.truth import truth_table
from autopilot.perception.image_pipeline import image_spec
from autopilot.status import register_status
from autopilot.steps.land_pad import search_footprint_per_m, search_warnings, within_ceiling
from autopilot.steps.registry import (
    ESTIMATE_FIGURES,
    Figure,
    StepContext,
    StepKind,
    register,
)
from drivers.geometry import quat_to_matrix

#: scored from this long after the image was first found (the approach to the hover point)
SETTLE_S = 3.0


def _behavior(params: HoverImageParams, ctx: StepContext) -> HoverImage:
    config = ctx.config
    footprint = search_footprint_per_m(ctx, config.perception.image.camera,
                                       "perception.image.camera")
    f = config.control.follow
    return HoverImage(within_ceiling(params, config),
                      HoverSettings(f.lost_after_s, f.lost_timeout_s, footprint))


def _yaw(q) -> float:
    r = quat_to_matrix(np.asarray(q, dtype=float))
    return math.atan2(r[1, 0], r[0, 0])


def hover_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                  step: Mapping) -> dict:
    """``hover``: horizontal, vertical and yaw error of the true vehicle from the hover point
    over the true image; detection rate (frames with the image found ÷ frames with it wholly
    in view); time per frame. ``estimation``: the image estimate flown on, against truth."""
    pipelines = step.get("pipelines") or []
    if not pipelines or not intervals:
        return {}
    p = pipelines[0]
    params = HoverImageParams(**step["params"])
    body = p["truth_body"]
    truth = truth_table(log).body(body)
    if not len(truth):
        return {}
    frames = log.get(ch.detection_topic(p["name"]), [])

    def running(t: float) -> bool:
        return any(a <= t <= b for a, b in intervals)

    found = next((f["time_s"] for f in frames if f["detected"] and running(f["time_s"])), None)
    start = (found + SETTLE_S) if found is not None else None
    horizontal, vertical, yaw_errors = array("d"), array("d"), array("d")
    from_start = array("d")  # the whole step, the approach (and the search) included
    for i, t in enumerate(truth.t):
        if not running(t):
            continue
        heading = _yaw(truth.q[i])
        goal = hover_point(truth.p[i], heading, params)
        vehicle = truth.vehicle_p[i]
        from_start.append(float(np.hypot(*(vehicle[:2] - goal[:2]))))
        if start is None or t < start:
            continue
        horizontal.append(from_start[-1])
        vertical.append(float(vehicle[2] - goal[2]))
        want = heading + math.radians(params.yaw_deg)
        yaw_errors.append(math.degrees(math.remainder(_yaw(truth.vehicle_q[i]) - want,
                                                      2.0 * math.pi)))
    cam = scoring_camera(log, p["camera"])
    in_view = detected = 0
    times_ms = array("d")
    if cam is not None:
        for f in frames:
            t = f["time_s"]
            if not running(t):
                continue
            if f.get("processing_ms") is not None:
                times_ms.append(f["processing_ms"])
            i = min(int(np.searchsorted(truth.t, t)), len(truth) - 1)
            proj = project_target(cam, truth.vehicle_p[i], truth.vehicle_q[i], truth.p[i],
                                  p["size_m"] / 2.0)
            if proj is None or not in_image(cam, proj[0] - proj[2], proj[1] - proj[2]) \
                    or not in_image(cam, proj[0] + proj[2], proj[1] + proj[2]):
                continue
            in_view += 1
            detected += bool(f["detected"])

    def rms(values):
        return float(np.sqrt(np.mean(np.square(values)))) if values else None

    hover = {
        "rms_horizontal_error_from_start_m": rms(from_start),
        "rms_horizontal_error_m": rms(horizontal),
        "p95_horizontal_error_m": float(np.percentile(horizontal, 95)) if horizontal else None,
        "max_horizontal_error_m": max(horizontal) if horizontal else None,
        "rms_vertical_error_m": rms(vertical),
        "rms_yaw_error_deg": rms(yaw_errors),
        "detection_rate": detected / in_view if in_view else None,
        "frames_in_view": in_view,
        "found_after_s": (found - intervals[0][0]) if found is not None else None,
        "scored_s": (sum(b - a for a, b in intervals) - (start - intervals[0][0]))
        if start is not None else 0.0,
        "time_per_frame_ms_p50": float(np.percentile(times_ms, 50)) if times_ms else None,
        "time_per_frame_ms_p95": float(np.percentile(times_ms, 95)) if times_ms else None,
    }
    target = FollowedTarget(p["name"], p["camera"], body, p["size_m"], 0.0)
    return {"hover": hover, "estimation": estimation_metrics(log, intervals, target)}


#: its status codes (autopilot.status)
IN_PROGRESS = register_status(17, "hover image in progress")
COMPLETED = register_status(18, "hover image completed")

register(StepKind(
    "hover_image", HoverImageParams, _behavior, warnings=search_warnings,
    pipelines=lambda params, config: (image_spec(config, params.image, params.size_m),),
    metrics=hover_metrics,
    summary=((Figure("hover", "rms_horizontal_error_m", "horizontal error over the image RMS",
                     "m"),
              Figure("hover", "p95_horizontal_error_m", "p95", "m"),
              Figure("hover", "rms_vertical_error_m", "height error RMS", "m"),
              Figure("hover", "rms_yaw_error_deg", "yaw error RMS", "°"),
              Figure("hover", "detection_rate", "image found in", "%"),
              Figure("hover", "found_after_s", "first found after", "s")), ESTIMATE_FIGURES),
    report=("trajectory", "over_target", "detections", "estimate", "latency"),
    description="hover over a known image on the ground (down camera) for duration_s",
    replay={"hover": ("detection_rate", "frames_in_view", "found_after_s")},
    status=(int(IN_PROGRESS), int(COMPLETED))))
