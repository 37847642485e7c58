"""land_on_rover (seed 004) through the runtime on the lockstep clock: the drone catches up with
the rover driving at 1.5 m/s and lands on its deck, with and without the deck's tag; and
``autopilot trials`` on local workers and on a local Ray instance gives the same table."""

import asyncio
import dataclasses
import importlib.util
import json

import pytest

from autopilot.cli import main
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.mission import load_mission
from autopilot.replay import replay
from autopilot.report.html import write_report
from autopilot.run import fly
from autopilot.trials import TrialsError, parse_criterion, parse_vary, run_trials


def test_lands_on_the_moving_deck_within_5_cm(tmp_path):
    plan = load_mission("land_on_rover")
    summary = asyncio.run(fly(plan, tmp_path))
    assert summary["status"] == "completed", summary["reason"]
    landing = summary["metrics"]["landing"]
    assert landing["on_deck"]
    assert landing["error_m"] <= 0.05
    assert landing["retries"] == 0
    assert landing["rover_speed_m_s"] == pytest.approx(1.5, abs=0.05)
    assert landing["relative_horizontal_speed_m_s"] < 0.2
    relative = summary["metrics"]["relative"]
    assert relative["within_2sigma"] >= 0.9  # the σ the controller flew with is honest
    assert relative["availability"]["uwb"] > 0.9
    assert relative["availability"]["tag"] > 0.3
    log = read_log(tmp_path / "flight.mcap")
    assert len(log[ch.sensor_topic("uwb")]) > 50
    assert len(log[ch.sensor_topic("rover")]) > 50
    assert {r["source"] for r in log[ch.RELATIVE_ESTIMATES]} >= {"uwb", "tag", "range", "rover"}
    page = write_report(tmp_path).read_text()
    assert "Landing on the rover" in page
    # the replay drives the deck pipeline with the logged telemetry, UWB ranges, rover reports
    # and (every second) down-camera frame, as they arrived
    again = replay(tmp_path)
    assert again["metrics"]["relative"]["ticks"] == relative["ticks"]
    assert again["metrics"]["relative"]["rms_horizontal_error_m"] == pytest.approx(
        relative["rms_horizontal_error_m"], rel=0.2)
    assert again["metrics"]["relative"]["within_2sigma"] >= 0.9


@pytest.mark.long  # (the landing with the tag runs in CI; this is the same loop, UWB alone)
def test_uwb_only_lands_on_the_deck():
    plan = load_mission("land_on_rover", ["steps.1.land_on_rover.use_marker=false",
                                          "scenario.seed=4"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "completed", summary["reason"]
    landing = summary["metrics"]["landing"]
    assert landing["on_deck"]
    assert landing["error_m"] <= 0.25
    relative = summary["metrics"]["relative"]
    assert relative["availability"]["tag"] == 0.0  # no camera in the loop
    assert relative["within_2sigma"] >= 0.9


HOP = """
name: hop
steps:
  - takeoff: {altitude_m: 1.5}
  - goto: {position_m: [2.0, 0.0, 1.5]}
  - land: {}
scenario: {seed: 0, ball: null}
"""


def test_trials_tabulate_seeds_and_list_the_failing_ones(tmp_path, capsys):
    mission = tmp_path / "hop.yaml"
    mission.write_text(HOP)
    varies = [parse_vary("scenario.wind.gust_mps=0:2")]
    result = run_trials(str(mission), 3, varies=varies, workers=2)
    assert [r["seed"] for r in result.runs] == [0, 1, 2]
    assert result.success_rate == 1.0
    table = result.distribution()
    errors = sorted(r["metrics"]["goto.final_error_m"] for r in result.runs)
    assert table["goto.final_error_m"]["median"] == pytest.approx(errors[1])
    assert table["goto.final_error_m"]["worst"] == pytest.approx(errors[2])
    # a criterion the worst seed misses: it is listed, with the command that replays it
    threshold = (errors[1] + errors[2]) / 2.0
    strict = dataclasses.replace(result, criteria=[
        parse_criterion("completed"), parse_criterion(f"goto.final_error_m<={threshold}")])
    worst_seed = table["goto.final_error_m"]["worst_seed"]
    assert [r["seed"] for r in strict.failing] == [worst_seed]
    command = strict.replay_command(strict.failing[0])
    assert f"scenario.seed={worst_seed}" in command
    assert "scenario.wind.gust_mps=" in command
    # ... and flying those overrides again is the same run (lockstep, the log written alike)
    again = asyncio.run(fly(load_mission(str(mission), strict.failing[0]["overrides"]), tmp_path))
    assert again["metrics"]["goto"]["final_error_m"] == pytest.approx(errors[2], abs=1e-9)
    # the command line: a table, exit status 1 when a seed fails
    code = main(["trials", str(mission), "--trials", "1", "--json",
                 "--success", "goto.final_error_m<=0"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1
    assert out["failing_seeds"] == [0]
    assert out["success_rate"] == 0.0


def test_bad_trial_options_are_refused_clearly():
    with pytest.raises(TrialsError, match="KEY=LOW:HIGH"):
        parse_vary("scenario.seed")
    with pytest.raises(TrialsError, match="LOW <= HIGH"):
        parse_vary("scenario.wind.gust_mps=3:1")
    with pytest.raises(TrialsError, match="--success"):
        parse_criterion("landing.error_m<=")
    with pytest.raises(Exception, match="speed_mps"):  # nothing flies on an invalid mission
        run_trials("land_on_rover", 2, overrides=["scenario.rover.speed_mps=fast"])


@pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                    reason="Ray is not installed (pip install -e '.[test,cluster]')")
@pytest.mark.long  # (starting Ray takes its time; the local trials above run in CI)
def test_trials_on_a_local_ray_instance_give_the_same_table(tmp_path):
    mission = tmp_path / "hop.yaml"
    mission.write_text(HOP)
    varies = [parse_vary("scenario.wind.gust_mps=0:2")]
    local = run_trials(str(mission), 2, varies=varies, workers=2)
    on_ray = run_trials(str(mission), 2, varies=varies, workers=2, cluster="local")
    assert on_ray.backend == "ray"
    assert on_ray.distribution() == local.distribution()
    assert [r["seed"] for r in on_ray.failing] == [r["seed"] for r in local.failing]


def test_land_on_rover_as_a_goal_through_the_api(tmp_path):
    """Standby, then the landing as a runtime goal (the deck pipeline and the sensor streams
    start with it); the goal succeeds on the deck and the run completes."""
    from .test_goal_api import _fly_with_client

    plan = load_mission("standby", ["scenario.rover.path=straight",
                                    "scenario.rover.speed_mps=1.0"])

    def script(client):
        client.wait(lambda s: s["waiting_for_goals"], 60.0, "standby")
        code, body = client.call("POST", "/api/goals", {"land_on_rover": {}})
        assert code == 202, body
        done = client.wait(lambda s: s["goal_id"] is None and not s["in_air"], 120.0,
                           "landed on the rover")
        code, goal = client.call("GET", f"/api/goals/{body['goal_id']}")
        return goal, done

    summary, (goal, _) = _fly_with_client(plan, tmp_path, script)
    assert goal["state"] == "succeeded", goal
    landing = summary["metrics"].get("landing") or {}
    assert landing.get("on_deck"), landing
