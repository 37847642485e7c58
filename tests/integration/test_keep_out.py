"""Keep-out discs (seed 001: blue = keep away) through the runtime on the lockstep clock: blue
discs the cameras see become zones that every step's setpoints keep out of. follow_ball with
discs on the ball's path and land_pad with a disc beside the pad (on the way to it): the
vehicle's true position (the simulator's ground truth, for scoring only) never enters a disc,
and the missions still complete."""

import asyncio

import numpy as np
import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.mission import load_mission
from autopilot.run import fly

#: on the ball's circle (centre (6, 0), radius 4, clockwise from (2, 0)), where the ball passes
#: about 13 s and 20 s into the run: the follower, 2 m behind on the inside of the curve, would
#: fly over both (0.07 m and 0.34 m from their centres without the guard, seed 1)
BALL_PATH_DISCS = "[{north_east_m: [5.5, 3.9], radius_m: 0.4}, {north_east_m: [10.0, -0.2], " \
                  "radius_m: 0.4}]"
#: 1.5 m short of the pad (2.5, -1.5), on the straight way to it from the take-off point
PAD_SIDE_DISC = "[{north_east_m: [1.2, -0.73], radius_m: 0.4}]"


def _fly(mission, out, overrides):
    plan = load_mission(mission, overrides)
    summary = asyncio.run(fly(plan, out))
    return plan, summary, read_log(out / "flight.mcap")


def _clearances(plan, log) -> dict[str, float]:
    """Each disc's closest approach: the vehicle's true horizontal distance from its centre
    less its radius (negative: it flew over the disc)."""
    discs = plan.mission.scenario.keep_out.discs
    truth = log[ch.GROUND_TRUTH]
    flown = np.array([g["vehicle_position_ned_m"][:2] for g in truth])
    out = {}
    for i, disc in enumerate(discs):
        centre = np.array(truth[0]["bodies"][f"keep_out{i}"]["position_ned_m"][:2])
        out[f"keep_out{i}"] = float(np.linalg.norm(flown - centre, axis=1).min()
                                    - disc.radius_m)
    return out


def _zones(log) -> list[dict]:
    records = log.get(ch.watch_topic("keep_out", "zones"), [])
    return records[-1]["zones"] if records else []


def test_following_the_ball_goes_round_the_discs_on_its_path(tmp_path):
    plan, summary, log = _fly("follow_ball", tmp_path, [
        "steps.1.follow_ball.duration_s=25", f"scenario.keep_out.discs={BALL_PATH_DISCS}"])
    assert summary["status"] == "completed"
    # seed 1: 0.58 m and 0.52 m from the discs' edges (the zone: 0.4 m + 0.5 m margin)
    clearance = _clearances(plan, log)
    assert min(clearance.values()) > 0.2, clearance
    # both discs seen (from the front camera the step follows with), each one zone, placed
    # within the navigation's decimetres of where it is, its size measured
    zones = _zones(log)
    assert len(zones) == 2
    for zone, disc in zip(zones, plan.mission.scenario.keep_out.discs, strict=True):
        assert np.linalg.norm(np.subtract(zone["centre_ne_m"], disc.north_east_m)) < 0.7
        assert zone["radius_m"] == pytest.approx(disc.radius_m, abs=0.06)
    stats = summary["stats"]
    assert stats["guard_interventions"] >= 2  # (at least one round each disc)
    assert stats["guarded_setpoints"] >= 30
    guarded = log[ch.GUARDED_SETPOINTS]
    assert {r["step"] for r in guarded} == {"follow_ball"}
    assert {r["subject"] for r in guarded} == {"zone 0", "zone 1"}
    events = [e["text"] for e in log[ch.MISSION_EVENTS] if e["kind"] == "guard"]
    assert len(events) == stats["guard_interventions"]
    # the follower still followed: the ball seen in (nearly) every frame
    assert summary["metrics"]["follow"]["detection_rate"] >= 0.98


def test_landing_on_the_pad_goes_round_the_disc_beside_it(tmp_path):
    plan, summary, log = _fly("land_pad", tmp_path,
                              [f"scenario.keep_out.discs={PAD_SIDE_DISC}"])
    assert summary["status"] == "completed"
    landing = summary["metrics"]["landing"]
    assert landing["landed"]
    assert landing["on_pad"]
    assert landing["error_m"] <= 0.10
    clearance = _clearances(plan, log)  # seed 1: 0.51 m from the disc's edge
    assert clearance["keep_out0"] > 0.2, clearance
    (zone,) = _zones(log)
    assert zone["radius_m"] == pytest.approx(0.4, abs=0.05)
    assert summary["stats"]["guard_interventions"] >= 1
    assert {r["step"] for r in log[ch.GUARDED_SETPOINTS]} == {"land_pad"}


@pytest.mark.long  # (the counterfactual: what the guard prevented)
def test_without_the_guard_the_landing_flies_over_the_disc(tmp_path):
    plan, summary, log = _fly("land_pad", tmp_path, [
        f"scenario.keep_out.discs={PAD_SIDE_DISC}", "control.keep_out.enabled=false"])
    assert summary["status"] == "completed"
    assert _clearances(plan, log)["keep_out0"] < 0.0  # seed 1: 0.15 m from its centre
    assert summary["stats"]["guard_interventions"] == 0
    assert len(_zones(log)) == 1  # (seen all the same)
