"""MAVSDK 4's own examples (tests/integration/mavsdk_examples), each run unmodified in its own
process against the simulator's MAVLink face, as a user runs them against PX4 SITL.

Real time (a MAVSDK client cannot be put on a lockstep clock), bounded by timeouts: a slow
machine takes longer, it does not fail. Each example gets a fresh simulated vehicle; the test
checks the example's exit code and output, and where the vehicle actually went.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import FlightMode

from ..conftest import sim_with
from .mavtools import CLIENT_URL, LOSSY_LINK, served
from .sim_process import die_with_parent

pytestmark = pytest.mark.serial  # MAVSDK's examples against the simulator in real time

EXAMPLES = Path(__file__).parent / "mavsdk_examples"


async def _run_example(name: str, timeout_s: float, url: str = CLIENT_URL) -> tuple[int, str]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, str(EXAMPLES / name), url, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT, env={**os.environ, "PYTHONUNBUFFERED": "1"},
        preexec_fn=die_with_parent)
    out = bytearray()  # what it printed, kept as it comes (a killed example's output too)

    async def read() -> None:
        while chunk := await proc.stdout.read(4096):
            out.extend(chunk)

    reader = asyncio.ensure_future(read())
    try:
        await asyncio.wait_for(asyncio.shield(reader), timeout_s)
        await proc.wait()
    except TimeoutError:
        proc.kill()
        await proc.wait()
        await reader
        raise AssertionError(f"{name} did not finish within {timeout_s:g} s:\n"
                             f"{out.decode(errors='replace')[-3000:]}") from None
    return proc.returncode, out.decode(errors="replace")


class _Track:
    """The vehicle's telemetry while an example flies (for what the example does not print)."""

    def __init__(self, vehicle) -> None:
        self.states = []
        self._task = asyncio.ensure_future(self._collect(vehicle))

    async def _collect(self, vehicle) -> None:
        async with contextlib.aclosing(vehicle.telemetry(buffer=256)) as samples:
            async for state in samples:
                self.states.append(state)

    async def aclose(self) -> None:
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task

    @property
    def max_altitude_m(self) -> float:
        return max(s.altitude_m for s in self.states)

    def modes(self) -> list[FlightMode]:
        seen = []
        for s in self.states:
            if not seen or seen[-1] is not s.mode:
                seen.append(s.mode)
        return seen


def _check(code: int, out: str, *expected: str) -> None:
    assert code == 0, out[-3000:]
    for text in expected:
        assert text in out, f"{text!r} not in the example's output:\n{out[-3000:]}"


@pytest.mark.parametrize("faults", [
    # MAVSDK's own example as a user runs it (in CI: the short examples fly there)
    pytest.param([], id="clean"),
    # MAVSDK over a link that loses 10 % each way, duplicates, reorders and delays (the
    # simulator's link_loss fault on its face): its retransmissions carry the example through
    pytest.param(LOSSY_LINK, id="lossy-link", marks=pytest.mark.long)])
def test_takeoff_and_land(no_camera_config, faults):
    config = type(no_camera_config).model_validate(
        {**no_camera_config.model_dump(), "faults": faults})

    async def main():
        async with served(config) as (vehicle, face):
            track = _Track(vehicle)
            code, out = await _run_example("takeoff_and_land.py", 90.0)
            _check(code, out, "-- Global position estimate OK", "-- Home at 488.",
                   "-- Takeoff altitude: 2.5 m", "-- Return-to-launch altitude: 60.0 m",
                   "-- Landing")
            await wait_for_state(vehicle, lambda s: not s.armed, 30.0, "landed and disarmed")
            await track.aclose()
            assert track.max_altitude_m == pytest.approx(2.5, abs=0.3)  # MIS_TAKEOFF_ALT
            assert FlightMode.TAKEOFF in track.modes()
            assert FlightMode.LAND in track.modes()
            assert vehicle.latest_state.altitude_m < 0.3
            assert (face.stats.link_dropped > 0) == bool(faults)

    asyncio.run(main())


def test_telemetry(no_camera_config):
    async def main():
        async with served(no_camera_config) as (_vehicle, _face):
            code, out = await _run_example("telemetry.py", 60.0)
            _check(code, out, "Battery: 100", "fix_type=3", "In air: False",
                   "latitude_deg=47.39774", "longitude_deg=8.54559")

    asyncio.run(main())


