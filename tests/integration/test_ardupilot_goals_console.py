"""The goal API and the console through each MAVLink driver against ``autopilot sim
--firmware ardupilot`` (a process of its own with its video, real time): standby over MAVLink,
a goto goal flown in GUIDED and succeeded, Y hands the vehicle to the keys, W moves it forward
(GUIDED velocity targets), key up brakes, Y hands it back and a land goal lands it in LAND."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from autopilot.mission import load_mission
from autopilot.run import fly
from drivers.mavlink.face_ardupilot import serial0_port

from .sim_process import sim_process
from .test_console import Socket, _forward, _hold_keys, _settled
from .test_goal_api import Client

pytestmark = pytest.mark.serial  # real time, MAVLink ports

INSTANCE = 7
SERIAL0 = serial0_port(INSTANCE)


@pytest.fixture(scope="module")
def copter():
    """``autopilot sim --firmware ardupilot`` (standby's world, its cameras streaming)."""
    with sim_process(["--firmware", "ardupilot", "--instance", str(INSTANCE), "--mission",
                      "standby"], "Ctrl-C to stop") as proc:
        yield proc


# (pymavlink flies an ArduCopter in CI through test_ardupilot_face; here with --run-long)
@pytest.mark.parametrize("driver", [pytest.param("pymavlink", marks=pytest.mark.long), "mavsdk"])
def test_goals_and_keys_fly_an_arducopter_through_each_driver(copter, tmp_path, driver):
    plan = load_mission("standby", [f"driver={driver}"])
    seen: dict = {}

    def script(c: Client) -> None:
        seen["standby"] = c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"],
                                 90, "standby")
        code, body = c.call("POST", "/api/goals", {"goto": {"position_m": [4.0, 2.0, 3.0]}})
        assert code == 202, body
        goal = body["goal_id"]
        c.wait(lambda s: c.call("GET", f"/api/goals/{goal}")[1]["state"] == "succeeded", 60,
               "the goto goal")
        seen["at_goal"] = c.call("GET", "/api/status")[1]
        sock = Socket(c.server.bound_port)
        sock.send({"type": "action", "action": "autopilot"})  # Y
        assert sock.next("answer")["ok"]
        status = c.wait(lambda s: s["control"] == "manual", 30, "manual")
        heading = math.radians(status["yaw_deg"])
        moved = _hold_keys(sock, c, ["forward"],
                           lambda s: _forward(s, heading) - _forward(status, heading) > 1.0)
        seen["forward_m"] = _forward(moved, heading) - _forward(status, heading)
        seen["manual"] = moved
        sock.send({"type": "keys", "held": []})
        settled = _settled(c, "hover after W")
        seen["drift_after_w_m"] = abs(_forward(settled, heading) - _forward(moved, heading))
        sock.send({"type": "action", "action": "autopilot"})  # Y: the autopilot again
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["control"] != "manual" and s["waiting_for_goals"], 30, "handed back")
        code, body = c.call("POST", "/api/goals", {"land": {}})
        assert code == 202, body
        seen["landing"] = c.wait(lambda s: s["mode"] == "land", 30, "LAND")

    async def main():
        servers: list = []
        flight = asyncio.ensure_future(fly(
            plan, tmp_path, connect=f"tcpout://127.0.0.1:{SERIAL0}", api="127.0.0.1:0",
            console=True, on_api=servers.append))
        while not servers or not servers[0].started.is_set():
            if flight.done():
                return flight.result()
            await asyncio.sleep(0.01)
        client = Client(servers[0].bound_port)
        client.server = servers[0]
        try:
            await asyncio.to_thread(script, client)
        except BaseException:
            await asyncio.to_thread(client.call, "POST", "/api/abort")
            await flight
            raise
        return await asyncio.wait_for(flight, 120)

    summary = asyncio.run(main())
    assert summary["status"] == "completed", summary["reason"]
    # GUIDED reads as offboard (the firmware profile's mapping), LAND as land
    assert seen["standby"]["mode"] == "offboard"
    np.testing.assert_allclose(seen["at_goal"]["position_ned_m"], [4.0, 2.0, -3.0], atol=0.6)
    assert seen["at_goal"]["mode"] == "offboard"
    assert seen["manual"]["mode"] == "offboard"  # the keys: GUIDED velocity targets
    assert seen["forward_m"] > 1.0
    assert seen["drift_after_w_m"] < 1.5
    assert seen["landing"]["armed"]


@pytest.mark.parametrize("driver", ["pymavlink", "mavsdk"])
def test_a_landing_handed_to_plnd_off_is_refused_before_anything_flies(copter, tmp_path,
                                                                       driver):
    """ArduCopter SITL's PLND_ENABLED is 0, as the firmware's: land_pad handed to the vehicle
    would land wherever it is, so ``autopilot run`` refuses it once connected, naming the step
    and the parameter, read through either driver."""
    from autopilot.config import ConfigError

    plan = load_mission("land_pad", [f"driver={driver}",
                                     "steps.1.land_pad.method=vehicle_precland"])
    with pytest.raises(ConfigError) as caught:
        asyncio.run(fly(plan, tmp_path, connect=f"tcpout://127.0.0.1:{SERIAL0}"))
    text = str(caught.value)
    assert "steps[1].land_pad" in text
    assert "PLND_ENABLED is 0" in text
