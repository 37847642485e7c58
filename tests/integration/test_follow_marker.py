"""follow_marker (seed 002) through the runtime, on the simulator's lockstep clock: the mission
flies, its figures hold, and replay, report and onboard video work for it as for follow_ball."""

import asyncio

import cv2
import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.mission import load_mission
from autopilot.replay import replay
from autopilot.report.html import write_report
from autopilot.report.video import write_video
from autopilot.run import fly

SHORT = ["steps.1.follow_marker.duration_s=20"]


def _fly(overrides, out=None, **kwargs):
    plan = load_mission("follow_marker", [*SHORT, *overrides])
    return asyncio.run(fly(plan, out, **kwargs))


@pytest.fixture(scope="module")
def marker_flight(tmp_path_factory):
    out = tmp_path_factory.mktemp("marker_flight")
    summary = _fly([], out, record_video="")
    return out, summary


def test_follow_marker_closed_loop(marker_flight):
    run_dir, summary = marker_flight
    assert summary["status"] == "completed"
    follow = summary["metrics"]["follow"]
    # the README's figures (detection 1.000, RMS range error 0.045 m over 60 s), with about
    # twice their room, so a regression fails
    assert follow["detection_rate"] >= 0.98
    assert follow["rms_range_error_m"] <= 0.09
    assert follow["max_lost_s"] <= 0.5
    assert follow["false_detection_rate"] == 0.0  # three decoy boards with other ids
    assert follow["standoff_m"] == 1.0
    est = summary["metrics"]["estimation"]
    assert est["lost_share"] == 0.0
    # relative to the vehicle (what following flies); against truth the GNSS navigation's
    # decimetres come on top
    assert est["rms_relative_position_error_m"] <= 0.08
    # the marker pipeline ran on the front camera, logged on its own topic
    log = read_log(run_dir / "flight.mcap")
    frames = log[ch.detection_topic("marker")]
    assert len(frames) == summary["stats"]["frames"]
    found = [f for f in frames if f["detected"]]
    assert {f["marker_id"] for f in found} == {36}
    assert all(len(f["corners_px"]) == 8 for f in found)
    assert ch.detection_topic("ball") not in log or not log[ch.detection_topic("ball")]


def test_replay_reproduces_the_marker_flight(marker_flight):
    run_dir, summary = marker_flight
    result = replay(run_dir)
    flown, again = summary["metrics"]["follow"], result["metrics"]["follow"]
    assert again["detection_rate"] == flown["detection_rate"]
    assert again["frames_in_view"] == flown["frames_in_view"]
    est_flown, est_again = summary["metrics"]["estimation"], result["metrics"]["estimation"]
    assert est_again["ticks"] == est_flown["ticks"]
    assert est_again["rms_position_error_m"] == pytest.approx(
        est_flown["rms_position_error_m"], rel=0.01)


@pytest.mark.long  # (test_replay.py replays with overrides in CI; this is the marker's own)
def test_a_replay_looking_for_another_marker_sees_nothing(marker_flight):
    run_dir, _summary = marker_flight
    blind = replay(run_dir, ["perception.marker.id=7"])
    assert blind["metrics"]["follow"]["detection_rate"] == 0.0


@pytest.mark.long  # (test_video.py and test_report_browser.py cover reports and videos in CI)
def test_report_and_video_of_the_marker_flight(marker_flight, tmp_path):
    run_dir, summary = marker_flight
    page = write_report(run_dir).read_text()
    assert "follow_marker" in page
    assert page.count("<img") >= 4
    path, count = write_video(run_dir, out=tmp_path / "onboard.mp4")
    assert path.stat().st_size > 0
    assert count == summary["stats"]["frames_logged"]
    capture = cv2.VideoCapture(str(path))
    ok, image = capture.read()
    capture.release()
    assert ok
    assert image.shape[:2] == (480, 640)


def test_a_marker_that_is_never_seen_is_searched_for_then_the_fallback_lands():
    # the board carries id 36; the autopilot looks for id 7: it never sees it
    summary = _fly(["perception.marker.id=7", "control.follow.lost_timeout_s=3"])
    assert summary["status"] == "failed"
    assert "target lost" in summary["reason"]


@pytest.mark.long  # (the closed loops above and the bench's stress scenario cover it in CI)
@pytest.mark.parametrize(("mission", "target", "area"),
                         [("follow_ball", "ball", "size_m"),
                          ("follow_marker", "marker", "path_size_m")])
def test_following_under_stress(mission, target, area):
    # a random walk at 2.5 m/s RMS (at most 2 m/s² of acceleration, in a 16 m area) with 3 m/s
    # gusts: the follower at its limits keeps the target in view and close (the README's
    # figures, over 60 s: RMS 0.31 m for the ball, 0.25 m for the marker)
    plan = load_mission(mission, [f"steps.1.{mission}.duration_s=30",
                                  f"scenario.{target}.path=random_walk",
                                  f"scenario.{target}.speed_mps=2.5",
                                  f"scenario.{target}.{area}=16", "scenario.wind.gust_mps=3"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "completed"
    follow = summary["metrics"]["follow"]
    assert follow["target_speed_mps_rms"] >= 2.0
    assert follow["rms_range_error_m"] <= 0.5
    assert follow["max_lost_s"] <= 2.0
    assert follow["detection_rate"] >= 0.95


def test_a_target_turning_at_the_vehicle_s_limit_is_kept_in_view_and_close():
    # a 4 m circle at 4 m/s: 4 m/s² of centripetal acceleration, the follower's own limit. It
    # cuts inside the circle rather than trailing the ball round it (the README: 0.8 m too far
    # on average over 60 s; 3.8 m before)
    plan = load_mission("follow_ball", ["steps.1.follow_ball.duration_s=30",
                                        "scenario.ball.speed_mps=4"])
    summary = asyncio.run(fly(plan, None))
    assert summary["status"] == "completed"
    follow = summary["metrics"]["follow"]
    assert follow["detection_rate"] >= 0.95
    assert follow["max_lost_s"] <= 0.5
    assert follow["mean_range_error_m"] <= 1.6