@pytest.mark.long
def test_fly_mission_with_camera_pause_continue_and_rtl(sim_config):
    # the published waypoints are 40-60 m out at 10 m: a 20 m return altitude keeps the RTL
    # short (RTL_RETURN_ALT is the vehicle's parameter, not the example's business)
    config = sim_with(sim_config, **{"params": {"RTL_RETURN_ALT": 20.0}})

    async def main():
        async with served(config) as (vehicle, _face):
            photos = []

            async def collect_photos():
                async with contextlib.aclosing(vehicle.photos()) as stream:
                    async for photo in stream:
                        photos.append(photo)

            photo_task = asyncio.ensure_future(collect_photos())
            track = _Track(vehicle)
            code, out = await _run_example("fly_mission.py", 240.0)
            _check(code, out, "-- Mission uploaded", "-- Mission downloaded: 6 items",
                   "-- Pausing mission for 5 seconds", "-- Resuming mission",
                   "Mission status update: 6 / 6", "-- Mission finished", "-- Disarmed")
            await track.aclose()
            photo_task.cancel()
            modes = track.modes()
            # paused in HOLD and resumed, then RTL
            assert modes[modes.index(FlightMode.MISSION):][:4] == [
                FlightMode.MISSION, FlightMode.HOLD, FlightMode.MISSION, FlightMode.RETURN]
            assert track.max_altitude_m == pytest.approx(20.0, abs=1.0)  # the return altitude
            # every waypoint was visited, at 10 m above home
            origin = vehicle.global_origin
            flown = np.array([s.position_ned_m for s in track.states])
            for lat, lon in [(47.398170327054473, 8.5456490218639658),
                             (47.398058617228855, 8.5454618036746979),
                             (47.398001890458097, 8.5455576181411743)]:
                n, e, _ = origin.to_ned(lat, lon, origin.alt_amsl_m)
                closest = np.min(np.hypot(flown[:, 0] - n, flown[:, 1] - e))
                assert closest < 1.5, f"waypoint {lat}, {lon} missed by {closest:.1f} m"
            # landed at home, and the camera took the mission's photos with the down camera
            final = vehicle.latest_state.position_ned_m
            assert math.hypot(final[0], final[1]) < 1.0
            assert len(photos) >= 3  # one TAKE_PHOTO, then an interval of 1 s over a leg
            assert all(p.frame is not None and p.frame.camera.name == "down" for p in photos)
            assert all(p.height_above_home_m == pytest.approx(10.0, abs=1.0) for p in photos)

    asyncio.run(main())


@pytest.mark.long  # (offboard through MAVSDK in CI: test_offboard_position_ned)
def test_offboard_velocity_ned(no_camera_config):
    async def main():
        async with served(no_camera_config) as (vehicle, _face):
            track = _Track(vehicle)
            code, out = await _run_example("offboard_velocity_ned.py", 90.0)
            _check(code, out, "-- Starting offboard", "-- Go up 2 m/s", "-- Stopping offboard")
            # the example exits as soon as its stop is acknowledged; the telemetry saying HOLD
            # may come a moment later (well within COM_OF_LOSS_T: not the offboard-loss
            # failsafe's HOLD, which would take a second)
            await wait_for_state(vehicle, lambda s: s.mode is FlightMode.HOLD, 0.5,
                                 "HOLD after the example's stop")
            await track.aclose()
            assert "failed" not in out
            assert track.modes()[-2:] == [FlightMode.OFFBOARD, FlightMode.HOLD]
            # up at 2 m/s, later down at 1 m/s, each for 4 s of the example's sleeps: wall
            # seconds, which a simulator slowed by a busy machine flies fewer of (and unevenly),
            # so the vertical speeds it flew are judged, and the heights only loosely
            offboard = [s for s in track.states if s.mode is FlightMode.OFFBOARD]
            climb_m_s = max(-float(s.velocity_ned_m_s[2]) for s in offboard)
            sink_m_s = max(float(s.velocity_ned_m_s[2]) for s in offboard)
            assert 1.7 < climb_m_s < 2.3, climb_m_s
            assert 0.8 < sink_m_s < 1.2, sink_m_s
            assert 1.5 < track.max_altitude_m < 8.5  # at most 4 s at 2 m/s
            down = track.max_altitude_m - vehicle.latest_state.altitude_m
            assert 0.5 < down < 4.0 + 1.0
            if track.max_altitude_m > 5.0:  # more than the descent can take: still flying
                assert vehicle.latest_state.in_air  # the example leaves it hovering in HOLD
            if vehicle.latest_state.armed:
                await vehicle.land()
            await wait_for_state(vehicle, lambda s: not s.armed, 30.0, "landed")

    asyncio.run(main())


