"""Whole missions through the runtime, on the simulator's lockstep clock."""

import asyncio
import functools
import json
import os
import signal

import pytest
from mcap.reader import make_reader

from autopilot import values
from autopilot.behaviors.flight import SafeStop
from autopilot.flightlog import records as ch
from autopilot.mission import load_mission
from autopilot.runtime import Runtime, detection_charge
from autopilot.runtime.control import ControlLoop
from drivers.base import FlightMode

from .simtools import fly_short

_fly = fly_short


def test_follow_ball_closed_loop(tmp_path):
    # the shipped mission as it is (60 s of following): the figures the README quotes
    summary, orphans = _fly(["steps.1.follow_ball.duration_s=60"], tmp_path)
    assert orphans == []
    assert summary["status"] == "completed"
    follow = summary["metrics"]["follow"]
    # the shipped (realistic) world: the README's figures (detection 0.999, RMS range error
    # 0.042 m over 60 s; the target ≤ 0.10 m) with about twice their room
    assert summary["sim"]["profile"] == "realistic"
    assert follow["detection_rate"] >= 0.98
    assert follow["rms_range_error_m"] <= 0.09
    assert follow["max_lost_s"] <= 0.5
    assert follow["false_detection_rate"] == 0.0
    # the estimate the controller flew on, at every control tick, never lost. Against truth it
    # carries the GNSS navigation's decimetres (one slow draw in a minute); relative to the
    # vehicle — what following flies — centimetres, and its σ never overconfident (an
    # overconfident filter scores far below 0.8; ours is on the timid side, see the benches)
    est = summary["metrics"]["estimation"]
    assert est["lost_share"] == 0.0
    assert est["rms_relative_position_error_m"] <= 0.12
    assert est["relative_within_2sigma"] >= 0.8
    assert 0.1 <= est["rms_position_error_m"] <= 1.5
    # lockstep: capture → setpoint is the camera's own latency (with its jitter) plus the
    # detection's charge (to the next 2 ms physics step); the rest takes no simulated time
    cfg = load_mission("follow_ball").config
    cam = cfg.sim.cameras["front"]
    expected_ms = 1e3 * (cam.latency_s + detection_charge(cfg, ["ball"]))
    p95 = summary["metrics"]["latency_ms"]["p95"]
    assert expected_ms <= p95 <= expected_ms + 1e3 * 3 * cam.latency_jitter_s + 2.0
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    for key in ("status", "mission", "driver", "sim_time_s", "wall_time_s"):
        assert key in on_disk
    assert on_disk["metrics"]["sim"]["real_time_factor"] > 0
    # what fly() returns is what it wrote (made again from it once the flight's objects are
    # freed, so that nothing the caller keeps pins the memory the flight used), and the
    # flight's debug values went with it
    assert summary == on_disk
    assert values.board().snapshot() == {}

    with open(tmp_path / "flight.mcap", "rb") as f:
        reader = make_reader(f)
        channels = {c.topic: c for c in reader.get_summary().channels.values()}
        schemas = reader.get_summary().schemas
        counts = {}
        for _, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                json.loads(message.data)  # strict JSON
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    for topic in (ch.VEHICLE_STATE, ch.detection_topic("ball"), ch.TARGET_ESTIMATES, ch.SETPOINTS,
                  ch.GROUND_TRUTH, ch.MISSION_EVENTS, ch.CAMERA_INFO, ch.MISSION_PLAN):
        assert counts.get(topic, 0) > 0, topic
        assert channels[topic].message_encoding == "json"
        assert schemas[channels[topic].schema_id].encoding == "jsonschema"
    # the control-time target the behaviour flew on, at every control tick of the step
    assert counts[ch.CONTROL_TARGET] >= 60 * cfg.runtime.control_rate_hz
    # camera frames of the whole flight (the frame log does not depend on which step runs),
    # every second one (the simulator's default), as Foxglove's CompressedImage
    images = ch.camera_image_topic("front")
    assert counts[images] == summary["stats"]["frames_logged"]
    rate = cfg.sim.cameras["front"].rate_hz
    assert counts[images] == pytest.approx(summary["sim_time_s"] * rate / 2, abs=3)
    # the detector ran only while follow_ball did (takeoff and landing need no camera), on
    # every frame the camera did not drop (~1 %)
    drop = cfg.sim.cameras["front"].drop_fraction
    assert summary["stats"]["frames"] == pytest.approx(60 * rate * (1 - drop),
                                                       abs=3 + 3 * (60 * rate * drop) ** 0.5)
    assert channels[images].message_encoding == "protobuf"
    assert schemas[channels[images].schema_id].name == "foxglove.CompressedImage"


