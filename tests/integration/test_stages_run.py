"""``autopilot run --stages`` on the lockstep clock: every stage of the simulated world and of
the autopilot is counted, on its own thread, and the counts add up to no more than the
process's CPU time."""

from __future__ import annotations

from .simtools import fly_short


def test_a_short_follow_counts_every_stage(tmp_path):
    summary, orphans = fly_short([], tmp_path, stages=True)
    assert summary["status"] == "completed", summary.get("reason")
    assert orphans == []
    stages = summary["stages"]
    cpu = stages["cpu_s"]
    for name in ("physics", "flight stack", "sensors", "render.front", "camera model.front",
                 "codec.front", "detection.ball", "estimation", "control", "logging",
                 "metrics", "rasteriser"):
        assert cpu.get(name, 0.0) > 0.0, name
    assert cpu["other"] >= 0.0
    assert sum(v for k, v in cpu.items() if k != "other") <= stages["process_cpu_s"] + 0.05
    # rendering on the render thread, its camera model and the codec on the camera model's,
    # detection on its own (each stage's CPU counted on the thread that did it)
    threads = stages["threads_cpu_s"]
    assert threads["render"] >= cpu["render.front"]
    assert threads["camera-model"] >= cpu["camera model.front"] + cpu["codec.front"]
    assert stages["threads_cpu_s"]["detect"] >= cpu["detection.ball"]
    per_sim = stages["ms_per_sim_s"]
    assert per_sim["physics"] == round(cpu["physics"] * 1e3 / stages["sim_time_s"], 2)