def test_offboard_position_ned(no_camera_config):
    async def main():
        async with served(no_camera_config) as (vehicle, _face):
            track = _Track(vehicle)
            code, out = await _run_example("offboard_position_ned.py", 120.0)
            _check(code, out, "-- Starting offboard", "-- Stopping offboard")
            await track.aclose()
            assert "failed" not in out
            flown = np.array([s.position_ned_m for s in track.states])
            corner = np.min(np.linalg.norm(flown - np.array([5.0, 10.0, -5.0]), axis=1))
            assert corner < 0.3
            final = vehicle.latest_state
            assert final.position_ned_m[:2] == pytest.approx([0.0, 10.0], abs=0.3)
            assert final.altitude_m < 0.3  # the last setpoint is on the ground: it lands

    asyncio.run(main())


# --- MAVSDK's examples against the simulator as ArduCopter SITL (autopilot sim --firmware
# ardupilot), on the UDP port a ground station finds it on (sim_vehicle.py's MAVProxy output,
# every stream at 4 Hz). What MAVSDK supports on ArduPilot, and where it stops: docs/ardupilot.md

def _arducopter(config):
    return sim_with(config, firmware="ardupilot")


async def _run_on(face, name: str, timeout_s: float) -> tuple[int, str]:
    port = face.ports["udp"][1][1]
    return await _run_example(name, timeout_s, url=f"udpin://0.0.0.0:{port}")


@pytest.mark.long
def test_takeoff_and_land_as_published_waits_for_a_home_arducopter_never_streams(
        no_camera_config):
    from drivers.mavlink.face_ardupilot import ArduPilotFace

    async def main():
        async with served(_arducopter(no_camera_config), face_class=ArduPilotFace) as (
                vehicle, face):
            with pytest.raises(AssertionError, match="did not finish") as stopped:
                await _run_on(face, "takeoff_and_land.py", 25.0)
            text = str(stopped.value)
            assert "-- Global position estimate OK" in text
            assert text.rstrip().endswith("Fetching amsl altitude at home location....")
            assert not vehicle.latest_state.armed

    asyncio.run(main())


def test_takeoff_and_land_on_arducopter_with_home_asked_for(no_camera_config):
    from drivers.mavlink.face_ardupilot import ArduPilotFace

    async def main():
        async with served(_arducopter(no_camera_config), face_class=ArduPilotFace) as (
                vehicle, face):
            track = _Track(vehicle)
            code, out = await _run_on(face, "takeoff_and_land_ardupilot.py", 90.0)
            _check(code, out, "-- Global position estimate OK", "-- Home at 488.",
                   "-- Return-to-launch altitude: 15.0 m",  # RTL_ALT 1500 cm
                   "Status: 1: Arming motors", "-- Landing")
            await wait_for_state(vehicle, lambda s: not s.armed, 30.0, "landed and disarmed")
            await track.aclose()
            # MAVSDK's own takeoff altitude on ArduPilot (2 m, NAV_TAKEOFF in GUIDED), LAND
            assert track.max_altitude_m == pytest.approx(2.0, abs=0.3)
            assert FlightMode.OFFBOARD in track.modes()  # GUIDED
            assert FlightMode.LAND in track.modes()
            assert vehicle.latest_state.altitude_m < 0.3

    asyncio.run(main())


def test_mission_example_on_arducopter_stops_where_mavsdk_s_mission_plugin_does(
        no_camera_config):
    """MAVSDK's Mission plugin is PX4's: on ArduPilot its upload is taken, its first waypoint
    landing in seq 0 (ArduPilot's home, not flown), and the download it does next comes back
    with home at seq 0 in a frame the plugin cannot express: UNSUPPORTED (MissionRaw is
    MAVSDK's way to ArduPilot missions)."""
    from drivers.mavlink.face_ardupilot import ArduPilotFace

    async def main():
        async with served(_arducopter(no_camera_config), face_class=ArduPilotFace) as (
                vehicle, face):
            code, out = await _run_on(face, "fly_mission.py", 60.0)
            assert code != 0
            assert "-- Mission uploaded" in out
            assert "UNSUPPORTED; origin: download_mission()" in out
            flown = vehicle.mission_items()  # what the vehicle holds beyond home
            assert len(flown) == 16  # the plugin's 17 items, the first taken for home
            assert not vehicle.latest_state.armed

    asyncio.run(main())
