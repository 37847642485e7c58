"""The offboard step kinds' parameters are refused before anything flies, with the key named;
the mission status codes follow the steps."""

import pytest

from autopilot.config import ConfigError
from autopilot.mission import load_mission
from autopilot.status import MissionStatus, StatusTracker


def _problems(tmp_path, steps: str) -> str:
    path = tmp_path / "m.yaml"
    path.write_text(f"name: m\nsteps:\n  - takeoff: {{}}\n{steps}\n")
    with pytest.raises(ConfigError) as err:
        load_mission(str(path))
    return str(err.value)


@pytest.mark.parametrize(("step", "expected"), [
    ("  - goto: {position_m: [1, 2, 3], latlon: [47.3, 8.5, 3]}", "exactly one of position_m"),
    ("  - goto: {position_m: [1, 2]}", "steps[1].goto.position_m"),
    ("  - goto: {position_m: [1, 2, 3], frame: moon}", "steps[1].goto.frame"),
    ("  - goto: {position_m: [1, 2, 3], speed_m_s: 15}", "max_speed_m_s"),
    ("  - orbit: {center_m: [1, 2], radius_m: 2, speed_m_s: 4}", "at most 1.73 m/s"),
    ("  - orbit: {center_m: [1, 2], radius_m: 1.5, speed_m_s: 1.5}", "at most 1.18 m/s"),
    ("  - orbit: {center_m: [1, 2], camera: belly}", "camera 'belly'"),
    ("  - orbit: {radius_m: 3}", "exactly one of center_m"),
    ("  - survey: {polygon_m: [[0, 0], [10, 10], [10, 0], [0, 10]]}", "not a simple polygon"),
    ("  - survey: {polygon_m: [[0, 0], [10, 0]]}", "at least 3 corners"),
    ("  - survey: {polygon_m: [[0, 0], [10, 0], [0, 10]], spacing_m: 30}",
     "wider than the camera sees"),
    ("  - survey: {polygon_m: [[0, 0], [10, 0], [0, 10]], photo_spacing_m: 20}",
     "longer than the camera sees"),
    ("  - survey: {polygon_m: [[0, 0], [10, 0], [0, 10]], smoothing: spline}",
     "steps[1].survey.smoothing"),
])
def test_bad_offboard_steps_are_refused_naming_the_key(tmp_path, step, expected):
    assert expected in _problems(tmp_path, step)


def test_shipped_offboard_missions_load():
    for name in ("orbit", "survey"):
        plan = load_mission(name)
        assert [s.name for s in plan.steps] == ["takeoff", name, "land"]


def test_status_follows_the_steps_and_an_abort_sticks():
    t = StatusTracker()
    assert t.code is MissionStatus.IDLE
    assert t.step_started((1, 2)) == 1
    assert t.step_succeeded((1, 2)) == 2
    assert t.step_started((10, 11)) == 10
    assert t.idle(in_air=True) is MissionStatus.HOVER
    assert t.abort() == 12
    assert t.step_started((8, 9)) == 12  # the fallback's landing is still the abort
    assert t.idle(in_air=False) == 12
    t.resume()
    assert t.step_started((4, 5)) == 4


def test_standby_without_the_goal_api_is_refused(capsys, monkeypatch):
    from autopilot.cli import main

    monkeypatch.delenv("AUTOPILOT_API_TOKEN", raising=False)
    assert main(["run", "--mission", "standby"]) == 2
    assert "waits for goals from the goal API: run with --api" in capsys.readouterr().err
    assert main(["run", "--mission", "standby", "--api", "10.1.2.3:8080"]) == 2
    assert "give a token" in capsys.readouterr().err


def test_photo_cameras_are_cameras_the_mission_uses():
    # (a MAVLink driver attaches, and waits for the video of, exactly these)
    assert load_mission("survey").cameras_used() == ["down"]
    assert load_mission("orbit", ["steps.1.orbit.camera=front"]).cameras_used() == ["front"]
    assert load_mission("orbit", ["steps.1.orbit.images=0"]).cameras_used() == []
    assert load_mission("standby").cameras_used() == ["down"]  # what goals take photos with


def test_a_goal_needing_a_camera_the_vehicle_lacks_is_refused():
    from autopilot.goals import GoalError, GoalManager, validate_goal

    plan = load_mission("standby")
    goals = GoalManager(plan.config)
    step = validate_goal({"orbit": {"center_m": [5, 0], "images": 4}}, plan.config)
    with pytest.raises(GoalError, match="no camera 'down'") as err:
        goals.submit(step, 0.0, MissionStatus.HOVER, True, True, cameras=["front"])
    assert err.value.status == 409
    assert goals.submit(step, 0.0, MissionStatus.HOVER, True, True, cameras=["down"]).active
    # after a landing (status 9) a standby still waiting takes goals again
    goals.goals.clear()
    takeoff = validate_goal({"takeoff": {}}, plan.config)
    assert goals.submit(takeoff, 1.0, MissionStatus.LANDING_COMPLETED, True, False).active


def test_the_rover_frame_is_the_rover_estimate_when_the_step_starts():
    """frame: rover (seed 004): positions from the deck pipeline's estimate of the rover at
    the start of the step; without one, the step fails saying so; lat/lon stay absolute."""
    import numpy as np

    from autopilot.behaviors.base import BehaviorInputs, Status
    from autopilot.estimation.target import TargetEstimate
    from autopilot.mission import build_behavior
    from autopilot.steps import step_kind

    from ..factories import front_camera, vehicle_state

    plan = load_mission("orbit", ["steps.1.orbit.frame=rover", "steps.1.orbit.center_m=[0, 0]",
                                  "steps.1.orbit.images=0"])
    step = plan.steps[1]
    specs = step_kind("orbit").pipelines(step.params, plan.config)
    assert [s.kind for s in specs] == ["deck"]  # the rover's estimate runs with the step
    cameras = {"down": front_camera(), "front": front_camera()}
    state = vehicle_state(1.0, pos=(0.0, 0.0, -3.0))
    out = build_behavior(step, plan.config, cameras).activate(BehaviorInputs(1.0, state))
    assert out.status is Status.FAILED
    assert "no estimate of the rover" in out.reason
    deck = TargetEstimate(1.0, np.array([10.0, 5.0, -0.45]), np.array([1.5, 0.0, 0.0]),
                          np.eye(6) * 1e-4, 0.05, False, 50, True, kind="deck")
    behavior = build_behavior(step, plan.config, cameras)
    out = behavior.activate(BehaviorInputs(1.0, state, target=deck))
    assert out.status is Status.RUNNING
    radius = step.params.radius_m
    centre = np.asarray(out.plan["look_at_ned_m"], dtype=float)
    assert centre[:2] == pytest.approx([10.0, 5.0])
    ring = np.asarray(out.plan["points_ned_m"], dtype=float)
    far = np.linalg.norm(ring[:, :2] - centre[:2], axis=1)
    assert np.median(far) == pytest.approx(radius, abs=0.1)  # (after its entry leg)
    # its altitude is above the deck
    assert ring[len(ring) // 2, 2] == pytest.approx(-0.45 - step.params.altitude_m, abs=0.05)
