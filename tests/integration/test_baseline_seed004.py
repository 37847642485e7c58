"""Quick comparison for CI (one seed, a static rover: about a minute of CPU): seed 004's
landing baseline — its fused filter (PX4 position, UWB, tag, rover compass, altimeter) and its
gain-scheduled PID, ``strategy: seed004`` — still lands on the deck, and ours lands closer to
its centre. The full comparison is ``autopilot bench landing``."""

import asyncio

from autopilot.mission import load_mission
from autopilot.run import fly

STATIC = ["scenario.rover.speed_mps=0", "scenario.seed=1"]


def _landing(*overrides: str) -> dict:
    summary = asyncio.run(fly(load_mission("land_on_rover", [*STATIC, *overrides]), None))
    return summary


def test_seed004_lands_on_a_static_rover_and_ours_lands_closer():
    seed = _landing("steps.1.land_on_rover.strategy=seed004")
    assert seed["status"] == "completed", seed["reason"]
    seed_landing = seed["metrics"]["landing"]
    assert seed_landing["on_deck"], seed_landing
    # it flew on its own filter: the estimate it landed on is within the deck's half-width
    assert seed["metrics"]["relative"]["final_horizontal_error_m"] < 0.4
    ours = _landing()
    assert ours["status"] == "completed", ours["reason"]
    assert ours["metrics"]["landing"]["error_m"] < seed_landing["error_m"]
