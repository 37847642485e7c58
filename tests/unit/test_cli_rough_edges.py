"""A new user's first hour with the command line: exit codes as documented, no traceback,
errors naming what the user typed, "did you mean", and figures that say what they are."""

from __future__ import annotations

import argparse

import pytest

from autopilot.cli import EXIT_ABORTED, EXIT_FAILED, EXIT_LINK, EXIT_OK, EXIT_USAGE, main
from autopilot.cli.run import exit_code, prepare_out_dir, summary_lines
from autopilot.config import InputError


def _run(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return code, captured.out + captured.err


# -- exit codes ----------------------------------------------------------------------------

def _summary(status: str, signal: str | None = None) -> dict:
    return {"status": status, "signal": signal}


def test_only_a_signal_exits_130():
    assert exit_code(_summary("completed")) == EXIT_OK
    assert exit_code(_summary("completed", "SIGINT")) == EXIT_OK  # it finished anyway
    assert exit_code(_summary("aborted")) == EXIT_FAILED  # a failsafe, the console, the API
    assert exit_code(_summary("failed")) == EXIT_FAILED
    assert exit_code(_summary("aborted", "SIGINT")) == EXIT_ABORTED
    assert exit_code(_summary("aborted", "SIGTERM")) == EXIT_ABORTED


def test_the_api_clients_without_an_api_exit_4(capsys):
    for args in (["status"], ["abort"], ["cancel", "g1"], ["goal", '{"hold": {}}']):
        code, text = _run(capsys, *args, "--api", "127.0.0.1:9")
        assert code == EXIT_LINK, (args, text)
        assert "no goal API at http://127.0.0.1:9" in text


def test_a_goal_that_is_neither_json_nor_a_file(capsys):
    code, text = _run(capsys, "goal", "takeoff")
    assert code == EXIT_USAGE
    assert "not JSON" in text
    assert "nor a file" in text


# -- --out -----------------------------------------------------------------------------------

def test_out_onto_a_file_names_the_option(capsys, tmp_path):
    file = tmp_path / "afile"
    file.write_text("")
    code, text = _run(capsys, "run", "--mission", "follow_ball", "--out", str(file))
    assert code == EXIT_USAGE
    assert f"--out {file}: is a file, not a folder" in text


def test_out_where_nothing_can_be_written(capsys):
    code, text = _run(capsys, "run", "--mission", "follow_ball", "--out", "/proc/nope/run")
    assert code == EXIT_USAGE
    assert "--out /proc/nope/run: cannot write there" in text


def test_out_onto_a_previous_run_is_refused_unless_overwrite(tmp_path):
    for name in ("flight.mcap", "summary.json", "report.html"):
        (tmp_path / name).write_text("old")
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.jpg").write_text("old")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match=r"already holds a flight .*--overwrite"):
        prepare_out_dir(tmp_path, True, False)
    prepare_out_dir(tmp_path, True, True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # only the run's own
    prepare_out_dir(tmp_path / "new" / "deeper", True, False)  # made, parents too
    assert (tmp_path / "new" / "deeper").is_dir()


# -- errors that name what was typed, with "did you mean" ------------------------------------

@pytest.mark.parametrize(("args", "expected"), [
    (["run", "--mission", "follow_bal"], "did you mean 'follow_ball'?"),
    (["validate", "land_pda"], "did you mean 'land_pad'?"),
    (["run", "--mission", "follow_ball", "--set", "control.trajectori.max_path_m=3"],
     "--set: control.trajectori: unknown key (did you mean 'trajectory'?)"),
    (["run", "--mission", "follow_ball", "--set", "sim.camras.front.rate_hz=3"],
     "--set: sim.camras: unknown key (did you mean 'cameras'?)"),
    (["run", "--mission", "follow_ball", "--set", "steps.1.follow_ball.duraton_s=3"],
     "--set: steps[1].follow_ball.duraton_s: unknown key (did you mean 'duration_s'?)"),
    (["run", "--mission", "follow_ball", "--fault", "camera_dropot"],
     "unknown kind 'camera_dropot' (did you mean 'camera_dropout'?)"),
    (["run", "--mission", "follow_ball", "--fault", "camera_dropout:strt_s=1"],
     "camera_dropout has no parameter 'strt_s' (did you mean 'start_s'?) (its parameters: "
     "start_s, duration_s, camera)"),
    (["run", "--mission", "follow_ball", "--fault", "link_loss:0.3"],
     "(link_loss's parameters: start_s, duration_s, fraction"),
    (["validate", "follow_ball", "--set", "sim.wind.steady_ned_m_s=[0,3]"],
     "--set: sim.wind.steady_ned_m_s[2]: missing item 2: too few items"),
    (["bench", "follow_ball", "--scenario", "defalt"],
     "--scenario defalt: no such scenario (did you mean 'default'?)"),
    (["bench", "follow_ball", "--workers", "0"], "--workers"),
    (["bench", "land_pad", "--workers", "0"], "--workers"),
    (["run", "--mission", "follow_ball", "--calibration", "/nonexistent/cam.yaml"],
     "--calibration: /nonexistent/cam.yaml: no such calibration file"),
    (["run", "--mission", "follow_ball", "--calibration", "belly=/nonexistent/cam.yaml"],
     "the simulated vehicle has no camera 'belly'"),
])
def test_errors_name_the_argument_and_the_nearest_name(capsys, args, expected, tmp_path):
    code, text = _run(capsys, *args)
    assert code == EXIT_USAGE
    assert expected in text, text
    assert not any(tmp_path.iterdir())


def test_a_step_kind_typo_in_a_mission_file(capsys, tmp_path):
    mission = tmp_path / "m.yaml"
    mission.write_text("name: m\nsteps:\n  - takeof: {altitude_m: 2}\n  - hold: {duraton_s: 1}\n")
    code, text = _run(capsys, "validate", str(mission))
    assert code == EXIT_USAGE
    assert "m.yaml:3: steps[0].takeof: unknown step kind (did you mean 'takeoff'?)" in text
    assert "m.yaml:4: steps[1].hold.duraton_s: unknown key (did you mean 'duration_s'?)" in text


@pytest.mark.parametrize(("args", "expected"), [
    (["rn"], "did you mean 'run'?"),
    (["bench", "folow_ball"], "did you mean 'follow_ball'?"),
])
def test_a_mistyped_command_or_bench(capsys, args, expected):
    code, text = _run(capsys, *args)
    assert code == EXIT_USAGE
    assert expected in text


def test_validate_takes_what_run_takes(capsys):
    for name in ("follow_ball", "orbit", "land_on_rover"):
        code, text = _run(capsys, "validate", name)
        assert code == EXIT_OK, text
        assert f"{name}: ok (mission {name}" in text


def test_validate_a_file_that_is_not_utf8(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"name: x\n\xff\xfe: 1\n")
    code, text = _run(capsys, "validate", str(bad))
    assert code == EXIT_USAGE
    assert "not UTF-8 text" in text


def test_the_run_folder_commands_say_what_is_missing(capsys, tmp_path):
    for command in ("report", "video", "replay"):
        code, text = _run(capsys, command, str(tmp_path / "nope"))
        assert code == EXIT_USAGE, (command, text)
        assert "no such folder" in text, (command, text)
        code, text = _run(capsys, command, str(tmp_path))
        assert code == EXIT_USAGE, (command, text)
        assert "flight.mcap: no such file" in text, (command, text)


# -- an orbit whose centre the photos will not show ------------------------------------------

def test_an_orbit_that_will_not_see_its_centre_warns(capsys):
    code, text = _run(capsys, "validate", "orbit")
    assert code == EXIT_OK
    assert "warning" not in text  # the shipped orbit sees it
    code, text = _run(capsys, "validate", "orbit", "--set", "steps.1.orbit.altitude_m=3",
                      "--set", "steps.1.orbit.radius_m=10")
    assert code == EXIT_OK
    assert "warning: steps[1].orbit: the centre will not be in the photos" in text
    code, text = _run(capsys, "validate", "orbit", "--set", "steps.1.orbit.camera=front")
    assert "the front camera (pitch -5°) sees it" in text


# -- what the terminal says at the end -------------------------------------------------------

def _metrics(step: str, **groups) -> dict:
    return {"steps": [{"index": 1, "name": step, **groups}], "sim": {},
            "latency_ms": {"samples": 0}}


def test_each_step_prints_its_main_figures_with_what_they_are(tmp_path):
    hover = summary_lines({"status": "completed", "reason": "", "sim_time_s": 30.0,
                           "wall_time_s": 20.0, "metrics": {
                               **_metrics("hover_image",
                                          hover={"rms_horizontal_error_m": 0.04,
                                                 "detection_rate": 1.0}),
                               "sim": {"real_time_factor": 1.5}}}, tmp_path)
    assert "step 1 hover_image: horizontal error over the image RMS 0.040 m, image found in " \
           "100.0 %" in "\n".join(hover)
    land = summary_lines({"status": "completed", "reason": "", "sim_time_s": 30.0,
                          "wall_time_s": 20.0, "metrics": {
                              **_metrics("land_pad", landing={"on_pad": True, "error_m": 0.07},
                                         estimation={"lost_share": 0.226}),
                              "sim": {"real_time_factor": 1.5}}}, tmp_path)
    text = "\n".join(land)
    assert "step 1 land_pad: on the pad yes, touchdown error 0.070 m" in text
    assert "target lost (no estimate) 22.6 % of the step" in text


def test_nothing_flown_says_so(tmp_path):
    lines = summary_lines({"status": "aborted", "reason": "SIGINT received", "flown": False,
                           "sim_time_s": 1.3, "wall_time_s": 1.3,
                           "metrics": {"sim": {"real_time_factor": 1.0},
                                       "latency_ms": {"samples": 0}}}, tmp_path)
    assert lines[1].startswith("nothing flown (stopped after 1.3 s)")
    assert not any("flew for" in line or "simulated" in line for line in lines)


def test_every_command_and_bench_has_a_description():
    from autopilot.cli import build_parser

    def parsers(parser):
        yield parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    yield from parsers(sub)

    for parser in parsers(build_parser()):
        assert parser.description, parser.prog
        assert "%%" not in parser.format_help(), parser.prog


def test_bench_help_prints(capsys):
    assert main(["bench", "--help"]) == EXIT_OK
    assert "soak" in capsys.readouterr().out
