"""Planning bounded and off the control loop (issue 31, items 2 and 5): a goto, orbit or survey
beyond control.trajectory.max_path_m / max_photos or the geofence (on by default) is refused
naming the key and the limit — a mission when it loads (what it can tell then) or when the step
starts, a goal before it is accepted; in real time the plan is made by a worker while the
vehicle holds; the speed law and the path clean-up are exact and linear in the path's length."""

from __future__ import annotations

import math
from concurrent.futures import Future

import numpy as np
import orjson
import pytest

from autopilot.behaviors.base import BehaviorInputs, Status
from autopilot.config import ConfigError
from autopilot.flightlog.log import encode
from autopilot.goals import GoalError, validate_goal
from autopilot.mission import build_behavior, load_mission
from autopilot.planning.trajectory import Limits, Path, Trajectory, dedupe, hold_heading

from ..factories import front_camera, vehicle_state

CAMERAS = {"down": front_camera(), "front": front_camera()}


@pytest.fixture(scope="module")
def config():
    return load_mission("standby").config


def _site(pos=(0.0, 0.0, -3.0), home=(0.0, 0.0, 0.0)) -> BehaviorInputs:
    return BehaviorInputs(1.0, vehicle_state(1.0, pos=pos), home_ned_m=np.array(home))


@pytest.mark.parametrize(("goal", "key", "limit"), [
    ({"orbit": {"center_m": [8600, 0], "radius_m": 500, "laps": 100}}, "orbit.laps",
     "control.trajectory.max_path_m (10000)"),
    ({"orbit": {"center_m": [60, 0], "radius_m": 50, "laps": 40}}, "orbit.laps",
     "max_path_m"),
    ({"survey": {"polygon_m": [[0, 0], [200, 0], [200, 200], [0, 200]], "spacing_m": 0.25}},
     "survey.spacing_m", "max_path_m"),
    ({"survey": {"polygon_m": [[0, 0], [90, 0], [90, 90], [0, 90]], "spacing_m": 5,
                 "photo_spacing_m": 0.2}}, "survey.photo_spacing_m", "max_photos (2000)"),
    ({"goto": {"position_m": [10_000, 0, 8]}}, "goto.position_m",
     "failsafe.geofence.max_distance_m (500)"),
    ({"goto": {"position_m": [300, 400.5, 8]}}, "goto.position_m", "max_distance_m"),
    ({"goto": {"position_m": [5, 0, -50]}}, "goto.position_m", "below the ground"),
    ({"goto": {"position_m": [5, 0, 0.5]}}, "goto.position_m", "min_altitude_m is 1"),
    ({"goto": {"position_m": [5, 0, 121]}}, "goto.position_m", "max_altitude_m (120)"),
    ({"orbit": {"center_m": [480, 0], "radius_m": 30}}, "orbit.center_m", "max_distance_m"),
    ({"orbit": {"center_m": [6, 0], "altitude_m": 200}}, "orbit.altitude_m", "max_altitude_m"),
    ({"survey": {"polygon_m": [[0, 0], [20, 0], [20, 600], [0, 600]]}}, "survey.polygon_m",
     "max_distance_m"),
])
def test_goals_beyond_the_bounds_are_refused_naming_the_key_and_the_limit(config, goal, key,
                                                                          limit):
    with pytest.raises(GoalError) as err:
        validate_goal(goal, config, _site())
    assert err.value.status == 422
    assert err.value.problems[0]["key"] == key
    assert limit in err.value.reason


def test_the_fence_is_from_home_and_the_way_in_counts(config):
    # 450 m north of home is inside; the same goal from a home 100 m south is not
    goal = {"goto": {"position_m": [450, 0, 8]}}
    validate_goal(goal, config, _site())
    with pytest.raises(GoalError, match=r"550\.0 m from home"):
        validate_goal(goal, config, _site(home=(-100.0, 0.0, 0.0)))
    # frame home: altitudes above home (home 10 m up a hill: 0.5 m above it is too low)
    with pytest.raises(GoalError, match="min_altitude_m"):
        validate_goal({"goto": {"position_m": [0, 0, 0.5], "frame": "home"}}, config,
                      _site(home=(0.0, 0.0, -10.0)))
    # an orbit far from where the vehicle is: its way in makes the path too long
    far = {"orbit": {"center_m": [400, 0], "radius_m": 50, "laps": 31}}  # 9,739 m round
    validate_goal(far, config, _site(pos=(380.0, 0.0, -8.0)))
    with pytest.raises(GoalError, match="max_path_m"):  # + 350 m in
        validate_goal(far, config, _site(pos=(0.0, 0.0, -8.0)))


