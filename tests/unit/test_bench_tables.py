"""The down-camera benches' scoring (a run without its figure is a failure, never dropped) and
the generated tables (autopilot.bench.tables)."""

import json

import pytest

from autopilot.bench import down, tables


def _summary(status="completed", error=0.02, on_pad=True, lost=0.1):
    landing = {"error_m": error, "on_pad": on_pad, "retries": 0, "found_after_s": 3.0,
               "time_to_land_s": 12.0, "touchdown_speed_m_s": 0.4}
    return {"status": status, "metrics": {
        "landing": landing,
        "estimation": {"rms_position_error_m": 0.3, "rms_relative_position_error_m": 0.03,
                       "lost_share": lost}}}


def test_a_run_without_its_figure_or_off_the_pad_is_a_failure():
    spec = down.BENCHES["land_pad"]
    ok = down.score_run(spec, _summary(), 1)
    assert ok["success"]
    assert ok["estimate_lost_share"] == pytest.approx(0.1)
    never_landed = down.score_run(spec, _summary(status="failed", error=None), 2)
    assert not never_landed["success"]
    assert "no error_m" in never_landed["failure"]
    off_pad = down.score_run(spec, _summary(error=0.6, on_pad=False), 3)
    assert not off_pad["success"]
    assert "on_pad" in off_pad["failure"]
    empty = down.score_run(spec, {"status": "failed", "metrics": {}}, 4)
    assert not empty["success"]


def test_failures_count_as_infinite_in_the_median_and_worst():
    spec = down.BENCHES["land_pad"]
    runs = [down.score_run(spec, _summary(error=e), k) for k, e in enumerate((0.01, 0.03), 1)]
    s = down.summarise(runs, spec)
    assert s["error_m_median_all"] == pytest.approx(0.03)  # (the higher of two)
    assert s["error_m_worst_all"] == pytest.approx(0.03)
    runs.append(down.score_run(spec, _summary(status="failed", error=None), 3))
    s = down.summarise(runs, spec)
    assert s["failed"] == 1
    assert s["runs"] == 3
    assert s["error_m_median_all"] == pytest.approx(0.03)
    assert s["error_m_worst_all"] is None  # "fail", never the worst of the others
    assert s["error_m_n"] == 2  # the mean's count says it left one out
    runs.append(down.score_run(spec, _summary(status="failed", error=0.5, on_pad=False), 4))
    s = down.summarise(runs, spec)
    assert s["error_m_median_all"] is None  # half failed: the median is a failure


def _result():
    spec = down.BENCHES["land_pad"]
    rows = {"ours": [down.score_run(spec, _summary(error=0.015), 1)],
            "seed001_detector_lander": [
                down.score_run(spec, _summary(status="failed", error=None), 1)],
            "seed001_detector": [down.score_run(spec, _summary(error=0.03), 1)]}
    table = {r: down.summarise(v, spec) for r, v in rows.items()}
    return {"bench": "land_pad", "mission": "land_pad", "seeds": 1, "quick": False,
            "overrides": [], "compared": "error_m", "rows": {},
            "scenarios": {"default": {
                "overrides": [], "runs": rows, "summary": table,
                "baseline_over_ours": {r: down.ratio(table[r], table["ours"], "error_m")
                                       for r in table if r != "ours"}}}}


def test_quick_checks_find_a_comparison_pointing_the_wrong_way():
    result = _result()
    assert down.quick_checks(result) == []  # ours best; a failed baseline is worse
    s = result["scenarios"]["default"]["summary"]
    s["seed001_detector"]["error_m_median_all"] = 0.01  # a tie (within TIE_M) is fine
    assert down.quick_checks(result) == []
    s["seed001_detector_lander"]["error_m_median_all"] = 0.01  # "better" expected: not
    assert any("seed001_detector_lander" in p for p in down.quick_checks(result))
    s["ours"]["error_m_median_all"] = None
    assert any("ours failed" in p for p in down.quick_checks(result))
    result["scenarios"]["default"]["runs"]["seed001_detector"][0]["scored"] = False
    assert any("seed001_detector did not fly" in p for p in down.quick_checks(result))