def test_lateral_mode_closed_loop():
    summary, _ = _fly(["control.follow.mode=lateral"])
    assert summary["status"] == "completed"
    assert summary["metrics"]["follow"]["detection_rate"] >= 0.95
    assert summary["metrics"]["follow"]["rms_range_error_m"] <= 0.35


def test_invisible_target_is_searched_for_then_the_fallback_lands():
    # the world has a red ball; the autopilot looks for orange: it never sees it
    summary, _ = _fly(["scenario.ball.color=red", "control.follow.lost_timeout_s=3"])
    assert summary["status"] == "failed"
    assert "target lost" in summary["reason"]


class _Probe:
    """Hooks into a run to act at a simulated time and watch the vehicle."""

    def __init__(self, monkeypatch, action):
        self.seen = {}
        original = Runtime.run
        probe = self

        async def run(runtime):
            watcher = asyncio.ensure_future(action(runtime, probe, asyncio.current_task()))
            try:
                return await original(runtime)
            finally:
                watcher.cancel()

        monkeypatch.setattr(Runtime, "run", run)


@pytest.mark.long
def test_stale_telemetry_during_the_return_home_does_not_stop_it(monkeypatch, tmp_path):
    """The battery reserve sent the vehicle home (its own RTL); then its telemetry stops. A hold
    would stop the return and leave it hovering blind: the runtime stops its setpoints and lets
    the vehicle's return go on to the landing."""
    import autopilot.runtime.failsafes as rt

    class ShortReturn(rt.ReturnHome):  # blind, the return cannot see its end: 60 s, not 600
        def __init__(self) -> None:
            super().__init__(timeout_s=60.0)

    monkeypatch.setattr(rt, "ReturnHome", ShortReturn)

    async def stop_telemetry_on_the_way_home(runtime, probe, _task):
        while not runtime.flight.executor.in_fallback:
            await runtime.clock.sleep(0.1)
        await runtime.clock.sleep(1.0)
        probe.seen["stopped_s"] = runtime.clock.now()
        await runtime.vehicle.inject_failure("telemetry")

    probe = _Probe(monkeypatch, stop_telemetry_on_the_way_home)
    summary, orphans = _fly(["failsafe.battery.reserve_fraction=0.2",
                             "sim.params={RTL_RETURN_ALT: 5}",
                             "scenario.faults=[{kind: battery_sag, start_s: 12, "
                             "remaining_fraction: 0.15}]"], tmp_path)
    assert orphans == []
    from autopilot.flightlog.log import read_log

    log = read_log(tmp_path / "flight.mcap")
    events = [(e["time_s"], e["text"]) for e in log[ch.MISSION_EVENTS]]
    assert "fallback return_home started" in [text for _, text in events]
    stale_at = next(t for t, text in events if text.startswith("telemetry silent"))
    assert stale_at > probe.seen["stopped_s"]
    assert "the vehicle's return goes on" in next(text for t, text in events if t == stale_at)
    assert not [text for t, text in events if t >= stale_at and text.startswith("request")]
    # the simulated flight stack's own record: it returned and landed, never held
    after = [r for r in log[ch.GROUND_TRUTH] if r["time_s"] >= stale_at]
    assert {r["mode"] for r in after if r["armed"]} <= {"return", "land"}
    assert after[-1]["armed"] is False
    assert after[-1]["vehicle_position_ned_m"][2] > -0.3
    assert summary["metrics"]["safety"]["ended_safe"] is True


def test_ctrl_c_in_flight_lands_and_disarms(monkeypatch, tmp_path):
    async def interrupt(runtime, probe, _task):
        await runtime.clock.sleep_until(15.0)  # following by then
        probe.seen["step"] = runtime.flight.cursor.step
        os.kill(os.getpid(), signal.SIGINT)

    probe = _Probe(monkeypatch, interrupt)
    summary, orphans = _fly([], tmp_path, handle_signals=True)
    assert probe.seen["step"] == "follow_ball"
    assert summary["status"] == "aborted"
    assert "SIGINT" in summary["reason"]
    assert orphans == []
    # ended landed and disarmed, in bounded (simulated) time
    from autopilot.flightlog.log import read_log

    log = read_log(tmp_path / "flight.mcap")
    last = log[ch.VEHICLE_STATE][-1]
    assert last["armed"] is False
    assert last["landed_state"] == "on_ground"
    assert last["time_s"] < 15.0 + 15.0
    texts = [e["text"] for e in log[ch.MISSION_EVENTS]]
    assert "aborted: SIGINT received" in texts
    assert texts.index("request hold") < texts.index("request land")