def test_the_limits_are_configurable_and_off_only_when_chosen(config):
    goal = {"goto": {"position_m": [9_000, 0, 8]}}
    with pytest.raises(GoalError, match="max_distance_m"):
        validate_goal(goal, config, _site())
    open_sky = load_mission("standby", ["failsafe.geofence.max_distance_m=0"]).config
    validate_goal(goal, open_sky, _site())  # explicitly off
    fenced = load_mission("standby", [
        "failsafe.geofence.polygon_m=[[-10, -10], [10, -10], [10, 10], [-10, 10]]"]).config
    with pytest.raises(GoalError, match="polygon_m"):
        validate_goal({"goto": {"position_m": [15, 0, 3]}}, fenced, _site())
    validate_goal({"goto": {"position_m": [5, 0, 3]}}, fenced, _site())
    assert config.failsafe.geofence.max_distance_m == 500
    assert config.failsafe.geofence.max_altitude_m == 120
    assert config.failsafe.geofence.min_altitude_m == 1.0


def test_a_mission_beyond_the_bounds_is_refused_when_it_loads():
    with pytest.raises(ConfigError) as err:
        load_mission("orbit", ["steps.1.orbit.laps=100", "steps.1.orbit.radius_m=100"])
    assert "steps.1.orbit" in str(err.value)
    assert "max_path_m" in str(err.value)
    with pytest.raises(ConfigError, match="max_path_m"):
        load_mission("survey", ["steps.1.survey.spacing_m=0.3",
                                "steps.1.survey.polygon_m=[[0,0],[300,0],[300,300],[0,300]]"])


def test_a_mission_step_outside_the_fence_fails_when_it_starts_without_flying():
    plan = load_mission("orbit", ["steps.1.orbit.center_m=[700, 0]"])
    behavior = build_behavior(plan.steps[1], plan.config, CAMERAS)
    out = behavior.activate(_site())
    assert out.status is Status.FAILED
    assert "max_distance_m" in out.reason
    assert out.setpoint is None


class _Manual:
    """An offload whose jobs run only when the test says (a worker that takes its time)."""

    def __init__(self) -> None:
        self.jobs: list[tuple] = []

    def __call__(self, job) -> Future:
        future: Future = Future()
        self.jobs.append((job, future))
        return future

    def finish(self) -> None:
        for job, future in self.jobs:
            try:
                future.set_result(job())
            except Exception as exc:
                future.set_exception(exc)


def test_a_plan_made_by_a_worker_holds_the_vehicle_until_it_is_ready():
    plan = load_mission("orbit")
    step = plan.steps[1]
    inline = build_behavior(step, plan.config, CAMERAS)
    worker = _Manual()
    offloaded = build_behavior(step, plan.config, CAMERAS, worker)
    here = vehicle_state(1.0, pos=(0.0, 0.0, -3.0), yaw=0.3)
    first = offloaded.activate(BehaviorInputs(1.0, here, home_ned_m=np.zeros(3)))
    assert first.status is Status.RUNNING
    assert first.phase == "planning"
    assert np.allclose(first.setpoint.position_ned_m, here.position_ned_m)
    assert np.allclose(first.setpoint.velocity_m_s, 0.0)
    assert first.setpoint.yaw_rad == pytest.approx(0.3)
    assert first.plan is None
    assert len(worker.jobs) == 1
    for t in (1.02, 1.04):  # the worker is slow: the vehicle holds, ticks go on
        out = offloaded.update(BehaviorInputs(t, here, home_ned_m=np.zeros(3)))
        assert out.status is Status.RUNNING
        assert out.phase == "planning"
        assert out.setpoint.time_s == t
        assert np.allclose(out.setpoint.position_ned_m, here.position_ned_m)
    worker.finish()
    began = offloaded.update(BehaviorInputs(1.06, here, home_ned_m=np.zeros(3)))
    ref = inline.activate(BehaviorInputs(1.0, here, home_ned_m=np.zeros(3)))
    assert began.status is Status.RUNNING
    assert began.plan is not None
    # the same plan as made inline, the reference starting at its beginning when it is ready
    assert np.array_equal(began.plan["points_ned_m"], ref.plan["points_ned_m"])
    # the record goes to the log from its arrays (strided views of the time law included)
    logged = orjson.loads(encode(dict(began.plan, time_s=1.06)))
    assert len(logged["reference"]["s_m"]) == len(began.plan["reference"]["s_m"])
    assert np.allclose(began.setpoint.position_ned_m, ref.setpoint.position_ned_m)
    assert began.setpoint.time_s == 1.06