def test_tables_are_generated_from_the_json(tmp_path):
    f = tmp_path / "land_pad.json"
    f.write_text(json.dumps(_result()))
    page = tables.render([json.loads(f.read_text())], "2 seeds on a busy machine")
    assert page.startswith("# Benchmarks")
    assert "2 seeds on a busy machine" in page
    assert "| seed 001's detector and landing logic | 0/1 | fail (fail) |" in page
    assert "| ours | 1/1 | 0.015 (0.015) |" in page
    assert "2.0×" in page  # 0.030 ÷ 0.015
    assert "∞" in page
    # the estimate's RMS relative to the vehicle (not the absolute 0.3 m, the navigation's
    # error in it), median (worst), with its lost share
    assert "0.030 (0.030) m (10%)" in page
    assert "0.300" not in page
    assert "Failed runs: seed 001's detector and landing logic, seed 1" in page
    assert "Command: `autopilot bench land_pad --seeds 1 --scenario default --json`" in page
    with pytest.raises(ValueError, match="no table"):
        tables.render([{"bench": "nope"}])


def test_results_of_rows_flown_apart_are_pooled_into_one_table():
    whole = _result()
    parts = []
    for row in ("seed001_detector", "ours", "seed001_detector_lander"):
        part = json.loads(json.dumps(whole))
        for key in ("runs", "summary"):
            part["scenarios"]["default"][key] = {row: whole["scenarios"]["default"][key][row]}
        parts.append(part)
    merged = down.merge(parts)
    data = merged["scenarios"]["default"]
    assert list(data["summary"]) == ["ours", "seed001_detector", "seed001_detector_lander"]
    assert data["baseline_over_ours"]["seed001_detector"] == pytest.approx(2.0)
    page = tables.render(parts)
    assert "flown as 3 processes" in page
    assert page.count("| ours |") == 1


def test_offboard_never_leaves_a_run_without_its_figure_out_of_the_worst():
    from autopilot.bench import offboard

    keys = (*offboard.METRICS["orbit"], "real_time_factor")
    full = {"seed": 1, "status": "completed", **dict.fromkeys(keys, 0.05)}
    short = {"seed": 2, "status": "failed", **dict.fromkeys(keys)}
    s = offboard._summarise([full, short], "orbit")
    assert s["rms_cross_track_m_mean"] == pytest.approx(0.05)
    assert s["rms_cross_track_m_n"] == 1
    assert s["rms_cross_track_m_worst"] is None
    table = offboard.format_table({"seeds": 2, "scenarios": {"orbit": {
        "mission": "orbit", "overrides": [], "summary": {"ours": s},
        "seed004_over_ours": None}}})
    assert "0.050 [1] (fail)" in table


def _follow_result(scenario, seed_status="completed", seed_rms=0.4, seed=1):
    from autopilot.bench import follow

    def run(status, rms):
        follow_metrics = {"detection_rate": 1.0, "rms_range_error_m": rms,
                          "rms_image_error_px": 10.0, "max_lost_s": 0.04,
                          "target_speed_mps_rms": 1.0}
        return follow.score_run({"status": status, "metrics": {
            "follow": follow_metrics, "sim": {"real_time_factor": 3.0},
            "estimation": {"rms_relative_position_error_m": 0.05, "lost_share": 0.02}}}, seed)
    runs = {"estimator": [run("completed", 0.04)], "seed001": [run(seed_status, seed_rms)]}
    return {"bench": "follow_ball", "mission": "follow_ball", "overrides": [], "quick": False,
            "seeds": 1, "seed_start": seed,
            "step_duration_s": None, "controllers": {"estimator": "ours", "seed001": "s1"},
            "scenarios": {scenario: follow._scenario_result([], runs,
                                                            follow.BENCHES["follow_ball"])}}


def test_follow_tables_pool_scenarios_and_show_a_failed_baseline_as_a_failure(tmp_path):
    files = []
    for i, result in enumerate([_follow_result("figure8_2mps_gusts", "failed", 0.9),
                                _follow_result("default")]):
        files.append(tmp_path / f"{i}.json")
        files[-1].write_text(json.dumps(result))
    page = tables.render([json.loads(f.read_text()) for f in files])
    # the bench's order of scenarios, whatever order they were flown in
    assert page.index("**default**") < page.index("**figure8_2mps_gusts**")
    default, figure8 = page.split("**figure8_2mps_gusts**")
    assert "| `seed001` | 1/1 | 0.400 (0.400) |" in default
    assert "10.0×" in default
    assert "0.050 m (2%)" in default  # the estimate's RMS with its lost share
    assert "| `seed001` | 0/1 | fail (fail) |" in figure8
    assert figure8.split("| `seed001` | 0/1 |")[1].split("\n")[0].rstrip().endswith("∞ |")
    assert "Failed runs: `seed001`, seed 1: failed" in figure8
    assert "--scenario default --scenario figure8_2mps_gusts" in page


