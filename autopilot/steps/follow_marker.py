"""The ``follow_marker`` step kind: follow a fiducial marker with a camera (seed 002).

Its behaviour is :class:`~autopilot.behaviors.follow_marker.FollowMarker`, its pipeline the
marker pipeline on ``perception.marker.camera``, its metrics the follow and estimation figures
(the same keys as any followed target's) against the simulated marker board's ground truth.
"""

from __future__ import annotations

from autopilot.behaviors.follow_marker import FollowMarker, FollowMarkerParams
from autopilot.flightlog.metrics import follow_step_metrics
from autopilot.perception.marker_pipeline import marker_spec
from autopilot.status import register_status
from autopilot.steps.follow_ball import camera_of, follow_settings, lost_settings
from autopilot.steps.registry import (
    ESTIMATE_FIGURES,
    FOLLOW_REPLAY_KEYS,
    Figure,
    StepContext,
    StepKind,
    register,
)


def _behavior(params: FollowMarkerParams, ctx: StepContext) -> FollowMarker:
    config = ctx.config
    camera = camera_of(ctx, config.perception.marker.camera, "perception.marker.camera")
    return FollowMarker(params, follow_settings(config, params.mode, params.standoff_m),
                        lost_settings(config), camera)


#: its status codes (autopilot.status)
IN_PROGRESS = register_status(15, "follow marker in progress")
COMPLETED = register_status(16, "follow marker completed")

register(StepKind(
    "follow_marker", FollowMarkerParams, _behavior,
    pipelines=lambda params, config: (marker_spec(config),),
    metrics=follow_step_metrics,
    summary=((Figure("follow", "detection_rate", "detected in", "%"),
              Figure("follow", "rms_range_error_m", "range error RMS", "m"),
              Figure("follow", "p95_abs_range_error_m", "p95", "m"),
              Figure("follow", "rms_image_error_px", "image error RMS", "px"),
              Figure("follow", "max_lost_s", "longest loss", "s")), ESTIMATE_FIGURES),
    report=("trajectory", "standoff", "detections", "estimate", "velocity", "latency"),
    plan_info=lambda params, config: {"standoff_m": params.standoff_m},
    description="follow a fiducial marker (ArUco/AprilTag) at standoff_m for duration_s",
    replay={"follow": FOLLOW_REPLAY_KEYS},
    status=(int(IN_PROGRESS), int(COMPLETED))))
