"""Seed 000's keys fly the AR.Drone: the console's socket against the simulated AR.Drone in
process (lockstep), through the AR.Drone driver and the drone's protocol —
Y hands it over, W/S/A/D move it, Q/E turn it, ] and [ climb and sink, key up hovers, L lands
(the motors stop on the ground), T takes off again to the drone's own hover height, R (confirmed)
cuts the motors through the emergency bit. It never climbs through its ceiling."""

from __future__ import annotations

import math

import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.mission import load_mission

from .test_console import (
    Socket,
    _fly_console,
    _forward,
    _hold_keys,
    _settled,
    emergency_stop,
)
from .test_goal_api import Client

pytestmark = pytest.mark.serial  # (as the console's own tests)


def _right(status, heading_rad: float) -> float:
    p = status["position_ned_m"]
    return -p[0] * math.sin(heading_rad) + p[1] * math.cos(heading_rad)


def _height(status) -> float:
    return -status["position_ned_m"][2]


def test_seed_000s_keys_fly_the_ardrone(tmp_path):
    plan = load_mission("standby", ["sim.firmware=ardrone", "steps.0.takeoff.altitude_m=1.5"])
    seen: dict = {}

    def script(c: Client, server):
        c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 90, "standby")
        sock = Socket(server.bound_port)
        assert sock.hello["keys"]["up"] == "]"
        sock.send({"type": "action", "action": "autopilot"})  # Y
        assert sock.next("answer")["ok"]
        status = c.wait(lambda s: s["control"] == "manual", 30, "manual")
        heading = math.radians(status["yaw_deg"])
        start = status
        # W: forward, then key up: it stops where it is
        moved = _hold_keys(sock, c, ["forward"],
                           lambda s: _forward(s, heading) - _forward(start, heading) > 1.0)
        seen["forward_m"] = _forward(moved, heading) - _forward(start, heading)
        sock.send({"type": "keys", "held": []})
        settled = _settled(c, "hover after W")
        seen["drift_after_w_m"] = abs(_forward(settled, heading) - _forward(moved, heading))
        # D: to the right
        before = settled
        moved = _hold_keys(sock, c, ["right"],
                           lambda s: _right(s, heading) - _right(before, heading) > 0.8)
        sock.send({"type": "keys", "held": []})
        settled = _settled(c, "hover after D")
        # E: the heading turns right (clockwise seen from above)
        before = settled
        turned = _hold_keys(sock, c, ["yaw_right"], lambda s: (
            (s["yaw_deg"] - before["yaw_deg"] + 180) % 360 - 180) > 30)
        sock.send({"type": "keys", "held": []})
        seen["turned_deg"] = (turned["yaw_deg"] - before["yaw_deg"] + 180) % 360 - 180
        # ]: climbs; [: sinks
        before = _settled(c, "hover after E")
        up = _hold_keys(sock, c, ["up"], lambda s: _height(s) - _height(before) > 0.4)
        sock.send({"type": "keys", "held": []})
        down = _hold_keys(sock, c, ["down"], lambda s: _height(up) - _height(s) > 0.4)
        sock.send({"type": "keys", "held": []})
        seen["heights_m"] = [_height(before), _height(up), _height(down)]
        # L: lands, the motors stop on the ground; T: takes off to the drone's own hover
        sock.send({"type": "action", "action": "land"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: not s["in_air"] and not s["armed"], 60, "landed, motors off")
        sock.send({"type": "action", "action": "takeoff"})
        assert sock.next("answer")["ok"]
        airborne = c.wait(lambda s: s["in_air"] and _height(s) > 0.7, 60, "airborne again")
        seen["takeoff_height_m"] = _height(_settled(c, "hover after T"))
        assert airborne["armed"]
        # R, confirmed: the emergency bit cuts the motors in the air
        return emergency_stop(sock)

    summary, events, _, _ = _fly_console(plan, tmp_path / "run", script)
    assert seen["forward_m"] > 1.0
    assert seen["drift_after_w_m"] < 1.5  # it brakes and hovers (the drone's own hover)
    assert seen["turned_deg"] > 30
    before, up, down = seen["heights_m"]
    assert up > before + 0.4
    assert down < up - 0.4
    assert 0.7 < seen["takeoff_height_m"] < 1.4  # the AR.Drone's takeoff: about a metre
    assert summary["status"] == "aborted"
    assert "emergency stop from the console" in summary["reason"]
    kill = next(e for e in events if e["hook"] == "before_cmd_disarm")
    assert kill["data"]["force"] is True  # in the air: the emergency bit
    log = read_log(tmp_path / "run" / "flight.mcap")
    assert log[ch.VEHICLE_STATE][-1]["armed"] is False  # the motors stopped
    heights = [-r["vehicle_position_ned_m"][2] for r in log[ch.GROUND_TRUTH]]
    assert heights[-1] < 0.3  # and it came down (the truth)
    assert max(heights) < 3.1  # never above its ceiling (control:altitude_max)
