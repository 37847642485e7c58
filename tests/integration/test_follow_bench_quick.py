"""The quick follow benches (``autopilot bench follow_ball|follow_marker --quick``): every
seed rule still flies — takes off, follows the whole step without losing the target, lands —
and ours keeps a smaller RMS range error than each of them, on the PX4-like vehicle and (the
ball) on the AR.Drone. One seed, a 10 s step, lockstep."""

import json

import pytest

from autopilot.bench.follow import BENCHES, QUICK_DURATION_S, run_bench
from autopilot.cli import main


# (follow_ball's flights go to a worker process each, as by default; the others fly here, one
# after the other: the results are the same either way, the CI machine's cores are shared)
@pytest.mark.parametrize(("bench", "overrides", "workers"), [
    ("follow_ball", [], None), ("follow_marker", [], 1),
    # the seed rules on the drone they were written for, their commands as its tilt fractions
    ("follow_ball", ["sim.firmware=ardrone"], 1),
], ids=["follow_ball", "follow_marker", "follow_ball_ardrone"])
def test_quick_bench_baselines_fly_and_ours_is_better(bench, overrides, workers):
    said: list[str] = []
    result = run_bench(bench, overrides=overrides, quick=True, workers=workers,
                       announce=said.append)
    assert len(said) == 1
    assert said[0].startswith(f"{len(BENCHES[bench].controllers)} flights")
    assert result["quick"] is True
    assert result["step_duration_s"] == QUICK_DURATION_S
    assert list(result["scenarios"]) == ["default"]
    data = result["scenarios"]["default"]
    assert result["seeds"] == 1
    runs = {c: v[0] for c, v in data["runs"].items()}
    assert all(len(v) == 1 for v in data["runs"].values())
    ours, *baselines = BENCHES[bench].controllers
    assert list(runs) == [ours, *baselines]
    for controller, run in runs.items():
        assert run["status"] == "completed", (controller, run["reason"])
        assert run["success"], controller
        assert run["follow_time_s"] == pytest.approx(QUICK_DURATION_S, abs=0.2), controller
        assert run["detection_rate"] >= 0.9, (controller, run["detection_rate"])
        assert run["max_lost_s"] < 1.0, controller
    for controller in baselines:
        assert runs[controller]["rms_range_error_m"] > runs[ours]["rms_range_error_m"], controller
        assert data["baseline_rms_over_ours"][controller] > 1.0
    assert set(result["controllers"]) == set(runs)


def test_quick_flag_reaches_the_bench(capsys, monkeypatch):
    seen = {}

    def fake_run_bench(bench, mission, overrides, log, scenarios, quick=False, **kw):
        seen.update(bench=bench, quick=quick, workers=kw["workers"])
        return {"bench": bench, "scenarios": {}, "quick": quick, "step_duration_s": 10.0}

    monkeypatch.setattr("autopilot.bench.follow.run_bench", fake_run_bench)
    assert main(["bench", "follow_marker", "--quick", "--json", "--workers", "3"]) == 0
    assert seen == {"bench": "follow_marker", "quick": True, "workers": 3}
    assert json.loads(capsys.readouterr().out)["quick"] is True
