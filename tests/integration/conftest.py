"""A logged flight shared by the tests that read one back (replay, video, report)."""

from __future__ import annotations

import asyncio
import json

import pytest

from autopilot.mission import load_mission
from autopilot.run import fly


@pytest.fixture(scope="session")
def logged_flight(tmp_path_factory):
    """A short lockstep follow_ball flight with every front-camera frame logged (as
    ``autopilot run --record-video``): its folder and summary."""
    out = tmp_path_factory.mktemp("flight")
    plan = load_mission("follow_ball", ["steps.1.follow_ball.duration_s=10"])
    summary = asyncio.run(fly(plan, out, record_video=""))
    assert summary["status"] == "completed"
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"
    return out, summary