def test_stalled_control_stops_setpoints_and_the_vehicle_fails_safe(monkeypatch):
    runtime_cfg = load_mission("follow_ball").config
    expiry = runtime_cfg.runtime.setpoint_expiry_s
    loss = runtime_cfg.sim.flight_stack.commander.offboard_loss_timeout_s
    original_tick = ControlLoop.next_tick
    stalled: dict[str, float] = {}

    async def stalling_tick(self, period):
        clock = self.flight.clock
        if self.flight.cursor.step == "follow_ball" and clock.now() > 12.0:
            stalled.setdefault("at", clock.now())
            await asyncio.Event().wait()  # the control task hangs
        return await original_tick(self, period)

    monkeypatch.setattr(ControlLoop, "next_tick", stalling_tick)

    async def watch(runtime, probe, task):
        while True:
            await runtime.clock.sleep(0.02)
            s = runtime.flight.state
            if "at" in stalled and s.mode is FlightMode.HOLD and s.failsafe:
                probe.seen["hold_s"] = s.time_s - stalled["at"]
                probe.seen["last_send_s"] = runtime.setpoints.last_send_s - stalled["at"]
                task.cancel()  # end the run (the control task will never finish)
                return

    probe = _Probe(monkeypatch, watch)
    summary, _ = _fly([])
    assert summary["status"] == "aborted"
    # streaming stopped when the last setpoint expired, not later ...
    assert 0.0 < probe.seen["last_send_s"] <= expiry + 0.05
    # ... and the vehicle's own offboard-loss failsafe took over
    assert probe.seen["hold_s"] == pytest.approx(expiry + loss, abs=0.1)


def test_stale_telemetry_stops_setpoints_holds_and_lands(monkeypatch, tmp_path):
    """The vehicle keeps flying but its telemetry stops for good (a stalled telemetry link):
    the runtime must not fly on the old pose. Silent for ``telemetry_silence_s``, it stops the
    motion setpoints and commands HOLD; past ``telemetry_grace_s`` the step ends in the
    fallback, which lands."""
    runtime_cfg = load_mission("follow_ball").config.runtime
    limit, grace = runtime_cfg.telemetry_silence_s, runtime_cfg.telemetry_grace_s

    async def stop_telemetry(runtime, probe, _task):
        await runtime.clock.sleep_until(12.0)  # following by then
        probe.seen["step"] = runtime.flight.cursor.step
        # blind, the safe stop cannot see the landing end: it gives up after its timeout
        # (60 s); 15 s here is plenty for the 2 m down, and keeps the test short
        runtime.flight.executor.fallback = functools.partial(SafeStop, timeout_s=15.0)
        await runtime.vehicle.inject_failure("telemetry")
        probe.seen["stopped_s"] = runtime.clock.now()

    probe = _Probe(monkeypatch, stop_telemetry)
    summary, orphans = _fly([], tmp_path)
    assert probe.seen["step"] == "follow_ball"
    assert summary["status"] == "failed"
    assert "telemetry lost" in summary["reason"]
    assert orphans == []
    from autopilot.flightlog.log import read_log

    log = read_log(tmp_path / "flight.mcap")
    stopped = probe.seen["stopped_s"]
    events = [(e["time_s"], e["text"]) for e in log[ch.MISSION_EVENTS]]
    silent_at = next(t for t, text in events if text.startswith("telemetry silent"))
    lost_at = next(t for t, text in events if text.startswith("telemetry lost"))
    # noticed within the silence limit plus a control period, not later; the step waited
    # out the grace (counted from the last sample received) and no longer
    assert 0.0 < silent_at - stopped <= limit + 0.1
    assert grace - 0.1 <= lost_at - stopped <= grace + 0.1
    # no motion setpoint computed after the silence began ...
    assert all(sp["time_s"] <= silent_at for sp in log[ch.SETPOINTS])
    # ... HOLD, then the fallback's LAND; the vehicle (seen in the ground truth) came down
    texts = [text for t, text in events if t >= silent_at]
    assert texts.index("request hold") < texts.index("request land")
    assert not [text for text in texts if text.startswith("telemetry back")]
    truth = log[ch.GROUND_TRUTH][-1]
    assert truth["vehicle_position_ned_m"][2] > -0.2  # on the ground
