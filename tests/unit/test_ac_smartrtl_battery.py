"""ArduCopter's SmartRTL path (AP_SmartRTL: breadcrumbs SRTL_ACCURACY apart, simplification,
loop pruning, deactivation) and its battery monitor (AP_BattMonitor: voltage for
BATT_LOW_TIMER, capacity, the actions), without the simulator."""

import itertools

import numpy as np
import pytest

from drivers.base import Battery
from drivers.sim.flight.ac_battery import AcBatteryMonitor, Action, Level
from drivers.sim.flight.ac_smartrtl import (
    SmartRtlFlight,
    SmartRtlPath,
    prune_loops,
    segment_segment_distance,
    simplify,
)
from drivers.sim.flight.arducopter_params import ARDUCOPTER_PARAMS
from drivers.sim.flight.params import Parameters


def _params(**values) -> Parameters:
    return Parameters(values, specs=ARDUCOPTER_PARAMS)


def _flown(path: SmartRtlPath, points, dt_s: float = 0.1, start_s: float = 0.0,
           step_m: float = 0.2) -> float:
    """Fly through ``points`` in straight lines, sampling every ``step_m``."""
    t = start_s
    for a, b in itertools.pairwise(points):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(int(np.linalg.norm(b - a) / step_m), 1)
        for k in range(1, n + 1):
            t += dt_s
            path.update(t, True, a + (b - a) * k / n)
    return t


def test_the_path_keeps_points_accuracy_apart_and_simplifies_a_straight_line():
    texts = []
    path = SmartRtlPath(_params(), texts.append)
    path.set_home(0.0, True, np.array([0.0, 0.0, -3.0]))
    assert path.active
    _flown(path, [(0, 0, -3), (20, 0, -3), (20, 20, -3)])
    path.thorough_cleanup()
    corners = np.array(path.points)
    # a straight line is two points; the corner is kept (within SRTL_ACCURACY / 2 of it)
    assert len(corners) == 3
    np.testing.assert_allclose(corners[0], [0, 0, -3])
    assert np.linalg.norm(corners[1] - [20, 0, -3]) < 1.0
    assert np.linalg.norm(corners[2] - [20, 20, -3]) < 2.0
    assert texts == []


def test_a_loop_is_cut_where_the_path_comes_back_near_itself():
    pts = [np.array(p, float) for p in
           [(0, 0, 0), (10, 0, 0), (10, 10, 0), (5, 10, 0), (5, -5, 0), (5, -10, 0)]]
    # segment (5,10)→(5,-5) crosses (0,0)→(10,0) at (5,0): the square beyond it is cut
    pruned = prune_loops(pts, 1.98)
    assert len(pruned) < len(pts)
    assert any(np.linalg.norm(p - [5, 0, 0]) < 0.1 for p in pruned)
    assert not any(np.linalg.norm(p - [10, 10, 0]) < 0.1 for p in pruned)
    assert simplify(pts[:2], 1.0) == pts[:2]
    gap, _mid = segment_segment_distance(pts[0], pts[1], pts[0] + [0, 1, 0], pts[1] + [0, 1, 0])
    assert gap == float("inf")  # parallel: never a loop (ArduPilot's limitation kept)


def test_no_position_or_a_full_buffer_turns_it_off_for_the_flight():
    texts = []
    path = SmartRtlPath(_params(), texts.append)
    path.set_home(0.0, False, np.zeros(3))  # armed without a position
    assert not path.active
    path.set_home(0.0, True, np.zeros(3))
    path.update(1.0, False, np.zeros(3))
    path.update(16.5, False, np.zeros(3))  # 15 s without a position
    assert not path.active
    assert texts == ["SmartRTL deactivated: bad position"]
    texts.clear()
    small = SmartRtlPath(_params(SRTL_POINTS=20), texts.append)
    small.set_home(0.0, True, np.zeros(3))
    # a zig-zag wider than the accuracy: nothing to simplify or prune, the buffer fills
    zigzag = [(2.5 * k, 3.0 * (k % 2), 0.0) for k in range(60)]
    _flown(small, zigzag, dt_s=0.5)
    assert not small.active
    assert texts == ["SmartRTL deactivated: buffer full"]
    assert not SmartRtlPath(_params(SRTL_POINTS=0), texts.append).active


