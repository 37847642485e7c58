"""Fault injection in the simulator (drivers/sim/faults.py): each kind does what it says, in its
window only, on the scenario's clock (seconds after the first arming)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot.mission import load_mission
from drivers.sim.faults import FaultError, TimeWarp, fault_override, parse_fault
from drivers.sim.faults import RoverStop as RoverStopFault
from drivers.sim.simulator import Simulator

from ..conftest import sim_with


def flying(sim_config, faults, *, cameras=None, altitude_m=2.0, **changes) -> Simulator:
    """A simulator with ``faults``, armed and taking off (scenario time 0 at the arming)."""
    cfg = sim_with(sim_config, faults=faults, **changes)
    if cameras is not None:
        cfg = cfg.model_copy(update={"cameras": {k: v for k, v in cfg.cameras.items()
                                                 if k in cameras}})
    sim = Simulator(cfg)
    sim.advance_to(cfg.estimator.init_time_s + 0.1)
    for name in cfg.cameras:
        sim.set_camera_active(name, True)
    sim.command("arm")
    sim.command("takeoff", altitude_m)
    sim.advance_to(sim.time_s + sim.dt)  # the scenario's clock starts
    return sim


def collect(sim: Simulator, until_s: float, kinds=("telemetry", "frame")) -> list:
    """Outputs of ``kinds`` until ``until_s`` after the arming."""
    until_s += sim.scenario_start_s
    out = []
    while sim.time_s < until_s:
        out += [o for o in sim.advance_to(min(until_s, sim.time_s + 0.05)) if o.kind in kinds]
    return out


def since_arming(sim: Simulator, t: float) -> float:
    return t - sim.scenario_start_s


def test_parse_fault_and_override():
    assert parse_fault("camera_dropout:start_s=12,duration_s=3") == {
        "kind": "camera_dropout", "start_s": 12, "duration_s": 3}
    assert fault_override(["link_loss:fraction=0.3"]) == \
        'scenario.faults=[{"kind": "link_loss", "fraction": 0.3}]'
    for bad, said in (("nope", "unknown kind 'nope'"), ("link_loss:fraction=2", "fraction"),
                      ("ekf_glitch:magnitude", "expected KEY=VALUE"),
                      ("wind_step:speed=3", "no parameter 'speed' .did you mean 'speed_m_s'.")):
        with pytest.raises(FaultError, match=said):
            parse_fault(bad)


def test_the_command_line_refuses_a_fault_it_cannot_inject(capsys):
    from autopilot.cli import main

    # a vehicle flown over MAVLink is not ours to break: autopilot sim --fault is
    assert main(["run", "--mission", "follow_ball", "--driver", "pymavlink",
                 "--fault", "gps_loss"]) == 2
    assert "autopilot sim --fault" in capsys.readouterr().err
    assert main(["run", "--mission", "follow_ball", "--fault", "nope"]) == 2
    assert "unknown kind 'nope'" in capsys.readouterr().err


def test_mission_faults_are_validated_with_the_mission():
    plan = load_mission("follow_ball", [
        'scenario.faults=[{kind: camera_freeze, camera: front, start_s: 3}]'])
    assert plan.mission.scenario.faults[0].camera == "front"
    with pytest.raises(Exception, match="no camera 'rear'"):
        load_mission("follow_ball", ['scenario.faults=[{kind: camera_dropout, camera: rear}]'])
    with pytest.raises(Exception, match=r"--set: scenario.faults\[0\]: rover_stop: the scenario "
                       "has no rover"):
        load_mission("follow_ball", ['scenario.faults=[{kind: rover_stop}]'])
    with pytest.raises(Exception, match="start_s"):
        load_mission("follow_ball", ['scenario.faults=[{kind: gps_loss, start_s: -1}]'])
    with pytest.raises(Exception, match=r"scenario.faults.0.motor.*no motor 4: .* has 4"):
        load_mission("follow_ball", ['scenario.faults=[{kind: motor_failure, motor: 4}]'])
    load_mission("follow_ball", ['scenario.faults=[{kind: motor_failure, motor: 3}]'])


def test_time_warp_stops_and_reverses():
    stop = TimeWarp([RoverStopFault(kind="rover_stop", start_s=2.0, duration_s=3.0)])
    assert stop(1.0) == (1.0, 1.0)
    assert stop(4.0) == (2.0, 0.0)
    assert stop(6.0) == (3.0, 1.0)
    back = TimeWarp([RoverStopFault(kind="rover_stop", start_s=2.0, duration_s=3.0,
                                    mode="reverse")])
    assert back(3.0) == (1.0, -1.0)
    assert back(4.5) == (0.0, 0.0)  # back to where it started (2 s of path): it waits there
    assert back(5.5) == (0.5, 1.0)  # then on again
    late = TimeWarp([RoverStopFault(kind="rover_stop", start_s=10.0, duration_s=3.0,
                                    mode="reverse")])
    assert late(12.0) == (8.0, -1.0)
    assert late(14.0) == (8.0, 1.0)  # back 3 s, on 1 s
    # overlapping windows: the stop (2–5 s) acts, then what is left of the reverse (5–6 s)
    both = TimeWarp([RoverStopFault(kind="rover_stop", start_s=4.0, duration_s=2.0,
                                    mode="reverse"),
                     RoverStopFault(kind="rover_stop", start_s=2.0, duration_s=3.0)])
    assert both(4.5) == (2.0, 0.0)
    assert both(5.5) == (1.5, -1.0)
    assert both(8.0) == (3.0, 1.0)


def test_camera_dropout_freeze_and_corrupt(sim_config):
    faults = [{"kind": "camera_dropout", "camera": "front", "start_s": 1.0, "duration_s": 1.0},
              {"kind": "camera_freeze", "camera": "front", "start_s": 3.0, "duration_s": 1.0},
              {"kind": "camera_corrupt", "camera": "front", "mode": "black", "start_s": 5.0,
               "duration_s": 0.5}]
    sim = flying(sim_config, faults, cameras=("front",))
    frames = [o.payload for o in collect(sim, 7.0, ("frame",))]
    t = np.array([since_arming(sim, f.time_s) for f in frames])
    assert not np.any((t >= 1.0) & (t < 2.0))  # dropped
    assert np.any((t >= 0.5) & (t < 1.0))
    assert np.any((t >= 2.0) & (t < 2.5))
    frozen = [f for f, ti in zip(frames, t, strict=True) if 3.0 <= ti < 4.0]
    before = [f for f, ti in zip(frames, t, strict=True) if ti < 3.0][-1]
    assert len(frozen) > 5
    assert all(np.array_equal(f.image, before.image) for f in frozen)
    assert len({f.seq for f in frozen}) == len(frozen)  # new frames, old picture
    after = [f for f, ti in zip(frames, t, strict=True) if 4.0 <= ti < 5.0]
    assert not np.array_equal(after[-1].image, before.image)
    black = [f for f, ti in zip(frames, t, strict=True) if 5.0 <= ti < 5.5]
    assert black
    assert all(f.image.max() == 0 for f in black)
    assert all(f.image.max() > 0 for f, ti in zip(frames, t, strict=True) if ti >= 5.6)


def test_telemetry_dropout_delay_and_link_loss(sim_config):
    faults = [{"kind": "telemetry_dropout", "start_s": 1.0, "duration_s": 1.0},
              {"kind": "telemetry_delay", "delay_s": 0.4, "start_s": 3.0, "duration_s": 1.0},
              {"kind": "link_loss", "fraction": 0.3, "start_s": 5.0, "duration_s": 2.0}]
    sim = flying(sim_config, faults, cameras=())
    out = collect(sim, 8.0, ("telemetry",))
    t = np.array([since_arming(sim, o.payload.time_s) for o in out])
    latency = np.array([o.delivery_s - o.payload.time_s for o in out])
    assert not np.any((t >= 1.0) & (t < 2.0))
    normal = sim_config.telemetry.latency_s + sim_config.telemetry.latency_jitter_s
    assert np.all(latency[(t >= 3.0) & (t < 4.0)] >= 0.4)
    assert np.all(latency[(t >= 4.5) & (t < 5.0)] <= normal + 0.01)
    rate = sim_config.telemetry.rate_hz
    kept = np.count_nonzero((t >= 5.0) & (t < 7.0)) / (2.0 * rate)
    assert 0.55 < kept < 0.85  # 30 % lost
    assert np.count_nonzero((t >= 7.0) & (t < 8.0)) >= rate - 1


def test_ekf_glitch_gps_loss_and_rangefinder(sim_config):
    faults = [{"kind": "ekf_glitch", "magnitude_m": 3.0, "direction_deg": 90,
               "start_s": 6.0, "duration_s": 2.0},
              {"kind": "rangefinder_dropout", "start_s": 6.0, "duration_s": 1.0},
              {"kind": "gps_loss", "drift_m_s": 0.5, "invalid_after_s": 1.0,
               "start_s": 10.0, "duration_s": 3.0}]
    sim = flying(sim_config, faults, cameras=())
    out = collect(sim, 14.0, ("telemetry", "truth"))
    truth = {round(o.payload.time_s, 4): o.payload for o in out if o.kind == "truth"}
    offsets, ranges, lost = [], [], []
    for o in out:
        if o.kind != "telemetry":
            continue
        s = o.payload
        ts = since_arming(sim, s.time_s)
        gt = truth.get(round(s.time_s, 4))
        if gt is not None:
            offsets.append((ts, s.position_ned_m - gt.vehicle.position_ned_m))
        ranges.append((ts, s.distance_to_ground_m))
        lost.append((ts, s.health.local_position_ok))
    during = [d for ts, d in offsets if 6.2 <= ts < 8.0]
    outside = [d for ts, d in offsets if 4.0 <= ts < 6.0 or 8.5 <= ts < 10.0]
    assert during
    assert outside
    assert np.mean([d[1] for d in during]) == pytest.approx(3.0, abs=0.3)  # east
    assert max(abs(d[1]) for d in outside) < 0.5
    assert all(math.isnan(r) for ts, r in ranges if 6.0 <= ts < 7.0)
    assert all(not math.isnan(r) for ts, r in ranges if 7.2 <= ts < 10.0)
    assert all(ok for ts, ok in lost if 4.0 <= ts < 10.9)
    assert not any(ok for ts, ok in lost if 11.2 <= ts < 13.0)  # after invalid_after_s
    drift = [np.linalg.norm(d[:2]) for ts, d in offsets if 12.5 <= ts < 13.0]
    assert drift
    assert np.mean(drift) == pytest.approx(0.5 * 2.5, abs=0.4)


def test_motor_battery_and_wind(sim_config):
    faults = [{"kind": "motor_failure", "motor": 2, "efficiency": 0.7, "start_s": 6.0},
              {"kind": "battery_sag", "remaining_fraction": 0.1, "start_s": 6.0},
              {"kind": "wind_step", "speed_m_s": 6.0, "direction_deg": 90, "start_s": 6.0}]
    sim = flying(sim_config, faults, cameras=())
    out = collect(sim, 5.9, ("telemetry", "truth"))
    before = [o.payload for o in out if o.kind == "truth"][-1]
    assert np.linalg.norm(before.wind_ned_m_s[:2]) < 1.0
    battery_before = [o.payload for o in out if o.kind == "telemetry"][-1].battery
    assert battery_before.remaining_fraction > 0.5
    out = collect(sim, 12.0, ("telemetry", "truth"))
    truth = [o.payload for o in out if o.kind == "truth"]
    assert truth[-1].wind_ned_m_s[1] == pytest.approx(6.0, abs=0.6)
    # motor 2 gives 70 % of what its command asks: the others carry the rest, and the
    # vehicle (a quad with margin) still holds its height
    assert truth[-1].vehicle.position_ned_m[2] == pytest.approx(-2.1, abs=0.5)
    assert sim.fault_effects.motor_scale[2] == pytest.approx(0.7)
    tel = [o.payload for o in out if o.kind == "telemetry"]
    assert tel[-1].battery.remaining_fraction <= 0.1
    assert not tel[-1].health.battery_ok


def test_rover_stops_then_drives_on(app_config):
    from autopilot.scenario import build_world

    plan = load_mission("land_on_rover", [
        'scenario.faults=[{kind: rover_stop, start_s: 2, duration_s: 3}]'])
    cfg, objects = build_world(plan.mission.scenario, plan.config.sim, plan.config)
    cfg = cfg.model_copy(update={"cameras": {}})
    sim = Simulator(cfg, objects)
    sim.advance_to(cfg.estimator.init_time_s + 0.1)
    sim.command("arm")
    sim.command("takeoff", 2.0)
    sim.advance_to(sim.time_s + sim.dt)
    speeds = []
    for o in collect(sim, 8.0, ("truth",)):
        gt = o.payload
        speeds.append((since_arming(sim, gt.time_s),
                       float(np.linalg.norm(gt.bodies["rover"].velocity_ned_m_s[:2]))))
    assert max(v for t, v in speeds if 3.0 <= t < 5.0) < 0.1
    assert max(v for t, v in speeds if t >= 6.5) > 0.5
