"""Honest metrics: the estimate scored is the one the behaviour flew on (coasting and lost ticks
included), a target out of view or behind the camera is the image error's worst case, and a
step's interval comes from structured events."""

import math

import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import estimation_metrics, follow_metrics, step_intervals
from autopilot.steps.metrics import mission_metrics
from tests.factories import front_camera

BALL = {"name": "ball", "kind": "ball", "camera": "front", "truth_body": "ball", "size_m": 0.2}


def _events():
    def ev(t, kind, index, step):
        return {"time_s": t, "kind": kind, "step_index": index, "step": step, "text": kind}
    return [ev(0.0, "step_started", 0, "takeoff"), ev(1.0, "step_succeeded", 0, "takeoff"),
            ev(1.0, "step_started", 1, "follow_ball"), ev(5.0, "step_succeeded", 1, "follow_ball"),
            ev(5.0, "step_started", 2, "land")]


def _log(ball_north=lambda t: 2.0):
    """The vehicle hovers at the origin facing north; the ball is ``ball_north(t)`` ahead."""
    recs = {ch.MISSION_PLAN: [{"steps": [
                {"name": "takeoff", "index": 0, "params": {}, "pipelines": []},
                {"name": "follow_ball", "index": 1, "params": {"duration_s": 4},
                 "pipelines": [BALL], "standoff_m": 2.0},
                {"name": "land", "index": 2, "params": {}, "pipelines": []}]}],
            ch.CAMERA_INFO: [ch.clean(ch.camera_info_record(front_camera()))],
            ch.MISSION_EVENTS: _events(), ch.GROUND_TRUTH: [], ch.CONTROL_TARGET: [],
            ch.detection_topic("ball"): []}
    for k in range(61):
        t = 0.1 * k
        recs[ch.GROUND_TRUTH].append({
            "time_s": t, "vehicle_position_ned_m": [0, 0, -2], "vehicle_attitude_q": [1, 0, 0, 0],
            "bodies": {"ball": {"position_ned_m": [ball_north(t), 0, -2],
                                "velocity_ned_m_s": [0, 0, 0]}}})
        recs[ch.detection_topic("ball")].append({
            "time_s": t, "camera": "front", "detected": ball_north(t) > 0,
            "u_px": 319.5, "v_px": 239.5})
    return recs


def test_step_intervals_come_from_structured_events():
    events = _events()
    assert step_intervals(events, 9.0, step_index=1) == [(1.0, 5.0)]
    assert step_intervals(events, 9.0, step="land") == [(5.0, 9.0)]
    aborted = [*events[:3], {"time_s": 2.5, "kind": "aborted", "step_index": -1, "step": "",
                             "text": "aborted: SIGINT"}]
    assert step_intervals(aborted, 9.0, step_index=1) == [(1.0, 2.5)]


def test_a_target_behind_the_camera_counts_as_the_worst_image_error():
    centred = follow_metrics(_log())
    assert centred["rms_image_error_px"] == pytest.approx(0.0, abs=1e-6)
    assert centred["detection_rate"] == 1.0
    # half the step with the ball behind the vehicle: those frames count as the half-diagonal
    behind = follow_metrics(_log(lambda t: 2.0 if t < 3.0 else -2.0))
    frames = [0.1 * k for k in range(61) if 1.0 <= 0.1 * k <= 5.0]
    share = sum(t >= 3.0 for t in frames) / len(frames)
    half_diagonal = 0.5 * math.hypot(640, 480)
    assert behind["rms_image_error_px"] == pytest.approx(half_diagonal * math.sqrt(share))
    assert behind["frames_in_view"] == len(frames) - sum(t >= 3.0 for t in frames)


def test_detections_are_scored_against_the_camera_as_it_really_was():
    """The realistic world's camera is mounted off its nominal angles (its frames report the
    nominal mount): a detection where the ball really appeared is a hit, scored through the
    true mount the simulator logs, not a miss against the nominal one."""
    import dataclasses

    import cv2
    import numpy as np

    nominal = front_camera()
    off = cv2.Rodrigues(np.radians([0.0, 3.0, 0.0]))[0]  # 3° about the optical y axis
    true = dataclasses.replace(nominal, rotation_body_cam=nominal.rotation_body_cam @ off)
    log = _log()
    p_cam = off.T @ np.array([0.0, 0.0, 2.0])  # the ball, 2 m ahead, in the true optical frame
    u = nominal.intrinsics.fx * p_cam[0] / p_cam[2] + nominal.intrinsics.cx
    for rec in log[ch.detection_topic("ball")]:
        rec["u_px"] = float(u)  # where the ball really is in the image: ~17 px off centre
    assert abs(u - 319.5) > 10
    assert follow_metrics(log)["detection_rate"] == 0.0  # judged with the nominal mount
    log[ch.CAMERA_TRUTH] = [ch.clean(ch.camera_info_record(true))]
    assert follow_metrics(log)["detection_rate"] == 1.0  # with the true one


