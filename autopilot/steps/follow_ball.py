"""The ``follow_ball`` step kind: follow a coloured ball with a camera (seeds 001 and 003).

Its behaviour is :class:`~autopilot.behaviors.follow_ball.FollowBall`, its pipeline the ball
pipeline on ``perception.ball.camera``, its metrics the follow and estimation figures of
:mod:`autopilot.flightlog.metrics` against the simulated ball's ground truth.
"""

from __future__ import annotations

import math

from autopilot.behaviors.follow_ball import FollowBall, FollowBallParams, LostTargetSettings
from autopilot.config import AppConfig, ConfigError, Problem
from autopilot.control.follow import FollowSettings
from autopilot.flightlog.metrics import follow_step_metrics
from autopilot.perception.ball_pipeline import ball_spec
from autopilot.status import register_status
from autopilot.steps.registry import (
    ESTIMATE_FIGURES,
    FOLLOW_REPLAY_KEYS,
    Figure,
    StepContext,
    StepKind,
    register,
)


def follow_settings(config: AppConfig, mode: str | None, standoff_m: float | None
                    ) -> FollowSettings:
    f = config.control.follow
    return FollowSettings(
        mode=mode or f.mode,
        standoff_m=standoff_m or f.standoff_m,
        position_gain=f.position_gain,
        max_speed_m_s=f.max_speed_m_s,
        max_vertical_speed_m_s=f.max_vertical_speed_m_s,
        max_accel_m_s2=f.max_accel_m_s2,
        max_yaw_rate_rad_s=math.radians(f.max_yaw_rate_deg_s),
        altitude_floor_m=f.altitude_floor_m,
        accel_lead_s=f.accel_lead_s,
        accel_filter_s=f.accel_filter_s,
        sideways_feedforward=f.sideways_feedforward,
        yaw_tracked_bearing_rate_rad_s=math.radians(f.yaw_tracked_bearing_rate_deg_s),
        intercept_horizon_s=f.intercept_horizon_s,
        yaw_lead_s=f.yaw_lead_s,
    )


def lost_settings(config: AppConfig) -> LostTargetSettings:
    f = config.control.follow
    return LostTargetSettings(f.lost_after_s, f.lost_hold_s,
                              math.radians(f.search_yaw_rate_deg_s), f.lost_timeout_s,
                              f.lost_coast_s)


def camera_of(ctx: StepContext, name: str, key: str):
    if name not in ctx.cameras:
        raise ConfigError([Problem("config", None, key,
                                   f"the vehicle has no camera {name!r} "
                                   f"(it has {', '.join(ctx.cameras) or 'none'})")])
    return ctx.cameras[name]


def _behavior(params: FollowBallParams, ctx: StepContext) -> FollowBall:
    config = ctx.config
    camera = camera_of(ctx, config.perception.ball.camera, "perception.ball.camera")
    return FollowBall(params, follow_settings(config, params.mode, params.standoff_m),
                      lost_settings(config), camera, config.perception.ball.diameter_m)


def _plan_info(params: FollowBallParams, config: AppConfig) -> dict:
    return {"standoff_m": params.standoff_m or config.control.follow.standoff_m}


#: its status codes (autopilot.status)
IN_PROGRESS = register_status(13, "follow ball in progress")
COMPLETED = register_status(14, "follow ball completed")

register(StepKind(
    "follow_ball", FollowBallParams, _behavior,
    pipelines=lambda params, config: (ball_spec(config),),
    metrics=follow_step_metrics,
    summary=((Figure("follow", "detection_rate", "detected in", "%"),
              Figure("follow", "rms_range_error_m", "range error RMS", "m"),
              Figure("follow", "p95_abs_range_error_m", "p95", "m"),
              Figure("follow", "rms_image_error_px", "image error RMS", "px"),
              Figure("follow", "max_lost_s", "longest loss", "s")), ESTIMATE_FIGURES),
    report=("trajectory", "standoff", "detections", "estimate", "velocity", "latency"),
    plan_info=_plan_info,
    description="follow a coloured ball with a camera for duration_s",
    replay={"follow": FOLLOW_REPLAY_KEYS},
    status=(int(IN_PROGRESS), int(COMPLETED))))
