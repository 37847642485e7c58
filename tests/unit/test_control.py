"""The flight stack's building blocks in isolation: limits and saturation handling."""

import math

import numpy as np
import pytest

from drivers.geometry import q_body_z, quat_from_euler, quat_rotate
from drivers.sim.flight.allocation import ControlAllocator
from drivers.sim.flight.attitude_control import AttitudeController
from drivers.sim.flight.position_control import (
    ControlSetpoint,
    PositionController,
    body_z_to_attitude,
    constrain_xy,
)
from drivers.sim.flight.rate_control import RateController

NAN = float("nan")
HOVER = 0.46


@pytest.fixture
def position_cfg(sim_config):
    return sim_config.flight_stack.position


def test_constrain_xy_keeps_position_term_first():
    # position term alone exceeds the limit: it wins, feed-forward dropped
    assert np.allclose(constrain_xy((3.0, 0.0), (0.0, 3.0), 2.0), (2.0, 0.0))
    # within the limit: plain sum
    assert np.allclose(constrain_xy((0.5, 0.0), (0.0, 0.5), 2.0), (0.5, 0.5))
    # sum exceeds: result on the limit circle, position term fully kept
    vx, vy = constrain_xy((1.0, 0.0), (0.0, 3.0), 2.0)
    assert math.hypot(vx, vy) == pytest.approx(2.0)
    assert vx == pytest.approx(1.0)


def test_hover_needs_hover_thrust(position_cfg):
    ctrl = PositionController(position_cfg, HOVER)
    sp = ControlSetpoint([0.0, 0.0, -2.0], [NAN] * 3, 0.0)
    att = ctrl.update(0.02, [0.0, 0.0, -2.0], [0.0, 0.0, 0.0], sp)
    assert att.thrust == pytest.approx(HOVER)
    assert np.allclose(q_body_z(att.q_ned_frd), (0, 0, 1))


def test_far_position_error_saturates_velocity_tilt_and_thrust(position_cfg):
    ctrl = PositionController(position_cfg, HOVER)
    sp = ControlSetpoint([1000.0, 0.0, -2.0], [NAN] * 3, 0.0)
    att = ctrl.update(0.02, [0.0, 0.0, -2.0], [0.0, 0.0, 0.0], sp)
    assert ctrl.velocity_setpoint[0] == pytest.approx(position_cfg.xy_vel_max_m_s)
    tilt = math.degrees(math.acos(q_body_z(att.q_ned_frd)[2]))
    assert tilt == pytest.approx(position_cfg.tilt_max_deg, abs=0.01)
    assert att.thrust <= position_cfg.thrust_max + 1e-9
    # tilting towards north means pitching nose down
    forward = quat_rotate(np.array(att.q_ned_frd), [1, 0, 0])
    assert forward[2] > 0


def test_vertical_priority_when_thrust_saturates(position_cfg):
    ctrl = PositionController(position_cfg, HOVER)
    # climb hard and go sideways hard at once: vertical thrust first, horizontal gets the rest
    sp = ControlSetpoint([NAN, NAN, NAN], [20.0, 0.0, -20.0], 0.0)
    ctrl.update(0.02, [0, 0, -2.0], [0, 0, 0], sp)
    thr = ctrl.thrust_setpoint
    assert math.sqrt(sum(t * t for t in thr)) <= position_cfg.thrust_max + 1e-9
    assert -thr[2] > abs(thr[0])


def test_velocity_limits_up_and_down(position_cfg):
    ctrl = PositionController(position_cfg, HOVER)
    ctrl.update(0.02, [0, 0, -2.0], [0, 0, 0], ControlSetpoint([0, 0, -100.0], [NAN] * 3, 0.0))
    assert ctrl.velocity_setpoint[2] == pytest.approx(-position_cfg.z_vel_max_up_m_s)
    ctrl.update(0.02, [0, 0, -2.0], [0, 0, 0], ControlSetpoint([0, 0, 100.0], [NAN] * 3, 0.0))
    assert ctrl.velocity_setpoint[2] == pytest.approx(position_cfg.z_vel_max_down_m_s)


