"""``autopilot doctor`` against the simulator served as a MAVLink vehicle with its video, and
against nothing (real time, loopback, bounded by timeouts)."""

from __future__ import annotations

import asyncio
import json

import pytest

from autopilot.cli import main
from autopilot.config import load_config
from autopilot.doctor import run_doctor
from autopilot.mission import load_mission
from autopilot.sim_server import serve

pytestmark = pytest.mark.serial  # fixed video ports, rates on the wall clock

INSTANCE = 8
VIDEO = "udp://127.0.0.1:5608"
CONNECT = f"udpin://127.0.0.1:{14540 + INSTANCE}"


#: the camera at 15 fps: rendered, encoded and decoded in real time on a 2-core machine that is
#: busy with other tests (at its own 30 fps it may keep up only 20: a true WARN, of the machine)
CAMERA = ["vehicle.cameras.front.rate_hz=15"]


def test_doctor_passes_a_healthy_vehicle_and_camera():
    plan = load_mission("follow_ball", ["driver=pymavlink", *CAMERA])

    async def main_():
        stop = asyncio.Event()
        server = asyncio.ensure_future(serve(
            load_config(overrides=["vehicle.cameras.down.enabled=false", *CAMERA]), None,
            instance=INSTANCE, videos={"front": VIDEO}, log=lambda line: None, stop=stop))
        try:
            await asyncio.sleep(3.0)  # the simulator boots
            return await run_doctor(plan, connect=CONNECT, video=VIDEO, duration_s=3.0)
        finally:
            stop.set()
            await server

    checks = {c.item: c for c in asyncio.run(main_())}
    for item in ("link", "telemetry", "time sync", "vehicle", "signing", "capture times"):
        assert checks[item].status == "PASS", checks[item]
    # the stream decodes at its size; its rate is the machine's (a WARN under a CI run that
    # keeps both cores busy is the doctor telling the truth, not a fault of the stream)
    camera = checks["camera front"]
    assert camera.status in ("PASS", "WARN"), camera
    assert "640×480" in camera.detail, camera
    assert float(camera.detail.split(" fps")[0]) >= 5.0, camera
    assert "system 9" in checks["link"].detail  # PX4 SITL: instance 8 is system 9
    assert checks["link"].detail.startswith("PX4 vehicle")
    # the parameters a companion depends on, read from the vehicle (PX4's names)
    assert checks["param COM_OF_LOSS_T"].status == "PASS", checks["param COM_OF_LOSS_T"]
    assert checks["param COM_OF_LOSS_T"].detail.startswith("1: offboard setpoints lost")
    assert "data-link loss" in checks["param NAV_DLL_ACT"].detail
    assert "vehicle-clock" in checks["capture times"].detail
    assert checks["calibration front"].status == "WARN"  # no --calibration given
    assert "front=FILE" in checks["calibration front"].detail
    assert "FAIL" not in {c.status for c in checks.values()}


@pytest.mark.long  # (the doctor's test above checks one camera's stream in CI)
def test_each_camera_is_its_own_stream_the_down_camera_too():
    # follow_marker with its marker looked for by the down camera: the simulator streams both
    # cameras, each to its own port (vehicle.cameras.NAME.video), and the doctor checks the
    # camera the mission uses, on its own stream
    ports = {"front": "udp://127.0.0.1:5618", "down": "udp://127.0.0.1:5619"}
    plan = load_mission("follow_marker", ["driver=pymavlink", "perception.marker.camera=down",
                                          f"vehicle.cameras.down.video={ports['down']}"])

    async def main_():
        stop = asyncio.Event()
        server = asyncio.ensure_future(serve(
            load_config(), None, instance=INSTANCE, videos=ports, log=lambda line: None,
            stop=stop))
        try:
            await asyncio.sleep(3.0)
            return await run_doctor(plan, connect=CONNECT, duration_s=3.0)
        finally:
            stop.set()
            await server

    checks = {c.item: c for c in asyncio.run(main_())}
    assert checks["camera down"].status == "PASS", checks["camera down"]
    assert "camera front" not in checks  # not used by this mission
    assert "FAIL" not in {c.status for c in checks.values()}


def test_doctor_fails_clearly_without_a_vehicle(capsys):
    code = main(["doctor", "--connect", CONNECT, "--duration-s", "1", "--json",
                 "--set", "link.connect_timeout_s=1"])
    assert code == 1
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is False
    link = next(c for c in report["checks"] if c["item"] == "link")
    assert link["status"] == "FAIL"
    assert "no autopilot heartbeat" in link["detail"]


def _doctor_on_arducopter(plan, overrides, duration_s: float) -> dict:
    """``autopilot doctor`` for ``plan`` against the simulator served as ArduCopter SITL (its
    configuration with ``overrides``): the checks by item."""
    from drivers.mavlink.face_ardupilot import ArduPilotFace, serial0_port

    async def main_():
        stop = asyncio.Event()
        server = asyncio.ensure_future(serve(
            load_config(overrides=["sim.firmware=ardupilot", *overrides]), None,
            instance=INSTANCE, videos={}, log=lambda line: None, stop=stop,
            face_class=ArduPilotFace))
        try:
            await asyncio.sleep(3.0)
            return await run_doctor(plan, connect=f"tcpout://127.0.0.1:{serial0_port(INSTANCE)}",
                                    duration_s=duration_s)
        finally:
            stop.set()
            await server

    return {c.item: c for c in asyncio.run(main_())}


def test_doctor_recognises_an_arducopter_and_reads_what_a_companion_needs():
    plan = load_mission("follow_ball", ["driver=pymavlink"])
    checks = _doctor_on_arducopter(plan, [], duration_s=3.0)
    assert checks["link"].detail.startswith("ArduPilot vehicle"), checks["link"]
    for item in ("telemetry", "vehicle", "estimator", "param GUID_TIMEOUT",
                 "param SERIAL1_PROTOCOL", "param SERIAL2_PROTOCOL"):
        assert checks[item].status == "PASS", checks[item]
    assert "attitude, velocity and absolute position good" in checks["estimator"].detail
    # ArduCopter's default: no GCS failsafe — a lost companion leaves it in GUIDED
    assert checks["param FS_GCS_ENABLE"].status == "WARN"


@pytest.mark.parametrize(("driver", "plnd", "status"), [
    ("pymavlink", [], "FAIL"),
    ("mavsdk", ["sim.params.PLND_ENABLED=1", "sim.params.PLND_TYPE=1"], "PASS")])
def test_doctor_says_whether_an_arducopter_would_take_a_landing_handed_to_it(driver, plnd,
                                                                            status):
    """land_pad handed to the vehicle (method: vehicle_precland) lands on the pad on an
    ArduCopter only with PLND_ENABLED 1 and PLND_TYPE 1 (its PLND_ENABLED is 0 by default):
    FAIL naming the parameter, as ``autopilot run`` refuses the mission, or PASS — read
    through either driver (MAVSDK's param plugin, pymavlink's PARAM_REQUEST_READ)."""
    plan = load_mission("land_pad", [f"driver={driver}",
                                     "steps.1.land_pad.method=vehicle_precland"])
    checks = _doctor_on_arducopter(plan, plnd, duration_s=1.0)
    check = checks["precision_landing"]
    assert check.status == status, check
    assert "steps[1].land_pad" in check.detail
    if status == "FAIL":
        assert "PLND_ENABLED is 0" in check.detail
    assert checks["param GUID_TIMEOUT"].status == "PASS"  # (the driver reads parameters)
