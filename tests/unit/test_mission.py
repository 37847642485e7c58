"""Mission files: one test per kind of validation error (each names file, line and key path),
the shipped missions, and the executor's sequencing, fallback and abort."""

import re

import numpy as np
import pytest

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.cli import main
from autopilot.config import ConfigError
from autopilot.mission import MissionExecutor, load_mission, shipped_missions
from drivers.base import FlightMode

from ..factories import vehicle_state

GOOD = """\
name: test_mission
description: a mission for tests
steps:
  - takeoff: {altitude_m: 2.0}
  - follow_ball: {duration_s: 30, mode: lateral}
  - land: {}
scenario:
  seed: 3
  ball: {path: circle, speed_mps: 1.0}
config:
  control:
    follow:
      standoff_m: 2.5
"""


def _write(tmp_path, text):
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


def _error(tmp_path, text, *overrides) -> str:
    with pytest.raises(ConfigError) as err:
        load_mission(str(_write(tmp_path, text)), list(overrides))
    return str(err.value)


def _line(text, needle):
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.mark.parametrize("path", shipped_missions(), ids=lambda p: p.stem)
def test_every_shipped_mission_is_valid(path):
    plan = load_mission(str(path))
    assert plan.steps
    assert plan.mission.description


def test_a_valid_mission_merges_its_config(tmp_path):
    plan = load_mission(str(_write(tmp_path, GOOD)))
    assert [s.name for s in plan.steps] == ["takeoff", "follow_ball", "land"]
    assert plan.config.control.follow.standoff_m == 2.5
    assert plan.mission.scenario.seed == 3


def test_unknown_key(tmp_path):
    text = GOOD.replace("scenario:", "repeat: 3\nscenario:")
    assert _error(tmp_path, text) == f"mission.yaml:{_line(text, 'repeat')}: repeat: unknown key"


def test_unknown_behaviour(tmp_path):
    text = GOOD.replace("  - land: {}", "  - loop_the_loop: {}")
    msg = _error(tmp_path, text)
    assert msg.startswith(f"mission.yaml:{_line(text, 'loop_the_loop')}: steps[2].loop_the_loop: "
                          "unknown step kind")


def test_step_with_two_behaviours(tmp_path):
    text = GOOD.replace("  - land: {}", "  - land: {}\n    hold: {}")
    assert re.match(r"mission.yaml:\d+: steps\[2\]: a step is one behaviour",
                    _error(tmp_path, text))


def test_step_parameter_wrong_type(tmp_path):
    text = GOOD.replace("duration_s: 30", "duration_s: long")
    msg = _error(tmp_path, text)
    assert msg.startswith(f"mission.yaml:{_line(text, 'long')}: steps[1].follow_ball.duration_s: ")
    assert "'long'" in msg


def test_step_parameter_out_of_range(tmp_path):
    text = GOOD.replace("altitude_m: 2.0", "altitude_m: -4")
    msg = _error(tmp_path, text)
    assert msg.startswith(f"mission.yaml:{_line(text, '-4')}: steps[0].takeoff.altitude_m: ")
    assert "greater than 0.3" in msg


def test_step_parameter_unknown(tmp_path):
    text = GOOD.replace("mode: lateral", "mode: lateral, speed: 3")
    assert "steps[1].follow_ball.speed: unknown key" in _error(tmp_path, text)


def test_step_parameter_missing(tmp_path):
    text = GOOD.replace("{duration_s: 30, mode: lateral}", "{mode: lateral}")
    assert re.search(r"mission.yaml:\d+: steps\[1\]\.follow_ball\.duration_s: missing required",
                     _error(tmp_path, text))


def test_bad_choice_in_the_scenario(tmp_path):
    text = GOOD.replace("path: circle", "path: spiral")
    msg = _error(tmp_path, text)
    assert msg.startswith(f"mission.yaml:{_line(text, 'spiral')}: scenario.ball.path: ")
    assert "'circle'" in msg
    assert "'spiral'" in msg


def test_bad_value_in_the_missions_config_section(tmp_path):
    text = GOOD.replace("standoff_m: 2.5", "standoff_m: -1")
    msg = _error(tmp_path, text)
    assert msg.startswith(f"mission.yaml:{_line(text, 'standoff_m')}: "
                          "control.follow.standoff_m: ")


def test_empty_steps(tmp_path):
    text = GOOD.split("steps:")[0] + "steps: []\n"
    assert re.search(r"mission.yaml:\d+: steps: .*at least 1", _error(tmp_path, text))