def _tick(t, north, *, present=True, age=0.0, stale=False, std=0.05):
    record = {"time_s": t, "pipeline": "ball", "step": "follow_ball", "step_index": 1,
              "present": present}
    if present:
        record.update(position_ned_m=[north, 0, -2], velocity_ned_m_s=[0, 0, 0],
                      position_std_m=[std] * 3, age_s=age, stale=stale, confirmed=True)
    return record


def test_the_estimate_is_scored_as_flown_coasting_and_lost_included():
    log = _log()
    log[ch.CONTROL_TARGET] = (
        [_tick(1.0 + 0.05 * k, 2.01) for k in range(40)]  # tracking, 1 cm off
        + [_tick(3.0 + 0.05 * k, 2.3, age=0.2 + 0.05 * k) for k in range(20)]  # coasting
        + [_tick(4.0 + 0.05 * k, 0.0, present=False) for k in range(20)])  # lost
    e = estimation_metrics(log)
    assert e["ticks"] == 80
    assert e["lost_share"] == pytest.approx(0.25)
    assert e["coasting_share"] == pytest.approx(0.25)
    assert e["rms_position_error_coasting_m"] == pytest.approx(0.3)
    assert e["rms_position_error_m"] == pytest.approx(math.sqrt((40 * 0.01**2 + 20 * 0.3**2) / 60))
    # the coasting ticks' 0.3 m errors are outside their 2σ (0.1 m)
    assert e["within_2sigma"] == pytest.approx(40 / 60)
    summary = mission_metrics(log)
    assert summary["estimation"]["ticks"] == 80
    assert [s["name"] for s in summary["steps"]] == ["follow_ball"]


def test_cross_track_against_the_vehicles_navigation_and_against_truth():
    """The vehicle tracks a straight path exactly as its navigation sees it, while that
    navigation is 0.4 m off to the east: the cross-track error is 0 against its navigation and
    0.4 m against the truth, and the navigation's error is reported."""
    from autopilot.steps.trajectory import path_metrics

    recs = {ch.PLANNED_PATH: [{"time_s": 0.0, "step_index": 1,
                               "points_ned_m": [[0, 0, -3], [10, 0, -3]]}],
            ch.GROUND_TRUTH: [], ch.VEHICLE_STATE: []}
    for k in range(101):
        t = 0.1 * k
        recs[ch.GROUND_TRUTH].append({
            "time_s": t, "vehicle_position_ned_m": [t, -0.4, -3],
            "vehicle_attitude_q": [1, 0, 0, 0], "vehicle_velocity_ned_m_s": [1, 0, 0],
            "bodies": {}})
        recs[ch.VEHICLE_STATE].append({"time_s": t, "position_ned_m": [t, 0.0, -3]})
    out, _, _ = path_metrics(recs, [(0.0, 10.0)], {"index": 1})
    assert out["rms_cross_track_nav_m"] == pytest.approx(0.0, abs=1e-6)
    assert out["rms_cross_track_m"] == pytest.approx(0.4, abs=1e-6)
    assert out["rms_navigation_error_m"] == pytest.approx(0.4, abs=1e-6)


def test_an_estimate_in_the_navigations_frame_is_also_scored_relative_to_the_vehicle():
    """The navigation puts the vehicle 0.3 m north of where it is, so the ball (seen exactly)
    is placed 0.3 m north of the truth: 0.3 m absolute error, none relative to the vehicle."""
    log = _log()
    log[ch.VEHICLE_STATE] = [{"time_s": 0.1 * k, "position_ned_m": [0.3, 0, -2]}
                             for k in range(61)]
    log[ch.CONTROL_TARGET] = [_tick(1.0 + 0.05 * k, 2.3) for k in range(80)]
    e = estimation_metrics(log)
    assert e["rms_position_error_m"] == pytest.approx(0.3)
    assert e["rms_relative_position_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert "relative_within_2sigma" not in e  # (the log does not say the navigation's σ)
    # σ 0.05 m of which the navigation's position is 0.045: 0.022 m relative; 5 cm off
    log[ch.MISSION_PLAN][0]["config"] = {"estimation": {"navigation": {
        "position_std_m": 0.045, "height_std_m": 0.045}}}
    log[ch.CONTROL_TARGET] = [_tick(1.0 + 0.05 * k, 2.35 if k % 2 else 2.3)
                              for k in range(80)]
    e = estimation_metrics(log)
    assert e["relative_within_2sigma"] == pytest.approx(0.5)
