"""The simulated rover (drivers/sim/rover.py): a dynamic body that follows its path and carries
a drone standing on its deck; the land detector judges motion over that deck; the UWB and
rover-report sensor models with their noise, outliers, dropouts and latency."""

import math

import numpy as np
import pytest

from autopilot.config import load_config
from autopilot.mission import load_mission
from autopilot.scenario import build_world
from drivers.sim.rover import (
    ROVER_PATHS,
    RoverLinkModel,
    RoverLinkSettings,
    UwbModel,
    UwbSettings,
    rover_path,
)
from drivers.sim.simulator import Simulator

ANCHORS = ((0.5, 0.4, -0.47), (0.5, -0.4, -0.47), (-0.5, 0.4, -0.47), (-0.55, -0.45, -1.0))


def _simulator(overrides=(), seed=3):
    plan = load_mission("land_on_rover", [f"scenario.seed={seed}", *overrides])
    sim_cfg, objects = build_world(plan.mission.scenario, plan.config.sim, plan.config)
    sim_cfg = sim_cfg.model_copy(update={"cameras": {}})  # no rendering needed here
    return Simulator(sim_cfg, objects, seed)


@pytest.mark.parametrize("path", [p for p in ROVER_PATHS if p != "static"])
def test_the_rover_follows_its_path_within_its_limits(path):
    script = rover_path(path, (0.0, 0.0, 0.0), 0.3, 2.5, seed=4)
    t = np.arange(0.0, 60.0, 0.05)
    speeds = np.array([np.hypot(*script(x)[1][:2]) for x in t])
    assert speeds.max() <= 2.5 + 1e-6
    assert speeds[0] == pytest.approx(0.0)  # it starts at rest
    if path == "stop_and_go":
        assert (speeds[t > 5.0] < 0.01).any()  # it stops ...
        assert speeds[-200:].max() > 2.4 or speeds[-600:].max() > 2.4  # ... and goes again
    accel = np.array([np.hypot(*script.motion(x)[3][:2]) for x in t])
    assert np.percentile(accel, 99) <= 2.5 * 2.5 / 4.0 + 1.1  # braking, pulling away, turning


def test_the_rover_body_tracks_its_script_and_carries_a_drone_on_its_deck():
    sim = _simulator(["scenario.rover.path=circle", "scenario.rover.size_m=16",
                      "scenario.rover.speed_mps=2.0"])
    rover = sim.rover
    start, _, _ = rover.path(0.0)
    # the drone stands on the deck, motors off; the rover drives off
    sim.set_vehicle_pose(np.array([start[0], start[1], -0.45 - 0.095]), [1.0, 0.0, 0.0, 0.0])
    sim.start_scenario()
    worst_track, worst_slip = 0.0, 0.0
    for k in range(1, 41):
        sim.advance_to(0.5 * k)
        truth = sim.ground_truth()
        deck = truth.bodies["rover"]
        scripted, _, _ = rover.path(sim.time_s)
        worst_track = max(worst_track, float(np.linalg.norm(deck.position_ned_m[:2]
                                                            - scripted[:2])))
        offset = truth.vehicle.position_ned_m - deck.position_ned_m
        worst_slip = max(worst_slip, float(np.hypot(*offset[:2])))
    assert worst_track < 0.05  # a servoed body, on its script
    assert float(np.hypot(*deck.velocity_ned_m_s[:2])) == pytest.approx(2.0, abs=0.05)
    # carried round the circle by contact and friction (not teleported): still on the deck
    assert worst_slip < 0.1
    assert offset[2] == pytest.approx(-0.095, abs=0.01)
    assert float(np.linalg.norm(truth.vehicle.velocity_ned_m_s - deck.velocity_ned_m_s)) < 0.3