def test_a_worker_plan_that_cannot_be_made_fails_the_step_holding():
    plan = load_mission("orbit", ["steps.1.orbit.center_m=[700, 0]"])
    worker = _Manual()
    behavior = build_behavior(plan.steps[1], plan.config, CAMERAS, worker)
    assert behavior.activate(_site()).phase == "planning"
    worker.finish()
    out = behavior.update(_site())
    assert out.status is Status.FAILED
    assert "max_distance_m" in out.reason
    assert out.setpoint is not None  # (the hold it was keeping)


def _speed_law_loop(s, v, accel):
    v = v.copy()
    v[0] = v[-1] = 0.0
    ds = np.diff(s)
    for i in range(1, len(s)):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * accel * ds[i - 1]))
    for i in range(len(s) - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * accel * ds[i]))
    return v


def test_the_vectorised_speed_law_is_the_two_pass_law():
    """The closed-form passes give what the loops over every point gave (on a path with
    curves, climbs and descents)."""
    rng = np.random.default_rng(3)
    path = Path(np.cumsum(rng.normal(size=(30, 3)) * [4.0, 4.0, 0.5], axis=0))
    s = np.linspace(0.0, path.length_m, 4000)
    # the caps alone (curvature, climb, cruise): the passes with an acceleration that never binds
    def speed_law(accel_m_s2: float) -> np.ndarray:
        traj = Trajectory.__new__(Trajectory)  # (only its speed law: no samples)
        traj.path, traj.limits = path, Limits(4.0, accel_m_s2=accel_m_s2)
        return traj._speed_law(s)

    caps, law = speed_law(1e9), speed_law(1.5)
    assert Trajectory(path, Limits(4.0), hold_heading(0.0)).duration_s > 0
    assert np.allclose(law, _speed_law_loop(s, caps, 1.5), atol=1e-9)
    assert 0 < law.max() <= 4.0
    assert law[0] == law[-1] == 0.0


def test_dedupe_keeps_what_the_greedy_rule_keeps():
    def greedy(points, m=1e-3):
        keep = [0]
        for i in range(1, len(points)):
            if np.linalg.norm(points[i] - points[keep[-1]]) > m:
                keep.append(i)
        return points[keep]

    rng = np.random.default_rng(5)
    for _ in range(500):
        n = int(rng.integers(1, 40))
        steps = rng.choice([0.0, 0.0005, 0.002, 0.5], size=(n, 1)) * rng.normal(size=(n, 3))
        pts = np.cumsum(steps, axis=0)
        assert np.array_equal(dedupe(pts), greedy(pts))


def test_a_path_from_below_the_floor_or_outside_the_fence_may_come_back():
    """Hovering at 0.8 m (below min_altitude_m 1.0) or 510 m out: a goto up or back in is
    planned (only where it goes is bounded, not where it starts)."""
    plan = load_mission("standby")
    for pos, target in [((0.0, 0.0, -0.8), [5, 0, 3]), ((510.0, 0.0, -5.0), [0, 0, 5])]:
        step = validate_goal({"goto": {"position_m": target}}, plan.config,
                             _site(pos=pos))
        out = build_behavior(step, plan.config, CAMERAS).activate(_site(pos=pos))
        assert out.status is Status.RUNNING, out.reason


_UNGUARDED = """
import sys
sys.path.insert(0, {root!r})
print("top level ran", flush=True)
from autopilot.runtime.planner import PlanningWorker, warm_planner
worker = PlanningWorker()
print("planned", worker.submit(warm_planner).result(timeout=120), flush=True)
worker.close()
"""


@pytest.mark.parametrize("how", ["script", "stdin"])
def test_the_planning_worker_never_runs_the_embedding_program_again(tmp_path, how):
    """A program without ``if __name__ == "__main__":`` (or read from standard input) that
    flies in real time: its planning worker starts without running it a second time."""
    import subprocess
    import sys
    from pathlib import Path

    code = _UNGUARDED.format(root=str(Path(__file__).resolve().parents[2]))
    script = tmp_path / "fly.py"
    script.write_text(code)
    args = [sys.executable, str(script)] if how == "script" else [sys.executable, "-"]
    out = subprocess.run(args, input=None if how == "script" else code, text=True,
                         capture_output=True, timeout=180, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.count("top level ran") == 1
    assert "planned None" in out.stdout
