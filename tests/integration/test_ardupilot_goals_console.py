"""The goal API and the console through each MAVLink driver against the ArduCopter face (real
time): standby over MAVLink, a goto goal flown in GUIDED and succeeded, Y hands the vehicle to
the keys, W moves it forward (GUIDED velocity targets), key up brakes, Y hands it back and a
land goal ends the run — ArduCopter's modes along the way."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from autopilot.mission import load_mission
from autopilot.run import fly
from drivers.mavlink.face_ardupilot import ArduPilotFace

from ..conftest import sim_with
from .mavtools import INSTANCE, served
from .test_console import Socket, _forward, _hold_keys, _settled
from .test_goal_api import Client

pytestmark = pytest.mark.serial  # real time, MAVLink ports

SERIAL0 = 5760 + 10 * INSTANCE
GUIDED, LAND = 4, 9


@pytest.mark.parametrize("driver", ["pymavlink", "mavsdk"])
def test_goals_and_keys_fly_an_arducopter_through_each_driver(sim_config, tmp_path, driver):
    copter = sim_with(sim_config, firmware="ardupilot")
    plan = load_mission("standby", [f"driver={driver}"])
    seen: dict = {}

    def script(c: Client, modes) -> None:
        c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 90, "standby")
        seen["standby_mode"] = modes()
        code, body = c.call("POST", "/api/goals", {"goto": {"position_m": [4.0, 2.0, 3.0]}})
        assert code == 202, body
        goal = body["goal_id"]
        c.wait(lambda s: c.call("GET", f"/api/goals/{goal}")[1]["state"] == "succeeded", 60,
               "the goto goal")
        seen["at_goal"] = c.call("GET", "/api/status")[1]
        seen["goal_mode"] = modes()
        sock = Socket(c.server.bound_port)
        sock.send({"type": "action", "action": "autopilot"})  # Y
        assert sock.next("answer")["ok"]
        status = c.wait(lambda s: s["control"] == "manual", 30, "manual")
        heading = math.radians(status["yaw_deg"])
        moved = _hold_keys(sock, c, ["forward"],
                           lambda s: _forward(s, heading) - _forward(status, heading) > 1.0)
        seen["forward_m"] = _forward(moved, heading) - _forward(status, heading)
        seen["manual_mode"] = modes()
        sock.send({"type": "keys", "held": []})
        settled = _settled(c, "hover after W")
        seen["drift_after_w_m"] = abs(_forward(settled, heading) - _forward(moved, heading))
        sock.send({"type": "action", "action": "autopilot"})  # Y: the autopilot again
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["control"] != "manual" and s["waiting_for_goals"], 30, "handed back")
        code, body = c.call("POST", "/api/goals", {"land": {}})
        assert code == 202, body

    async def main():
        async with served(copter, face_class=ArduPilotFace) as (vehicle, _):
            servers: list = []
            flight = asyncio.ensure_future(fly(
                plan, tmp_path, connect=f"tcpout://127.0.0.1:{SERIAL0}", api="127.0.0.1:0",
                console=True, on_api=servers.append))
            while not servers or not servers[0].started.is_set():
                if flight.done():
                    return flight.result(), None
                await asyncio.sleep(0.01)
            client = Client(servers[0].bound_port)
            client.server = servers[0]
            try:
                await asyncio.to_thread(script, client,
                                        lambda: vehicle.simulator.flight.custom_mode)
            except BaseException:
                await asyncio.to_thread(client.call, "POST", "/api/abort")
                await flight
                raise
            summary = await asyncio.wait_for(flight, 120)
            return summary, vehicle.simulator.flight.custom_mode

    summary, final_mode = asyncio.run(main())
    assert summary["status"] == "completed", summary["reason"]
    assert seen["standby_mode"] == GUIDED  # the hover is GUIDED's
    np.testing.assert_allclose(seen["at_goal"]["position_ned_m"], [4.0, 2.0, -3.0], atol=0.6)
    assert seen["goal_mode"] == GUIDED
    assert seen["manual_mode"] == GUIDED  # the keys: GUIDED velocity targets
    assert seen["forward_m"] > 1.0
    assert seen["drift_after_w_m"] < 1.5
    assert final_mode == LAND  # landed by LAND, disarmed there
