"""The operator console in a real browser: Playwright driving Debian's chromium (launched with
``executable_path``: ``playwright install`` downloads a browser of its own, which a machine
without the internet cannot fetch). Against a lockstep follow_ball flight: the page loads and
video frames arrive, the values panel changes, F switches the follow mode, Y hands the vehicle
to the keys, W held moves it forward and key up stops it (hover), closing the page with W held
leaves it hovering, and Y on a new page gives it back to the autopilot. Skipped, saying so,
without chromium or Playwright."""

from __future__ import annotations

import math
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from autopilot.mission import load_mission

from .test_goal_api import Client, _fly_with_client

CHROMIUM = next(
    (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
try:
    from playwright.sync_api import sync_playwright
except ImportError:  # pragma: no cover - the test extra installs it
    sync_playwright = None

pytestmark = [
    pytest.mark.serial,  # a real-time flight watched in Chromium
    pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium (Debian: apt install chromium)"),
    pytest.mark.skipif(sync_playwright is None,
                       reason="needs Playwright (pip install -e '.[test]')"),
]

MISSION = """
name: follow_ball_console
description: follow_ball for long enough to fly it from the console
steps:
  - takeoff: {altitude_m: 1.7}
  - follow_ball: {duration_s: 600}
  - land: {}
fallback: land
scenario:
  seed: 1
  ball: {path: circle, speed_mps: 0.5, diameter_m: 0.2, color: orange, height_m: 1.5,
         start_distance_m: 2.0, start_delay_s: 7.0, size_m: 8.0}
  distractors: 2
"""


def _speed(s) -> float:
    return float(np.linalg.norm(s["velocity_ned_m_s"]))


def _forward(s, heading: float) -> float:
    return s["position_ned_m"][0] * math.cos(heading) + s["position_ned_m"][1] * math.sin(heading)


def _values(page) -> dict[str, str]:
    return page.eval_on_selector_all(
        "#values td[data-name]", "cells => Object.fromEntries(cells.map("
        "c => [c.dataset.name, c.textContent]))")


def _wait(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out: {what}")


def test_console_in_chromium(tmp_path):
    mission = tmp_path / "follow_ball_console.yaml"
    mission.write_text(MISSION)
    plan = load_mission(str(mission))
    shots = Path(os.environ.get("AUTOPILOT_CONSOLE_SHOTS", tmp_path))

    def script(c: Client):
        c.wait(lambda s: s["status_code"] == 13 and s["phase"] == "tracking", 120, "tracking")
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                                         args=["--no-sandbox"])
            # (bypass_csp: Playwright evaluates its waits as strings, which the page's CSP
            # forbids)
            page = browser.new_page(viewport={"width": 1200, "height": 900}, bypass_csp=True)
            page.goto(c.base + "/")
            page.wait_for_function("window.consoleState.frames > 5", timeout=60_000)
            first = _values(page)
            assert "follow.range_m" in first
            assert "det.score" in first
            _wait(lambda: _values(page) != first, 20, "the values panel changing")
            page.screenshot(path=str(shots / "console_follow_ball.png"))
            # F: lateral/yaw following, as seed 001's /toggle_lateral
            mode = _values(page)["follow.mode"]
            page.keyboard.press("f")
            _wait(lambda: _values(page).get("follow.mode") not in (None, mode), 20,
                  "the follow mode switching")
            # Y: manual; W held moves forward, key up hovers
            page.keyboard.press("y")
            _wait(lambda: page.inner_text("#controlBadge") == "MANUAL", 20, "MANUAL")
            status = c.wait(lambda s: s["control"] == "manual", 20, "manual")
            heading = math.radians(status["yaw_deg"])
            start = _forward(status, heading)
            page.keyboard.down("w")
            c.wait(lambda s: _forward(s, heading) - start > 1.5 and _speed(s) > 0.8, 60,
                   "moving forward with W held")
            page.screenshot(path=str(shots / "console_manual_w.png"))
            page.keyboard.up("w")
            stopped = c.wait(lambda s: _speed(s) < 0.15, 60, "hover after key up")
            t0, p0 = stopped["time_s"], np.array(stopped["position_ned_m"])
            later = c.wait(lambda s: s["time_s"] > t0 + 2.0, 30, "2 s of hover")
            assert np.linalg.norm(np.array(later["position_ned_m"]) - p0) < 0.3
            assert later["mode"] == "offboard"
            # W held, then the tab closes: hover
            page.keyboard.down("w")
            c.wait(lambda s: _speed(s) > 0.8, 60, "moving again")
            page.close()
            closed = c.call("GET", "/api/status")[1]
            stopped = c.wait(lambda s: _speed(s) < 0.15, 60, "hover after the page closed")
            assert stopped["time_s"] - closed["time_s"] < 4.0
            assert stopped["control"] == "manual"
            assert stopped["in_air"]
            # Y on a new page: the autopilot follows again
            page = browser.new_page(bypass_csp=True)
            page.goto(c.base + "/")
            page.wait_for_function("window.consoleState.hello !== null", timeout=30_000)
            page.keyboard.press("y")
            _wait(lambda: page.inner_text("#controlBadge") == "AUTOPILOT", 20, "AUTOPILOT")
            c.wait(lambda s: s["control"] == "autopilot" and s["step"] == "follow_ball", 20,
                   "the autopilot back on the follow step")
            browser.close()
        c.call("POST", "/api/abort")
        return True

    summary, ok = _fly_with_client(plan, tmp_path / "run", script, console=True)
    assert ok
    assert summary["status"] == "aborted"  # (the abort that ended it)
    assert (shots / "console_follow_ball.png").stat().st_size > 10_000
