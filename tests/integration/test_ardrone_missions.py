"""The seed missions on the simulated AR.Drone 2.0 in process (sim.firmware: ardrone), in
lockstep: the AR.Drone driver flies the simulator's AR.Drone firmware through the protocol's
bytes. Scored against the simulator's truth (the flight's own metrics); a mission that needs a
global position is refused before anything flies."""

from __future__ import annotations

import asyncio

import pytest

from autopilot.config import ConfigError
from autopilot.mission import load_mission
from autopilot.run import fly, make_vehicle

ARDRONE = ["sim.firmware=ardrone"]


def _fly(mission: str, overrides: list[str]) -> dict:
    plan = load_mission(mission, [*ARDRONE, *overrides])

    async def main():
        summary = await fly(plan, None)
        orphans = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        return summary, orphans

    summary, orphans = asyncio.run(main())
    assert orphans == []
    return summary


def _step(summary: dict, name: str) -> dict:
    return next(s for s in summary["metrics"]["steps"] if s["name"] == name)


def test_follow_ball_on_the_ardrone() -> None:
    summary = _fly("follow_ball", ["steps.1.follow_ball.duration_s=15"])
    assert summary["status"] == "completed", summary.get("reason")
    follow = _step(summary, "follow_ball")["follow"]
    assert follow["detection_rate"] > 0.95
    assert follow["rms_range_error_m"] < 0.4  # (PX4-like vehicle: ~0.06 m; a slower drone)


def test_land_pad_on_the_ardrone_searches_below_its_ceiling() -> None:
    plan = load_mission("land_pad", ARDRONE)
    assert any("vehicle's ceiling" in w for w in plan.warnings)
    summary = _fly("land_pad", [])
    assert summary["status"] == "completed", summary.get("reason")
    landing = _step(summary, "land_pad")["landing"]
    assert landing["on_pad"]
    assert landing["error_m"] < 0.3


def test_a_survey_is_refused_before_takeoff() -> None:
    plan = load_mission("survey", ARDRONE)
    vehicle, _ = make_vehicle(plan)
    assert vehicle.has_global_position is False
    with pytest.raises(ConfigError, match=r"steps\[1\]\.survey.*global_position"):
        asyncio.run(fly(plan, None))


def test_blue_discs_on_the_balls_path_are_kept_out_of(tmp_path) -> None:
    """Seed 001's blue discs as keep-out zones on the AR.Drone too: its true path never
    enters them (closest approach measured from the truth), and the mission completes."""
    from autopilot.flightlog.log import read_log

    from .test_keep_out import BALL_PATH_DISCS, _clearances

    plan = load_mission("follow_ball", [*ARDRONE, "steps.1.follow_ball.duration_s=25",
                                        f"scenario.keep_out.discs={BALL_PATH_DISCS}"])
    summary = asyncio.run(fly(plan, tmp_path))
    assert summary["status"] == "completed", summary.get("reason")
    clearance = _clearances(plan, read_log(tmp_path / "flight.mcap"))
    assert min(clearance.values()) > 0.1, clearance
    assert summary["stats"]["guard_interventions"] >= 1


@pytest.mark.parametrize(("mode", "rate_hz"), [("demo", 15.0), ("full", 200.0)])
def test_in_process_navdata_comes_at_its_modes_rate(mode, rate_hz) -> None:
    from drivers.sim.ardrone_driver import SimArdroneDriver

    plan = load_mission("follow_ball", [*ARDRONE, f"link.navdata={mode}"])
    vehicle, _ = make_vehicle(plan)
    assert isinstance(vehicle, SimArdroneDriver)
    assert vehicle.navdata_mode == mode

    async def main() -> list[float]:
        await vehicle.connect()
        try:
            times = []
            async for state in vehicle.telemetry(buffer=512):
                times.append(state.time_s)
                if times[-1] - times[0] >= 2.0:
                    return times
        finally:
            await vehicle.close()

    times = asyncio.run(main())
    assert (len(times) - 1) / (times[-1] - times[0]) == pytest.approx(rate_hz, rel=0.1)