def test_every_problem_is_reported_at_once_in_line_order(tmp_path):
    text = (GOOD.replace("path: circle", "path: spiral")
            .replace("altitude_m: 2.0", "altitude_m: -4")
            .replace("standoff_m: 2.5", "standoff_m: -1"))
    lines = _error(tmp_path, text, "control.follow.mode=sideways").splitlines()
    assert [line.split(": ")[0:2] for line in lines] == [
        [f"mission.yaml:{_line(text, '-4')}", "steps[0].takeoff.altitude_m"],
        [f"mission.yaml:{_line(text, 'spiral')}", "scenario.ball.path"],
        [f"mission.yaml:{_line(text, 'standoff_m')}", "control.follow.standoff_m"],
        ["--set", "control.follow.mode"],
    ]


def test_command_line_overrides(tmp_path):
    path = str(_write(tmp_path, GOOD))
    plan = load_mission(path, ["steps.1.follow_ball.duration_s=12", "scenario.ball.speed_mps=2",
                               "control.follow.mode=yaw"])
    assert plan.steps[1].params.duration_s == 12
    assert plan.mission.scenario.ball.speed_mps == 2
    assert plan.config.control.follow.mode == "yaw"
    msg = _error(tmp_path, GOOD, "steps.7.land.timeout_s=3")
    assert msg == "--set: steps[7]: no item 7 (the list has 3)"
    assert "--set: control.follow.speed: unknown key" in _error(tmp_path, GOOD,
                                                                 "control.follow.speed=3")


def test_unknown_mission_name():
    with pytest.raises(ConfigError, match=r"no mission of that name.*follow_ball"):
        load_mission("no_such_mission")


def test_cli_refuses_to_fly_an_invalid_mission(tmp_path, capsys):
    bad = _write(tmp_path, GOOD.replace("duration_s: 30", "duration_s: -1"))
    out = tmp_path / "out"
    assert main(["run", "--mission", str(bad), "--out", str(out)]) == 2
    assert "steps[1].follow_ball.duration_s" in capsys.readouterr().err
    assert not out.exists()  # nothing flew, nothing was written


def test_cli_lists_and_validates_missions(capsys):
    assert main(["missions"]) == 0
    listing = capsys.readouterr().out
    assert "follow_ball" in listing
    assert main(["validate", str(shipped_missions()[0])]) == 0
    assert "ok (mission" in capsys.readouterr().out


# -- the executor ---------------------------------------------------------------------------


def _inputs(t=0.0, armed=True, in_air=True):
    return BehaviorInputs(t, vehicle_state(t, armed=armed, mode=FlightMode.HOLD, in_air=in_air))


class _Scripted(Behavior):
    name = "scripted"

    def __init__(self, outcome: Status, after: int = 1, requests=()):
        self.outcome, self.after, self.requests, self.calls = outcome, after, requests, 0

    def activate(self, inputs):
        return BehaviorOutput(Status.RUNNING, requests=self.requests)

    def update(self, inputs):
        self.calls += 1
        if self.calls >= self.after:
            return BehaviorOutput(self.outcome, reason="scripted")
        return BehaviorOutput(Status.RUNNING)


def test_executor_runs_steps_in_order():
    steps = [_Scripted(Status.SUCCEEDED), _Scripted(Status.SUCCEEDED, after=2)]
    ex = MissionExecutor(steps)
    out = ex.start(_inputs())
    assert [(e.kind, e.step_index, e.step, e.text) for e in out.events] == [
        ("step_started", 0, "scripted", "step scripted started")]
    out = ex.update(_inputs())
    assert [(e.kind, e.step_index) for e in out.events] == [("step_succeeded", 0),
                                                           ("step_started", 1)]
    assert out.step_index == 1
    assert not out.finished
    ex.update(_inputs())
    out = ex.update(_inputs())
    assert out.finished
    assert ex.status == "completed"


def test_failed_step_runs_the_fallback_and_the_mission_fails():
    ex = MissionExecutor([_Scripted(Status.FAILED), _Scripted(Status.SUCCEEDED)])
    ex.start(_inputs())
    out = ex.update(_inputs())
    assert [(e.kind, e.step_index, e.text) for e in out.events] == [
        ("step_failed", 0, "step scripted failed: scripted"),
        ("fallback_started", -1, "fallback safe_stop started")]
    assert [r.kind for r in out.requests] == [RequestKind.HOLD]
    out = ex.update(_inputs(t=1.5))
    assert [r.kind for r in out.requests] == [RequestKind.LAND]
    out = ex.update(_inputs(t=5.0, armed=False, in_air=False))
    assert out.finished
    assert ex.status == "failed"