def test_follow_seeds_flown_apart_are_pooled_and_profiles_kept_apart():
    from autopilot.bench import follow

    a = _follow_result("default", seed_rms=0.2, seed=1)
    b = _follow_result("default", seed_rms=0.6, seed=2)
    merged = follow.merge([b, a])
    data = merged["scenarios"]["default"]
    assert [r["seed"] for r in data["runs"]["seed001"]] == [1, 2]
    assert data["summary"]["seed001"]["rms_range_error_m_median_all"] == pytest.approx(0.6)
    assert merged["seeds"] == 2
    ideal = _follow_result("default", seed=1)
    ideal["overrides"] = ["sim.profile=ideal"]
    page = tables.render([a, b, ideal])
    assert page.count("### `follow_ball`") == 2  # the ideal world in a table of its own
    assert "### `follow_ball` — ideal world" in page
    assert "--seeds 2" in page
    assert "--set sim.profile=ideal" in page
    # a run over seeds already in the table (more seeds, other code) is a table of its own
    again = _follow_result("default", seed_rms=0.4, seed=1)
    page = tables.render([a, b, again])
    assert page.count("### `follow_ball`") == 2
    assert "--row estimator --row seed001 --json" in page  # (seed003 not flown)
    ours_only = _follow_result("default", seed=3)
    ours_only["controllers"] = {"estimator": "ours"}
    assert tables.command_of(ours_only).endswith("--row estimator --json")


def test_a_table_flown_on_another_vehicle_says_which():
    px4 = _follow_result("default", seed=1)
    px4["overrides"] = ["sim.profile=realistic"]
    ardrone = _follow_result("default", seed=1)
    ardrone["overrides"] = ["sim.profile=realistic", "sim.firmware=ardrone"]
    page = tables.render([px4, ardrone])
    assert "### `follow_ball` — realistic world\n" in page
    assert "### `follow_ball` — realistic world, AR.Drone 2.0\n" in page
    assert "--set sim.firmware=ardrone" in page


def test_offboard_and_landing_tables_are_their_own_text_tables():
    from autopilot.bench import landing, offboard

    keys = (*offboard.METRICS["orbit"], "real_time_factor")
    run = {"seed": 1, "status": "completed", **dict.fromkeys(keys, 0.05)}
    s = offboard._summarise([run], "orbit")
    result = {"bench": "offboard", "seeds": 1, "overrides": ["sim.profile=ideal"],
              "scenarios": {"orbit": {"mission": "orbit", "overrides": [],
                                      "summary": {"ours": s}, "seed004_over_ours": None}}}
    summary = {"success_rate": 0.98, "median_error_m": 0.04, "replay": {}}
    land = {"bench": "landing", "mission": "land_on_rover", "rover_speed_m_s": 0.0,
            "trials": 50, "seeds": [0, 49], "overrides": [], "ours": summary,
            "seed004": {**summary, "success_rate": 0.5}}
    page = tables.render([result, land, {**land, "rover_speed_m_s": 1.5}])
    assert "```\norbit and survey: 1 seeds per scenario" in page
    assert "overrides: `sim.profile=ideal`" in page
    assert "`autopilot bench offboard --seeds 1 --scenario orbit --set sim.profile=ideal" in page
    # two landing results (a static and a moving rover): two tables, never pooled
    assert page.count("### `landing`") == 2
    assert "autopilot bench landing --trials 50 --rover-speed 0 --strategy ours " \
           "--strategy seed004 --json" in page
    assert landing.format_table(land) in page


def test_offboard_compares_trackers_against_the_navigation_when_it_has_it():
    from autopilot.bench.offboard import seed004_over_ours

    table = {"ours": {"rms_cross_track_m_mean": 0.32, "rms_cross_track_nav_m_mean": 0.05},
             "seed004": {"rms_cross_track_m_mean": 0.33, "rms_cross_track_nav_m_mean": 0.07}}
    assert seed004_over_ours(table) == pytest.approx(1.4)  # not 0.33/0.32: GNSS swamps both
    for row in table.values():
        del row["rms_cross_track_nav_m_mean"]
    assert seed004_over_ours(table) == pytest.approx(0.33 / 0.32)


