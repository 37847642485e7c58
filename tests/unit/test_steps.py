"""The step registry: every shipped kind is complete, missions validate against it, plans
declare their pipelines, and a new kind is one registration away."""

import pytest

from autopilot.behaviors.base import Behavior, BehaviorInputs, BehaviorOutput, Params, Status
from autopilot.config import ConfigError
from autopilot.mission import build_behavior, load_mission
from autopilot.pipeline import pipeline_kinds
from autopilot.steps import STEP_KINDS, StepContext, StepKind, register, step_kind
from tests.factories import front_camera, vehicle_state


def test_shipped_kinds_and_pipelines():
    assert {"takeoff", "hold", "land", "follow_ball", "follow_marker"} <= set(STEP_KINDS)
    assert {"ball", "marker"} <= set(pipeline_kinds())
    for kind in STEP_KINDS.values():
        assert kind.description
        if kind.metrics is not None:
            assert "trajectory" in kind.report


def test_a_plan_knows_what_each_step_needs():
    plan = load_mission("follow_marker")
    assert [spec.key for spec in plan.pipelines(0)] == []  # takeoff: no camera
    (marker,) = plan.pipelines(1)
    assert (marker.kind, marker.camera, marker.truth_body, marker.target_size_m) == \
        ("marker", "front", "marker", 0.16)
    assert plan.cameras_used() == ["front"]
    assert load_mission("follow_ball").all_pipelines()["ball"].target_size_m == 0.2


def test_the_followed_camera_must_exist():
    plan = load_mission("follow_marker", ["perception.marker.camera=rear"])
    with pytest.raises(ConfigError, match="no camera 'rear'"):
        build_behavior(plan.steps[1], plan.config, {"front": front_camera()})


def test_a_new_step_kind_is_one_registration(tmp_path, monkeypatch):
    class SpinParams(Params):
        turns: int = 1

    class Spin(Behavior):
        name = "spin"

        def __init__(self, params):
            self.params = params

        def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
            return BehaviorOutput(Status.SUCCEEDED)

        def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
            return BehaviorOutput(Status.SUCCEEDED)

    # registered for this test only (the registry is one dict, read wherever kinds are used):
    # monkeypatch takes "spin" out again afterwards
    monkeypatch.setitem(STEP_KINDS, "spin", None)
    del STEP_KINDS["spin"]
    register(StepKind("spin", SpinParams, lambda params, ctx: Spin(params),
                      description="turn on the spot"))
    with pytest.raises(ValueError, match="registered twice"):
        register(StepKind("spin", SpinParams, lambda params, ctx: Spin(params)))
    path = tmp_path / "spin.yaml"
    path.write_text("name: spin\nsteps:\n  - takeoff: {altitude_m: 2}\n  - spin: {turns: 3}\n"
                    "  - land: {}\n")
    plan = load_mission(str(path))
    assert plan.steps[1].params.turns == 3
    behaviour = build_behavior(plan.steps[1], plan.config, {})
    assert behaviour.activate(BehaviorInputs(0.0, vehicle_state())).status is \
        Status.SUCCEEDED
    assert step_kind("spin").pipelines(plan.steps[1].params, plan.config) == ()
    assert isinstance(StepContext(plan.config, {}), StepContext)
