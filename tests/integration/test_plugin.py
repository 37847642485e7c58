"""A plugin from another package (examples/autopilot-beacon): a new target kind with its own
scenario section, simulated body, configuration section and detector pipeline, and a new step
kind with its own metrics, terminal figures and report panel, found through the
``autopilot.targets`` / ``autopilot.steps`` entry points. Installed by pip (into a folder of its
own, so the test's environment is left as it was) and flown in the simulator from its own
mission file; nothing under ``autopilot/`` or ``drivers/`` names it."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = ROOT / "examples" / "autopilot-beacon"
MISSION = PLUGIN / "missions" / "hover_beacon.yaml"


def _autopilot(*args: str, site: Path | None, timeout_s: float = 600.0):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    if site is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(
            os.pathsep)
    return subprocess.run([sys.executable, "-m", "autopilot", *args], capture_output=True,
                          text=True, timeout=timeout_s, env=env, cwd=ROOT)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The plugin, installed by pip from its folder (its entry points in its dist-info)."""
    where = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--target", str(where), str(PLUGIN)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    points = next(where.glob("autopilot_beacon-*.dist-info")) / "entry_points.txt"
    assert "autopilot.targets" in points.read_text()
    return where


def test_the_plugin_flies_its_own_mission_with_its_own_target_and_step(site, tmp_path):
    out = tmp_path / "run"
    done = _autopilot("run", "--mission", str(MISSION), "--out", str(out), "--report",
                      site=site)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    # its step's figures, as its kind declared them
    assert re.search(r"step 1 hover_beacon: over the beacon: error RMS 0\.\d+ m", done.stdout), \
        done.stdout[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    step = next(s for s in summary["metrics"]["steps"] if s["name"] == "hover_beacon")
    beacon = step["beacon"]
    # scored against the simulator's truth of the beacon's body: hovering over it, found by
    # its own pipeline (its frames logged on its own channel)
    assert beacon["held"] is True
    assert beacon["rms_hover_error_m"] < 0.4, beacon
    assert beacon["final_hover_error_m"] < 0.4, beacon
    assert beacon["detection_rate"] > 0.3, beacon
    # its status codes, registered by the plugin, reported while it ran and once it succeeded
    from autopilot.flightlog import records as ch
    from autopilot.flightlog.log import read_log

    codes = [r["code"] for r in read_log(out / "flight.mcap")[ch.MISSION_STATUS]]
    assert {40, 41} <= set(codes), codes
    report = (out / "report.html").read_text()
    assert "<h2>Over the beacon</h2>" in report  # its report panel, drawn
    assert report.index("<h2>Trajectories</h2>") < report.index("<h2>Over the beacon</h2>")
    # replay rebuilds its pipeline from the log (registered by kind, loaded from the plugin)
    replayed = _autopilot("replay", str(out), "--json", site=site)
    assert replayed.returncode == 0, replayed.stderr[-2000:]
    replay = json.loads(replayed.stdout)
    assert replay["frames"]["replayed"] > 0
    # ... and recomputes its step's detection figures (its StepKind.replay) from the frames:
    # the same detector on the same frames sees what the flight saw
    now, then = replay["metrics"]["beacon"], replay["flight_metrics"]["beacon"]
    assert set(now) == {"detection_rate", "found_after_s"}, now
    assert now["detection_rate"] == pytest.approx(then["detection_rate"], abs=0.02), (now, then)


def test_the_plugins_sections_are_validated_by_its_models_and_named_on_their_lines(
        site, tmp_path):
    mission = tmp_path / "bad.yaml"
    mission.write_text("name: bad\nsteps:\n  - hover_beacon: {hold_s: 8}\nscenario:\n"
                       "  ball: null\n  beacon: {size_m: 9}\nconfig:\n  targets:\n"
                       "    beacon: {min_area_px: 0}\n")
    done = _autopilot("validate", str(mission), site=site)
    assert done.returncode == 2
    assert "bad.yaml:6: scenario.beacon.size_m: Input should be less than or equal to 5" \
        in done.stderr, done.stderr
    assert "bad.yaml:9: targets.beacon.min_area_px" in done.stderr, done.stderr
    # without the plugin, its keys are unknown and nothing flies
    done = _autopilot("validate", str(MISSION), site=None)
    assert done.returncode == 2
    assert "hover_beacon: unknown step kind" in done.stderr, done.stderr
    assert "scenario.beacon: unknown key" in done.stderr, done.stderr


def test_nothing_under_autopilot_or_drivers_names_the_plugins_kinds():
    names = re.compile(r"beacon", re.IGNORECASE)
    found = [str(path.relative_to(ROOT)) for top in ("autopilot", "drivers")
             for path in (ROOT / top).rglob("*") if path.is_file()
             and path.suffix in (".py", ".yaml", ".html", ".js", ".md")
             and names.search(path.read_text(errors="replace"))]
    assert found == []