def test_the_flight_home_pops_points_and_ends_two_metres_above_home():
    path = SmartRtlPath(_params(), lambda _: None)
    path.set_home(0.0, True, np.array([0.0, 0.0, -3.0]))
    _flown(path, [(0, 0, -3), (10, 0, -3), (10, 10, -3)])
    flight = SmartRtlFlight.start(path, np.array([10.0, 10.0, -3.0]))
    targets = []
    here = np.array([10.0, 10.0, -3.0])
    for _ in range(20):
        sp = flight.setpoint(here, 2.0)
        if sp is None:
            break
        here = np.asarray(sp.position_ned_m, float)  # arrive at each target
        if not targets or not np.allclose(targets[-1], here):
            targets.append(here.copy())
    assert sp is None
    assert any(np.linalg.norm(t - [10, 0, -3]) < 1.0 for t in targets)  # the corner
    np.testing.assert_allclose(targets[-1], [0.0, 0.0, -5.0])  # home, 2 m higher


def test_leaving_before_a_point_is_reached_puts_it_back():
    path = SmartRtlPath(_params(), lambda _: None)
    path.set_home(0.0, True, np.zeros(3))
    _flown(path, [(0, 0, 0), (10, 0, 0), (10, 10, 0)])
    flight = SmartRtlFlight.start(path, np.array([10.0, 10.0, 0.0]))
    flight.setpoint(np.array([10.0, 10.0, 0.0]), 2.0)  # pops the first point
    count = len(path.points)
    flight.end()
    assert len(path.points) == count + 1


def _battery(volts: float, amps: float = 10.0) -> Battery:
    return Battery(voltage_v=volts, current_a=amps, remaining_fraction=0.5)


def test_low_voltage_for_batt_low_timer_acts_once_with_batt_fs_low_act():
    texts = []
    monitor = AcBatteryMonitor(_params(BATT_LOW_VOLT=15.0, BATT_FS_LOW_ACT=2,
                                       BATT_CRT_VOLT=14.0, BATT_FS_CRT_ACT=1), texts.append)
    t, fs = 0.0, None
    for _ in range(100):  # 9.9 s under BATT_LOW_VOLT: not yet (BATT_LOW_TIMER 10 s)
        t += 0.1
        fs = monitor.update(t, 0.1, _battery(14.8), True, False, False) or fs
    assert fs is None
    for _ in range(5):
        t += 0.1
        fs = monitor.update(t, 0.1, _battery(14.8), True, False, False) or fs
    assert fs is not None
    assert fs.level is Level.LOW
    assert fs.action is Action.RTL
    assert fs.text == "Battery Failsafe"
    assert texts[0].startswith("Battery 1 is low 14.80V used ")
    assert monitor.update(t + 1, 0.1, _battery(14.8), True, False, False) is None  # once
    assert monitor.level is Level.LOW
    # a recovery (under load the voltage comes back) does not end it; critical still acts
    for _ in range(120):
        t += 0.1
        fs = monitor.update(t, 0.1, _battery(13.9), True, False, True)
        if fs is not None:
            break
    assert fs.level is Level.CRITICAL
    assert fs.action is Action.LAND


def test_capacity_on_the_ground_landing_and_arming():
    texts = []
    p = _params(BATT_CAPACITY=1000, BATT_LOW_MAH=500, BATT_FS_LOW_ACT=2, FS_OPTIONS=8)
    monitor = AcBatteryMonitor(p, texts.append)
    assert monitor.arming_problem() is None
    # 10 A for 200 s: 556 mAh used, 444 left (< 500): low at once, no timer
    fs = None
    for k in range(200):
        fs = monitor.update(float(k), 1.0, _battery(16.0), True, False, True) or fs
    assert fs is not None
    assert fs.action is Action.LAND
    assert fs.text == "Battery Failsafe - Continuing Landing"
    assert monitor.remaining_fraction == pytest.approx(1 - 200 * 10 / 3.6 / 1000)
    assert monitor.arming_problem() == "Battery 1 low capacity failsafe"
    monitor.disarmed()
    landed = monitor.update(201.0, 1.0, _battery(16.0), True, True, False)
    assert landed.disarm
    assert landed.text == "Battery Failsafe - Disarming"
    # disarmed: never acts (though the capacity is under BATT_LOW_MAH from the start)
    quiet = AcBatteryMonitor(_params(BATT_CAPACITY=1000, BATT_LOW_MAH=2000), texts.append)
    assert quiet.update(1.0, 1.0, _battery(16.0), False, True, False) is None
    assert quiet.arming_problem() == "Battery 1 low capacity failsafe"
    inverted = AcBatteryMonitor(_params(BATT_LOW_VOLT=14.0, BATT_CRT_VOLT=14.5), texts.append)
    inverted.update(0.0, 0.1, _battery(16.0), False, True, False)
    assert inverted.arming_problem() == "Battery 1 voltage failsafe critical > low"