def test_the_load_curve_is_a_table_of_its_own_with_its_command():
    from autopilot.bench import load_figures

    def row(hogs, completed, p99, shed):
        return {"hogs": hogs, "completed": completed, "why": None if completed else "lost",
                "tick_ms_p50": 33.0, "tick_ms_p99": p99, "ticks": 500,
                "latency_ms_p50": 50.0, "latency_ms_p95": 60.0, "perception_shed": 0,
                "perception_frames": 600, "perception_shed_share": shed,
                "console_shed": 0, "console_frames_due": 300, "console_shed_share": 0.0,
                "viewer_error": None, "rms_range_error_m": 0.06, "detection_rate": 0.99,
                "vehicle_real_time_factor": 1.0, "loop_lag_p99_ms": 5.0}

    rows = [row(0, True, 44.0, 0.0), row(2, True, 61.0, 0.0), row(4, False, 130.0, 0.2)]
    result = {"bench": "load", "mission": "follow_ball", "hogs": [0, 2, 4], "follow_s": 20.0,
              "driver": "mavsdk", "overrides": [], "vehicle_core": 0, "autopilot_core": 1,
              "viewer_fps": 15.0, "control_rate_hz": 20.0, "rows": rows,
              **load_figures.conclusions(rows, 20.0), "out": None}
    page = tables.render([result])
    assert "### `load`" in page
    assert load_figures.format_table(result) in page
    assert "`autopilot bench load --hogs 0,2,4 --follow-s 20 --driver mavsdk --json`" in page
    again = {**result, "hogs": [3], "repeat": 3, "driver": "pymavlink",
             "overrides": ["scenario.seed=7"], "rows": [row(3, True, 60.0, 0.3)] * 3}
    assert ("`autopilot bench load --hogs 3 --repeat 3 --follow-s 20 --driver pymavlink "
            "--set scenario.seed=7 --json`") in tables.render([again])


def test_an_older_result_without_the_relative_estimate_shows_its_absolute_mean_marked():
    s = {"runs": 2, "estimate_rms_m_mean": 0.25, "estimate_rms_m_n": 2}
    assert down._estimate_cell(s) == "0.250 m abs"
    s.update(estimate_relative_rms_m_median=0.02, estimate_relative_rms_m_worst=0.05,
             estimate_relative_rms_m_n=1)
    assert down._estimate_cell(s) == "0.020 (0.050) m [1]"


def test_the_published_page_is_what_its_inputs_generate(capsys, monkeypatch):
    """docs/benchmarks.md is generated, never edited: its inputs (docs/bench-data/benchmarks.args)
    give it byte for byte."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    monkeypatch.chdir(root)
    assert tables.main(["@docs/bench-data/benchmarks.args"]) == 0
    assert capsys.readouterr().out == (root / "docs" / "benchmarks.md").read_text()


def _mavlink_cell(mission, firmware, driver, status="completed", **figures):
    return {"mission": mission, "firmware": firmware, "driver": driver, "status": status,
            "reason": "" if status == "completed" else "telemetry lost", "wall_s": 80.0,
            "figures": figures}


def test_mavlink_headline_takes_each_scored_step_s_first_figures():
    from autopilot.bench import mavlink

    metrics = {"steps": [
        {"name": "follow_ball", "follow": {"detection_rate": 0.98, "rms_range_error_m": 0.05,
                                            "rms_image_error_px": 12.0}},
        {"name": "no_such_kind", "x": {"y": 1.0}}]}
    figures = mavlink.headline(metrics)
    assert figures  # the follow step's first figures, named group.key
    assert all(k.startswith("follow.") for k in figures)
    assert figures.get("follow.rms_range_error_m") == pytest.approx(0.05)
    assert mavlink.headline({}) == {}


def test_mavlink_cells_flown_apart_are_pooled_and_the_command_names_what_was_flown():
    from autopilot.bench import mavlink

    px4 = {"bench": "mavlink", "cells": [
        _mavlink_cell("land_pad", "px4", "mavsdk", **{"landing.error_m": 0.031}),
        _mavlink_cell("follow_ball", "px4", "mavsdk", **{"follow.rms_range_error_m": 0.05})]}
    ardupilot = {"bench": "mavlink", "cells": [
        _mavlink_cell("follow_ball", "ardupilot", "mavsdk", "failed")]}
    merged = mavlink.merge([px4, ardupilot])
    assert [(c["mission"], c["firmware"]) for c in merged["cells"]] == [
        ("follow_ball", "ardupilot"), ("follow_ball", "px4"), ("land_pad", "px4")]
    table = mavlink.format_table(merged)
    follow_rows = table.split("land_pad")[0]
    assert "ardupilot  mavsdk     failed" in follow_rows
    assert "—" in follow_rows  # the failed flight has no figure, never a number
    assert "0.050" in follow_rows
    assert "(ardupilot through mavsdk: telemetry lost)" in follow_rows  # why, not just "failed"
    assert tables.command_of(merged) == (
        "autopilot bench mavlink --mission follow_ball --mission land_pad --driver mavsdk "
        "--json")
    page = tables.render([px4, ardupilot])
    assert "flown as 2 processes, pooled" in page
    # the same cell flown again is a table of its own, never counted twice
    page = tables.render([px4, px4])
    assert page.count("Command: `autopilot bench mavlink") == 2