def test_the_land_detector_judges_motion_over_the_deck():
    sim = _simulator(["scenario.rover.speed_mps=1.5"])
    start, _, _ = sim.rover.path(0.0)
    sim.set_vehicle_pose(np.array([start[0], start[1], -0.45 - 0.095]), [1.0, 0.0, 0.0, 0.0])
    sim.start_scenario()
    sim.advance_to(3.0)  # the rover is at 1.5 m/s, the drone with it
    sim.command("arm")
    sim.advance_to(4.0)
    # idle on a deck moving at 1.5 m/s: still landed (over the ground it is not still)
    assert float(np.hypot(*sim.ground_truth().vehicle.velocity_ned_m_s[:2])) > 1.4
    assert sim.flight.land_detector.landed
    assert sim.flight.landed


def test_uwb_ranges_match_the_geometry_with_their_noise_outliers_and_dropouts():
    settings = UwbSettings(ANCHORS, (0.0, 0.0, -0.06), 0.08, 0.1, 0.05, 1.0, 80.0)
    model = UwbModel(settings, np.random.default_rng(1))
    rover, yaw = np.array([10.0, 5.0, 0.0]), 0.7
    drone, q = np.array([8.0, 4.0, -3.0]), np.array([1.0, 0.0, 0.0, 0.0])
    true = model.true_ranges(rover, yaw, drone, q)
    c, s = math.cos(yaw), math.sin(yaw)
    anchor0 = rover + np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array(ANCHORS[0])
    assert true[0] == pytest.approx(np.linalg.norm(anchor0 - (drone + np.array([0.0, 0.0, -0.06]))))
    errors = {i: [] for i in range(4)}
    readings = 0
    for k in range(4000):
        m = model.measure(k * 0.1, rover, yaw, drone, q)
        if m is None:
            continue
        readings += len(m.anchor_ids)
        for i, r in zip(m.anchor_ids, m.ranges_m, strict=True):
            errors[i].append(r - true[i])
    share = readings / (4 * 4000)
    assert share == pytest.approx(0.9, abs=0.02)  # 10 % dropped
    e = np.concatenate([errors[i] for i in range(4)])
    assert np.median(e) == pytest.approx(0.0, abs=0.01)
    core = e[np.abs(e) < 0.3]
    assert np.std(core) == pytest.approx(0.08, rel=0.1)
    # non-line-of-sight: only ever longer
    assert (e > 0.3).mean() > 0.02
    assert (e < -0.4).mean() == 0.0


def test_rover_reports_wander_slowly_and_stamp_their_capture_time():
    link = RoverLinkModel(RoverLinkSettings((0.8, 0.8, 1.0), 60.0, 0.05, 2.0, 2.0),
                          np.random.default_rng(2))
    pos, vel = np.array([3.0, 1.0, 0.0]), np.array([1.5, 0.0, 0.0])
    reports = [link.measure(k * 0.1, pos, vel, 0.0) for k in range(600)]
    errs = np.array([r.position_ned_m - pos for r in reports])
    assert np.abs(errs).max() < 5.0
    # slowly wandering: consecutive reports differ by far less than the error itself
    steps = np.linalg.norm(np.diff(errs[:, :2], axis=0), axis=1)
    assert np.median(steps) < 0.1
    assert reports[42].time_s == pytest.approx(4.2)
    vel_err = np.array([r.velocity_ned_m_s - vel for r in reports])
    assert np.std(vel_err[:, 0]) == pytest.approx(0.05, rel=0.2)
    assert vel_err[:, 2].max() == 0.0


def test_sensor_outputs_arrive_after_their_latency_with_capture_stamps():
    sim = _simulator()
    outputs = sim.advance_to(2.0)
    uwb = [o for o in outputs if o.kind == "uwb"]
    rover = [o for o in outputs if o.kind == "rover"]
    config = load_config()
    assert len(uwb) >= 15
    assert len(rover) >= 15
    for o in uwb:
        assert o.delivery_s == pytest.approx(o.payload.time_s + config.sim.uwb.latency_s)
    for o in rover:
        lag = o.delivery_s - o.payload.time_s
        assert config.sim.rover_link.latency_s - 1e-9 <= lag <= \
            config.sim.rover_link.latency_s + config.sim.rover_link.latency_jitter_s + 1e-9
