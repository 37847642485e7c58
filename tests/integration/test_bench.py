"""``autopilot bench sitl --json``: runs, and its flight-stack accuracy meets the targets.

Accuracy is deterministic in lockstep, so it is asserted here; speed (real-time factor,
frames per second) depends on the machine and is only reported."""

import json

from autopilot.cli import main


def test_bench_sitl_json(capsys):
    assert main(["bench", "sitl", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("real_time_factor", "hover_rms_m", "camera_fps"):
        assert result[key] > 0
    step = result["step_response"]
    assert step["overshoot_pct"] <= 10.0
    assert step["settle_time_s"] <= 3.0
    assert 0 < step["rise_time_s"] < 2.0
    assert result["hover_rms_m"] <= 0.05
    assert abs(result["camera_fps_sim"] - 30.0) < 0.5
