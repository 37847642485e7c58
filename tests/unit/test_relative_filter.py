"""The relative-state filter (autopilot/estimation/relative.py) on synthetic data: a rover
driving, a drone following it down, each sensor with its own noise, rate and delay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot.estimation.relative import RelativeFilter
from autopilot.estimation.relative_types import DeckGeometry, RelativeSettings, tag_measurement

ANCHORS = ((0.5, 0.4, -0.47), (0.5, -0.4, -0.47), (-0.5, 0.4, -0.47), (-0.55, -0.45, -1.0))
GEOMETRY = DeckGeometry((1.0, 0.8), 0.45, ANCHORS, (0.0, 0.0, -0.06))
LEVEL = np.eye(3)


def _yaw(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class World:
    """A rover turning gently at 1.5 m/s; the drone closing in from 3 m behind and 4 m up
    towards 0.3 m over the deck; truth of the relative state at any time."""

    def __init__(self, seed: int = 0, rover_bias=(1.0, -0.8, 0.5)) -> None:
        self.seed = seed
        self.bias = np.array(rover_bias, dtype=float)

    def noise(self, kind: int, t: float, n: int) -> np.ndarray:
        """Standard normal noise of one reading (the same whenever it is asked for)."""
        return np.random.default_rng((self.seed, kind, round(t * 1000))).standard_normal(n)

    def rover(self, t: float):
        psi = 0.3 + 0.05 * t
        speed = 1.5
        # integrate the unicycle in closed form (constant turn rate)
        w = 0.05
        x = speed / w * (math.sin(0.3 + w * t) - math.sin(0.3))
        y = speed / w * (-math.cos(0.3 + w * t) + math.cos(0.3))
        pos = np.array([x, y, -0.45])  # the deck's top centre
        vel = speed * np.array([math.cos(psi), math.sin(psi), 0.0])
        return pos, vel, psi

    def relative(self, t: float) -> np.ndarray:
        f = min(t / 20.0, 1.0)
        return np.array([-3.0 * (1 - f), 0.5 * (1 - f), -4.0 + 3.7 * f])

    def relative_velocity(self, t: float) -> np.ndarray:
        return np.array([3.0, -0.5, 3.7]) / 20.0 if t < 20.0 else np.zeros(3)

    def drone(self, t: float):
        pos, vel, _ = self.rover(t)
        return pos + self.relative(t), vel + self.relative_velocity(t)

    def uwb(self, t: float, noise: float = 0.08):
        pos, _, psi = self.rover(t)
        drone, _ = self.drone(t)
        tag = drone + np.array([0.0, 0.0, -0.06])
        ref = pos + np.array([0.0, 0.0, 0.45])
        n = self.noise(1, t, len(ANCHORS))
        ranges = [float(np.linalg.norm(tag - (ref + _yaw(psi) @ np.array(a)))) + noise * e
                  for a, e in zip(ANCHORS, n, strict=True)]
        return (0, 1, 2, 3), ranges

    def rover_report(self, t: float):
        pos, vel, psi = self.rover(t)
        drone, dvel = self.drone(t)
        reported = pos + np.array([0.0, 0.0, 0.45]) - self.bias  # its reference point, biased
        rough = drone - (reported + np.array([0.0, 0.0, -0.45]))
        n = self.noise(2, t, 4)
        return (rough, dvel - (vel + 0.05 * n[:3] * (1, 1, 0)), psi + math.radians(2.0) * n[3])


def _fly(world: World, filt: RelativeFilter, until_s: float, *, uwb_delay=0.03,
         rover_delay=0.15, tag_delay=0.08, uwb_until=math.inf, tag_from=math.inf,
         check=None):
    """Feed the filter in arrival order (each message at capture + its delay)."""
    messages = []
    for k in range(int(until_s * 50)):
        t = k / 50.0
        messages.append((t + 0.015, "velocity", t))
    # capture times never tie with another sensor's (so that the order is the same whatever
    # the delays: what the rewind must reproduce)
    for k in range(int(until_s * 10)):
        t = k / 10.0 + 0.005
        if t < uwb_until:
            messages.append((t + uwb_delay, "uwb", t))
        messages.append((t + 0.002 + rover_delay, "rover", t + 0.002))
    for k in range(int(until_s * 15)):
        t = k / 15.0 + 0.003
        if t >= tag_from:
            messages.append((t + tag_delay, "tag", t))
    messages.sort()
    errors = []
    for arrival, kind, t in messages:
        if kind == "velocity":
            filt.add_velocity(t, world.drone(t)[1])
        elif kind == "uwb":
            ids, ranges = world.uwb(t)
            filt.add_uwb(t, ids, ranges, [1.0, 0.0, 0.0, 0.0])
        elif kind == "rover":
            filt.add_rover(t, *world.rover_report(t))
        else:
            rel = world.relative(t) + 0.01 * world.noise(3, t, 3)
            filt.add_tag(t, rel, np.eye(3) * 0.01 ** 2, world.rover(t)[2], math.radians(2))
        est = filt.estimate(arrival)
        if est is not None and arrival > 2.0:
            err = est.position_m - world.relative(arrival)
            errors.append((arrival, err, est.position_std_m))
            if check is not None:
                check(arrival, est)
    return errors


def test_uwb_and_rover_converge_and_stay_consistent():
    world = World(seed=1)
    filt = RelativeFilter(RelativeSettings(), GEOMETRY)
    errors = _fly(world, filt, 25.0)
    late = [(e, s) for t, e, s in errors if t > 8.0]
    rms = math.sqrt(np.mean([float(e @ e) for e, _ in late]))
    assert rms < 0.12, rms  # UWB ranges at 8 cm fix the relative position to about 10 cm
    # honest: within 2σ per axis most of the time
    inside = np.mean([np.all(np.abs(e) <= 2.0 * s + 1e-9) for e, s in late])
    assert inside > 0.8, inside
    # the rough position's bias was learned (UWB observes r, the report r + b)
    est = filt.estimate()
    assert np.linalg.norm(est.bias_m[:2] - world.bias[:2]) < 0.3, est.bias_m
    assert filt.updates["uwb"] > 150
    assert filt.dropped_late == 0


def test_rough_position_only_is_honest_about_its_uncertainty():
    world = World(seed=2)
    filt = RelativeFilter(RelativeSettings(), GEOMETRY, use_uwb=False, use_tag=False)
    errors = _fly(world, filt, 15.0)
    last_err, last_std = errors[-1][1], errors[-1][2]
    # the bias is not observable: the error stays about the bias, and σ says so
    assert np.linalg.norm(last_err[:2]) > 0.5
    assert np.all(np.abs(last_err) <= 2.0 * last_std), (last_err, last_std)
    assert filt.updates["uwb"] == 0


def test_tag_takes_over_and_tightens_the_estimate():
    world = World(seed=3)
    filt = RelativeFilter(RelativeSettings(), GEOMETRY)
    errors = _fly(world, filt, 25.0, uwb_until=12.0, tag_from=10.0)
    end = [(e, s) for t, e, s in errors if t > 14.0]
    rms = math.sqrt(np.mean([float(e @ e) for e, _ in end]))
    assert rms < 0.04, rms
    assert np.median([float(np.max(s)) for _, s in end]) < 0.05
    inside = np.mean([np.all(np.abs(e) <= 2.0 * s + 1e-9) for e, s in end])
    assert inside > 0.85, inside


def test_delayed_measurements_are_fused_at_their_capture_time():
    """The same data arriving late or on time gives the same estimate (the rewind)."""
    on_time = RelativeFilter(RelativeSettings(), GEOMETRY)
    delayed = RelativeFilter(RelativeSettings(), GEOMETRY)
    _fly(World(seed=4), on_time, 12.0, uwb_delay=0.0, rover_delay=0.0, tag_delay=0.0,
         tag_from=6.0)
    _fly(World(seed=4), delayed, 12.0, uwb_delay=0.3, rover_delay=0.45, tag_delay=0.2,
         tag_from=6.0)
    a, b = on_time.estimate(), delayed.estimate(on_time.estimate().time_s)
    assert a.time_s == pytest.approx(b.time_s, abs=0.05)
    assert np.allclose(a.position_m, b.position_m, atol=0.01), (a.position_m, b.position_m)
    assert any(r.late for r in delayed.take_results()) or delayed.updates["uwb"] > 0


def test_too_late_measurements_are_dropped_and_counted():
    filt = RelativeFilter(RelativeSettings(history_s=0.5), GEOMETRY)
    world = World()
    for k in range(100):
        filt.add_velocity(k / 50.0, world.drone(k / 50.0)[1])
    filt.add_rover(1.9, *world.rover_report(1.9))
    ids, ranges = world.uwb(0.5)
    filt.add_uwb(0.5, ids, ranges, [1, 0, 0, 0])  # 1.5 s late
    assert filt.dropped_late == 1


def test_uwb_dropout_degrades_gracefully():
    """Ranges stop: σ grows (the rover's velocity keeps the motion in check), never lies."""
    world = World(seed=5)
    filt = RelativeFilter(RelativeSettings(), GEOMETRY)
    stds = []

    def check(t, est):
        if t > 10.0:
            stds.append(float(est.position_std_m[0]))
    errors = _fly(world, filt, 18.0, uwb_until=10.0, check=check)
    assert stds[-1] > stds[0]
    late = [(e, s) for t, e, s in errors if t > 10.0]
    inside = np.mean([np.all(np.abs(e) <= 2.0 * s + 1e-9) for e, s in late])
    assert inside > 0.9


def test_non_line_of_sight_ranges_are_gated():
    world = World(seed=6)
    filt = RelativeFilter(RelativeSettings(), GEOMETRY)
    _fly(world, filt, 10.0)
    before = filt.estimate().position_m.copy()
    ids, ranges = world.uwb(10.0, noise=0.0)
    ranges[0] += 1.5  # a reflected path: much longer
    for k in range(5):
        filt.add_velocity(10.0 + k * 0.02, world.drone(10.0 + k * 0.02)[1])
    filt.add_uwb(10.05, ids, ranges, [1, 0, 0, 0])
    result = filt.take_results()[-1]
    assert result.source == "uwb"
    assert result.parts == 3
    assert np.linalg.norm(filt.estimate().position_m - before) < 0.2


def test_rangefinder_over_the_deck_and_beside_it():
    filt = RelativeFilter(RelativeSettings(), GEOMETRY, use_uwb=False)
    world = World()
    filt.add_velocity(0.0, np.zeros(3))
    filt.add_tag(0.0, [0.0, 0.0, -1.0], np.eye(3) * 0.02 ** 2, 0.0, 0.05)
    filt.add_range(0.01, 0.95)  # over the deck: 0.95 m above it
    assert filt.take_results()[-1].accepted
    assert filt.estimate().position_m[2] == pytest.approx(-0.96, abs=0.03)
    filt2 = RelativeFilter(RelativeSettings(), GEOMETRY, use_uwb=False)
    filt2.add_velocity(0.0, np.zeros(3))
    filt2.add_tag(0.0, [3.0, 0.0, -1.0], np.eye(3) * 0.02 ** 2, 0.0, 0.05)
    filt2.add_range(0.01, 1.45)  # beside the deck: the ground is 0.45 m lower
    assert filt2.take_results()[-1].accepted
    assert filt2.estimate().position_m[2] == pytest.approx(-1.0, abs=0.03)
    del world


def test_tag_measurement_geometry():
    # camera straight down, 0.1 m ahead of the body origin; the tag 2 m below, 0.2 m east
    r_body_cam = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    m = tag_measurement([0.2, 0.0, 2.0], np.eye(3), LEVEL, r_body_cam, [0.1, 0.0, 0.0],
                        500.0, pixel_noise_px=1.0, range_noise_fraction=0.02,
                        attitude_std_rad=0.0, heading_std_rad=0.05)
    # the tag is at camera x (body east) 0.2 → the drone is 0.2 m west of it, 0.1 m behind
    assert np.allclose(m.relative_m, [-0.1, -0.2, -2.0])
    assert m.covariance[2, 2] > m.covariance[0, 0]  # range noise dominates along the axis