def test_horizontal_integrator_converges_while_saturated(position_cfg):
    """Tracking anti-windup: pinned against the tilt limit, the integrator settles where the
    demand tracks the achievable output instead of growing without bound."""
    ctrl = PositionController(position_cfg, HOVER)
    sp = ControlSetpoint([1000.0, 0.0, -2.0], [NAN] * 3, 0.0)
    for _ in range(1000):  # 20 s
        ctrl.update(0.02, [0.0, 0.0, -2.0], [0.0, 0.0, 0.0], sp)
    after_20s = ctrl._vel_int[0]
    for _ in range(500):  # 10 s more
        ctrl.update(0.02, [0.0, 0.0, -2.0], [0.0, 0.0, 0.0], sp)
    unbounded = position_cfg.xy_vel_i * position_cfg.xy_vel_max_m_s * 30.0
    assert abs(ctrl._vel_int[0] - after_20s) < 0.3
    assert abs(ctrl._vel_int[0]) < 0.2 * unbounded


def test_body_z_to_attitude_heading():
    q = body_z_to_attitude((0.0, 0.0, 1.0), math.radians(30))
    assert np.allclose(q, quat_from_euler(0, 0, math.radians(30)))


def test_attitude_controller_prioritises_tilt(sim_config):
    ctrl = AttitudeController(sim_config.flight_stack.attitude)
    q = quat_from_euler(0, 0, 0).tolist()
    # desired: 20° roll and 90° yaw at once
    q_sp = quat_from_euler(math.radians(20), 0, math.radians(90)).tolist()
    rates = ctrl.update(q, q_sp, 0.0)
    assert rates[0] > 0
    assert rates[2] > 0
    lim = [math.radians(r) for r in sim_config.flight_stack.attitude.rate_max_deg_s]
    assert all(abs(r) <= m + 1e-9 for r, m in zip(rates, lim, strict=True))
    # a pure yaw error yields a pure yaw rate
    yaw_only = ctrl.update(q, quat_from_euler(0, 0, 0.5).tolist(), 0.0)
    assert abs(yaw_only[0]) < 1e-9
    assert abs(yaw_only[1]) < 1e-9
    assert yaw_only[2] > 0


def _quad_allocator():
    positions = np.array([[0.15, 0.15, 0], [-0.15, -0.15, 0], [0.15, -0.15, 0], [-0.15, 0.15, 0]])
    return ControlAllocator(positions, np.array([0.016, 0.016, -0.016, -0.016]),
                            np.full(4, 8.0))


def test_allocation_reproduces_demands_when_feasible():
    alloc = _quad_allocator()
    out = alloc.allocate((0.1, -0.05, 0.02), 14.7, 0.4)
    u = np.array(out.thrust_n)
    assert u.sum() == pytest.approx(14.7)
    pos = np.array([[0.15, 0.15], [-0.15, -0.15], [0.15, -0.15], [-0.15, 0.15]])
    assert (-pos[:, 1] * u).sum() == pytest.approx(0.1)
    assert (pos[:, 0] * u).sum() == pytest.approx(-0.05)
    assert (np.array([0.016, 0.016, -0.016, -0.016]) * u).sum() == pytest.approx(0.02)
    assert not any(out.saturated_positive)
    assert not any(out.saturated_negative)


def test_allocation_sacrifices_yaw_for_roll():
    alloc = _quad_allocator()
    out = alloc.allocate((1.0, 0.0, 0.5), 14.7, 0.4)
    u = np.array(out.thrust_n)
    assert np.all(u >= 0.4 - 1e-9)
    assert np.all(u <= 8.0 + 1e-9)
    roll = (-np.array([0.15, -0.15, -0.15, 0.15]) * u).sum()
    yaw = (np.array([0.016, 0.016, -0.016, -0.016]) * u).sum()
    assert roll == pytest.approx(1.0)  # roll fully achieved
    assert yaw < 0.5  # yaw cut
    assert out.saturated_positive[2]
    assert not out.saturated_positive[0]


def test_rate_integrator_freezes_in_saturated_direction(sim_config):
    ctrl = RateController(sim_config.flight_stack.rates)
    for _ in range(100):
        ctrl.update(0.004, [0, 0, 0], [1.0, 1.0, 0.0], [0, 0, 0],
                    (True, False, False), (False, False, False))
    assert ctrl.integral[0] == 0.0  # saturated positive, error positive: frozen
    assert ctrl.integral[1] > 0.0