def test_abort_stops_safely():
    ex = MissionExecutor([_Scripted(Status.SUCCEEDED, after=100)])
    ex.start(_inputs())
    out = ex.abort("SIGINT received", _inputs())
    assert ("aborted", 0, "aborted: SIGINT received") in [(e.kind, e.step_index, e.text)
                                                           for e in out.events]
    assert ex.status == "aborted"
    ex.update(_inputs(t=2.0))
    out = ex.update(_inputs(t=4.0, armed=False, in_air=False))
    assert out.finished
    assert ex.status == "aborted"


def test_refused_request_fails_the_step():
    ex = MissionExecutor([_Scripted(Status.SUCCEEDED, after=100,
                                    requests=(VehicleRequest(RequestKind.ARM),))])
    out = ex.start(_inputs(in_air=False))
    assert out.requests[0].kind is RequestKind.ARM
    out = ex.request_failed(out.requests[0], "arm denied: preflight checks failed",
                            _inputs(in_air=False))
    assert ("request_refused", "arm refused: arm denied: preflight checks failed") in [
        (e.kind, e.text) for e in out.events]
    assert ex.status == "failed"
    assert np.all([r.kind is RequestKind.LAND for r in out.requests])


# -- goals (the goal API) in the executor ------------------------------------------------


def test_goals_run_in_place_of_standby_and_return_to_it():
    from autopilot.behaviors.standby import Standby, StandbyParams

    standby = Standby(StandbyParams())
    ex = MissionExecutor([standby])
    out = ex.start(_inputs(0.0))
    assert ex.accepts_goals
    assert out.setpoint is not None  # hovering where it can stop
    # a goal that fails does not end the mission: back to the hover
    out = ex.start_goal(_Scripted(Status.FAILED), 1, _inputs(0.1))
    assert not ex.accepts_goals
    assert ex.goal_running
    out = ex.update(_inputs(0.2))
    kinds = [e.kind for e in out.events]
    assert kinds == ["step_failed", "waiting_for_goals"]
    assert out.events[0].step_index == 1
    assert ex.status == "running"
    assert ex.accepts_goals
    # a cancelled goal: the same
    ex.start_goal(_Scripted(Status.SUCCEEDED, after=100), 2, _inputs(0.3))
    out = ex.cancel_goal(_inputs(0.4))
    assert [e.kind for e in out.events] == ["goal_cancelled", "waiting_for_goals"]
    assert out.step_index == 0
    # landed (disarmed on the ground after flying): standby ends the mission
    ex.start_goal(_Scripted(Status.SUCCEEDED), 3, _inputs(0.5))
    out = ex.update(_inputs(0.6, armed=False, in_air=False))
    assert [e.kind for e in out.events][-2:] == ["step_succeeded", "mission_completed"]
    assert out.finished
    assert ex.status == "completed"


def test_an_abort_during_a_goal_goes_to_the_fallback():
    from autopilot.behaviors.standby import Standby, StandbyParams

    ex = MissionExecutor([Standby(StandbyParams())])
    ex.start(_inputs(0.0))
    ex.start_goal(_Scripted(Status.SUCCEEDED, after=100), 1, _inputs(0.1))
    out = ex.abort("abort requested", _inputs(0.2))
    assert [e.kind for e in out.events][:2] == ["aborted", "fallback_started"]
    assert not ex.goal_running
    assert not ex.accepts_goals
    with pytest.raises(RuntimeError):
        ex.start_goal(_Scripted(Status.SUCCEEDED), 2, _inputs(0.3))


def test_a_goal_that_cannot_start_leaves_the_standby_as_it_was():
    from autopilot.behaviors.standby import Standby, StandbyParams

    class Broken(_Scripted):
        def activate(self, inputs):
            raise ValueError("cannot")

    ex = MissionExecutor([Standby(StandbyParams())])
    ex.start(_inputs(0.0))
    with pytest.raises(ValueError, match="cannot"):
        ex.start_goal(Broken(Status.SUCCEEDED), 1, _inputs(0.1))
    assert ex.accepts_goals
    assert not ex.goal_running
    assert ex.step_index == 0
