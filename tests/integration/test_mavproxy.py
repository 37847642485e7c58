"""MAVProxy as a ground station on the simulator's GCS link: load a QGC WPL 110 mission, fly
it, return home (real time, bounded by timeouts).

MAVProxy cannot switch a PX4 vehicle's mode by name (with pymavlink 2.4.x, ``mode auto`` is
"Unknown mode" and ``mode mission`` / ``mode rtl`` fail inside pymavlink, as they do against
PX4 SITL); the mode changes go as MAVProxy's ``long DO_SET_MODE`` commands, which is how
MAVProxy users fly PX4 missions.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import shutil
import sys

import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import FlightMode
from drivers.sim.flight.navigator import MissionState

from ..conftest import sim_with
from .mavtools import INSTANCE, LOSSY_LINK, served
from .sim_process import die_with_parent

pytestmark = pytest.mark.serial  # MAVProxy against the simulator in real time

MAVPROXY = shutil.which("mavproxy.py")
GCS_PORT = 14557 + INSTANCE  # where mavtools' face sends its ground-station link

#: home, a takeoff to 8 m, three waypoints at 10 m around a 20 m square, a camera trigger
#: distance on the way (QGC WPL 110: seq current frame command p1-p4 lat lon alt autocontinue)
MISSION = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.000000\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t8.000000\t1
2\t0\t3\t16\t0\t2\t0\t0\t47.397922\t8.545594\t10.000000\t1
3\t0\t3\t206\t5\t0\t1\t0\t0\t0\t0\t1
4\t0\t3\t16\t0\t2\t0\t0\t47.397922\t8.545860\t10.000000\t1
5\t0\t3\t16\t0\t2\t0\t0\t47.397742\t8.545860\t10.000000\t1
6\t0\t3\t206\t0\t0\t0\t0\t0\t0\t0\t1
"""

#: the short version: home, a takeoff to 3 m, one waypoint 8 m north at 3 m (no hold) with a
#: camera trigger distance on the way, and the trigger off
SHORT_MISSION = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.000000\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t3.000000\t1
2\t0\t3\t206\t5\t0\t1\t0\t0\t0\t0\t1
3\t0\t3\t16\t0\t0\t0\t0\t47.397814\t8.545594\t3.000000\t1
4\t0\t3\t206\t0\t0\t0\t0\t0\t0\t0\t1
"""


async def _wait(predicate, timeout_s: float, what: str) -> None:
    try:
        async with asyncio.timeout(timeout_s):
            while not predicate():  # noqa: ASYNC110 (polls another process's progress)
                await asyncio.sleep(0.1)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}") from None


@pytest.mark.skipif(MAVPROXY is None, reason="MAVProxy is not installed (pip install -e .[test])")
@pytest.mark.parametrize(("mission", "commands", "last", "altitude_m", "rtl_alt_m", "faults"), [
    pytest.param(SHORT_MISSION, [16, 22, 206, 16, 206], (47.397814, 8.545594), 3.0, 3.0, [],
                 id="one-waypoint"),
    pytest.param(MISSION, [16, 22, 16, 206, 16, 16, 206], (47.397742, 8.545860), 10.0, 15.0,
                 [], id="square", marks=pytest.mark.long),
    pytest.param(SHORT_MISSION, [16, 22, 206, 16, 206], (47.397814, 8.545594), 3.0, 3.0, LOSSY_LINK,
                 id="one-waypoint-lossy-link", marks=pytest.mark.long),
])
def test_mavproxy_loads_a_wpl_mission_flies_it_and_returns_home(
        sim_config, tmp_path, mission, commands, last, altitude_m, rtl_alt_m, faults):
    mission_file = tmp_path / "mission.waypoints"
    mission_file.write_text(mission)
    config = sim_with(sim_config, **{"params": {"RTL_RETURN_ALT": rtl_alt_m}, "faults": faults})

    async def main():
        async with served(config) as (vehicle, face):
            proc = await asyncio.create_subprocess_exec(
                sys.executable, MAVPROXY, f"--master=udpin:127.0.0.1:{GCS_PORT}",
                "--source-system=255", "--nowait", cwd=tmp_path, preexec_fn=die_with_parent,
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT)
            output: list[str] = []

            async def read() -> None:
                async for line in proc.stdout:
                    output.append(line.decode(errors="replace"))

            reader = asyncio.ensure_future(read())

            def command(text: str) -> None:
                proc.stdin.write(f"{text}\n".encode())

            try:
                await _wait(lambda: face.links["gcs"].heard_from is not None, 30.0,
                            "MAVProxy on the GCS link")
                await _wait(lambda: any("Received" in line and "parameters" in line
                                        for line in output), 30.0, "parameters fetched")
                command(f"wp load {mission_file}")
                await _wait(lambda: vehicle.mission_status.total == len(commands), 20.0,
                            "mission uploaded")
                await _wait(lambda: any("MISSION_ACK" in line and "ACCEPTED" in line
                                        for line in output), 10.0, "MISSION_ACK")
                assert [i.command for i in vehicle.mission_items()] == commands
                command("long DO_SET_MODE 1 4 4")  # AUTO.MISSION
                await wait_for_state(vehicle, lambda s: s.mode is FlightMode.MISSION, 10.0,
                                     "MISSION")
                command("arm throttle")
                await wait_for_state(vehicle, lambda s: s.in_air, 20.0, "taking off")
                await _wait(lambda: vehicle.mission_status.state is MissionState.COMPLETE,
                            120.0, "the mission flown")
                corner = vehicle.latest_state.position_ned_m
                origin = vehicle.global_origin
                end = origin.to_ned(*last, origin.alt_amsl_m)
                assert math.hypot(corner[0] - end[0], corner[1] - end[1]) < 2.5
                assert -corner[2] == pytest.approx(altitude_m, abs=1.0)
                for _ in range(5):  # (a lossy link may lose the command or its answer)
                    command("long DO_SET_MODE 1 4 5")  # AUTO.RTL
                    with contextlib.suppress(TimeoutError):
                        await wait_for_state(vehicle, lambda s: s.mode is FlightMode.RETURN,
                                             4.0, "RTL")
                        break
                assert vehicle.latest_state.mode in (FlightMode.RETURN, FlightMode.LAND)
                await wait_for_state(vehicle, lambda s: not s.armed, 90.0, "home and disarmed")
                home = vehicle.latest_state.position_ned_m
                assert math.hypot(home[0], home[1]) < 1.0
                await _wait(lambda: any("DISARMED" in line for line in output), 10.0,
                            "MAVProxy saw the disarm")
                text = "".join(output)
                assert "Mode MISSION" in text  # MAVProxy read the modes
                assert "Mode RTL" in text
                if not faults:  # (one STATUSTEXT, which a lossy link may lose)
                    assert "AP: RTL: land at destination" in text  # the vehicle's messages
            except AssertionError as exc:
                raise AssertionError(f"{exc}\nMAVProxy said:\n{''.join(output)[-4000:]}") from None
            finally:
                with contextlib.suppress(ProcessLookupError, BrokenPipeError, TimeoutError):
                    command("exit")
                    await asyncio.wait_for(proc.wait(), 5.0)
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
                reader.cancel()

    asyncio.run(main())
