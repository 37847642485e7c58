"""Onboard-video overlays: what is drawn where, from the log's records."""

import math

import numpy as np
import pytest

from autopilot.flightlog import records as ch
from autopilot.report.video import (
    GREEN,
    RED,
    YELLOW,
    Overlay,
    OverlaySource,
    draw_overlay,
    project_with_covariance,
)
from tests.factories import front_camera, vehicle_state

CAM = ch.camera_info_record(front_camera())


def _blank():
    return np.full((480, 640, 3), 128, np.uint8)


def _near(image, colour, u, v, radius=3):
    patch = image[max(0, v - radius):v + radius + 1, max(0, u - radius):u + radius + 1]
    return bool(np.any(np.all(patch == np.array(colour, np.uint8), axis=-1)))


def test_a_point_ahead_projects_to_the_centre_with_its_2_sigma_ellipse():
    state = vehicle_state(pos=(0.0, 0.0, -2.0))
    # 4 m north of a north-facing camera, 0.1 m std in every direction
    (u, v), ellipse = project_with_covariance(CAM, state.position_ned_m, state.attitude_q,
                                              np.array([4.0, 0.0, -2.0]), np.eye(3) * 0.01)
    assert (u, v) == pytest.approx((319.5, 239.5))
    # across the line of sight: 2σ = 0.2 m at 4 m depth → 320 px/m × 0.05 = 16 px
    assert ellipse.half_axes_px == pytest.approx((16.0, 16.0))
    # an uncertainty along one axis only: a line-like ellipse along the image's x axis
    _, flat = project_with_covariance(CAM, state.position_ned_m, state.attitude_q,
                                      np.array([4.0, 0.0, -2.0]), np.diag([0.0, 0.04, 0.0]))
    assert flat.half_axes_px == pytest.approx((32.0, 0.0), abs=1e-6)
    assert flat.angle_deg % 180 == pytest.approx(0.0, abs=1e-6)
    behind = project_with_covariance(CAM, state.position_ned_m, state.attitude_q,
                                     np.array([-4.0, 0.0, -2.0]), np.eye(3) * 0.01)
    assert behind is None


def test_drawing_puts_each_element_where_it_belongs():
    overlay = Overlay(time_s=12.5, step="follow_ball", phase="tracking",
                      detection_px=(400.0, 200.0, 20.0), estimate_px=(100.0, 300.0),
                      command_frd_m_s=(2.0, 0.0, 0.0), command_yaw_rate_deg_s=10.0,
                      panel=(("mode", "offboard"),))
    image = _blank()
    out = draw_overlay(image, overlay)
    assert np.all(image == 128)  # the frame itself is not touched
    assert _near(out, GREEN, 420, 200)  # the detection's circle, at its radius
    assert _near(out, YELLOW, 100, 300)  # the estimate's marker
    # 2 m/s forward: an arrow up the image from the bottom centre (25 px per m/s)
    assert _near(out, RED, 320, 440 - 25)
    assert not _near(out, RED, 320 + 50, 440)
    assert np.any(out[5:25, 5:200] != 128)  # time, step and phase
    assert np.any(out[30:50, 5:120] != 128)  # the name::value panel
    # nothing is drawn where nothing was asked for
    assert np.all(draw_overlay(image, Overlay(time_s=0.0))[60:400, 200:600] == 128)


def _records():
    state = ch.vehicle_state_record(vehicle_state(0.0, pos=(0.0, 0.0, -2.0), yaw=math.pi / 2))
    later = dict(state, time_s=1.0)
    return {
        ch.CAMERA_INFO: [CAM],
        ch.VEHICLE_STATE: [state, later],
        ch.detection_topic("ball"): [{
                              "time_s": 0.5, "camera": "front", "detected": True, "u_px": 300.0,
                              "v_px": 240.0, "radius_px": 16.0, "score": 0.9, "range_m": 4.0,
                              "hint_u_px": 310.0, "hint_v_px": 240.0, "hint_radius_px": 15.0}],
        # the target 4 m east (the vehicle faces east), moving 1 m/s further east
        ch.TARGET_ESTIMATES: [{"time_s": 0.4, "position_ned_m": [0.0, 4.0, -2.0],
                               "velocity_ned_m_s": [0.0, 1.0, 0.0],
                               "position_std_m": [0.05] * 3, "velocity_std_m_s": [0.1] * 3,
                               "position_cov_m2": (np.eye(3) * 0.0025).ravel().tolist()}],
        ch.SETPOINTS: [{"time_s": 0.3, "frame": "local_ned", "velocity_m_s": [0.0, 1.0, 0.0],
                        "yaw_rate_rad_s": None, "step": "follow_ball", "phase": "tracking",
                        "latency_ms": 36.0}],
        ch.MISSION_EVENTS: [{"time_s": 0.0, "step": "follow_ball",
                             "text": "step follow_ball started"}],
    }


def test_overlay_data_comes_from_the_log_as_the_autopilot_had_it():
    overlay = OverlaySource(_records(), "front").overlay_at(0.5)
    assert overlay.detection_px == (300.0, 240.0, 16.0)
    assert overlay.hint_px == (310.0, 240.0, 15.0)
    assert (overlay.step, overlay.phase) == ("follow_ball", "tracking")
    # the estimate carried forward 0.1 s (4.1 m ahead), projected at the image centre
    assert overlay.estimate_px == pytest.approx((319.5, 239.5), abs=1e-6)
    assert overlay.estimate_ellipse.half_axes_px[0] == pytest.approx(
        2 * 320 * math.sqrt(0.0025 + 0.01 * 0.01) / 4.1, rel=1e-6)
    # a NED setpoint (1 m/s east) shown in the body frame: forward, for a vehicle facing east
    assert overlay.command_frd_m_s == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
    panel = dict(overlay.panel)
    assert panel["mode"] == "offboard"
    assert panel["latency"] == "36 ms"
    assert panel["target"].startswith("4.10 m")
    # no frame record, an estimate too old: nothing but the vehicle's own values
    late = OverlaySource(_records(), "front").overlay_at(0.99 + 1.0)
    assert late.detection_px is None
    assert late.estimate_px is None
