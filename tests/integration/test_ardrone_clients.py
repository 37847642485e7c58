"""Independent AR.Drone 2.0 client libraries from PyPI, unmodified, against ``autopilot sim
--firmware ardrone`` (a process of its own, real time): pyardrone 0.6.1 and ardrone-sdk 0.4.4
each read navdata, take off, move, hover, take video frames and land, as their own examples
do. Each client runs in a process of its own and prints what it saw as JSON.

ardrone-sdk's own video decoder reads two PaVE fields at the wrong offsets (it takes the
header size for the payload's, and the codec for the header's), so it never decodes a frame
from any drone: the test asserts that, and then that the same library decodes our frames once
its script sets those two offsets right (module attributes, as its users would; the library's
files are untouched)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from drivers.ardrone.urls import ArdronePorts

from .sim_process import sim_process

pytestmark = pytest.mark.serial

INSTANCE = 30
PORTS = ArdronePorts().offset(10 * INSTANCE)
READY_LINE = "AR.Drone 2.0-compatible simulated drone on"


@pytest.fixture(scope="module")
def drone():
    """``autopilot sim --firmware ardrone`` on its own ports, until the module ends."""
    with sim_process(["--firmware", "ardrone", "--instance", str(INSTANCE)], READY_LINE) as proc:
        yield proc


# pyardrone's video thread is a daemon blocked in cv2.VideoCapture.read(), which close() does
# not stop. At interpreter exit CPython ends such a thread with pthread_exit, whose unwinding
# OpenCV's C++ swallows in a catch (...): glibc then aborts ("FATAL: exception not rethrown",
# SIGABRT) after the script has done and printed everything. A client script therefore leaves
# with os._exit once its output is flushed, as an application using pyardrone has to; any
# exception before that still ends it with a non-zero status.
EXIT_WITHOUT_FINALIZING = "\nimport os, sys\nsys.stdout.flush()\nos._exit(0)\n"


def assert_fresh_battery(percent: int) -> None:
    """A full pack, less what this module's earlier flights drew from it: the module shares
    one drone, and how long each flight lasts in real time depends on the machine's load."""
    assert 90 <= percent <= 100, percent


def _run(script: str, timeout_s: float = 150) -> dict:
    script = textwrap.dedent(script) + EXIT_WITHOUT_FINALIZING
    result = subprocess.run([sys.executable, "-c", script],
                            capture_output=True, text=True, timeout=timeout_s,
                            cwd=Path(__file__).parent)
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


PYARDRONE = f"""
import json, time
from pyardrone import ARDrone, at

def wait(cond, timeout_s, what):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.03)
    raise SystemExit(what + ": timed out")

seen = {{}}
drone = ARDrone(host="127.0.0.1", at_port={PORTS.at}, navdata_port={PORTS.navdata},
                video_port={PORTS.video})
try:
    assert drone.navdata_ready.wait(30), "no navdata"
    drone.send(at.CONFIG("general:navdata_demo", True))
    wait(lambda: hasattr(drone.navdata, "demo"), 30, "demo navdata")
    seen["battery_percent"] = drone.navdata.demo.vbat_flying_percentage
    seen["altitude_before_mm"] = drone.navdata.demo.altitude
    seen["fly_before"] = bool(drone.state.fly_mask)
    drone.takeoff()
    wait(lambda: drone.state.fly_mask, 30, "flying")
    wait(lambda: drone.navdata.demo.altitude > 700, 30, "climbing")
    seen["altitude_flying_mm"] = drone.navdata.demo.altitude
    vx = []
    for _ in range(60):
        drone.move(forward=0.5)
        vx.append(drone.navdata.demo.vx)
        time.sleep(0.03)
    seen["max_vx_mm_s"] = max(vx)
    drone.hover()
    assert drone.video_ready.wait(60), "no video"
    wait(lambda: drone.frame is not None, 60, "a decoded frame")
    seen["frame_shape"] = list(drone.frame.shape)
    drone.land()
    wait(lambda: not drone.state.fly_mask, 60, "landed")
    seen["altitude_landed_mm"] = drone.navdata.demo.altitude
finally:
    drone.close()
print(json.dumps(seen))
"""


def test_pyardrone_flies_it_unmodified(drone) -> None:
    seen = _run(PYARDRONE)
    assert_fresh_battery(seen["battery_percent"])
    assert not seen["fly_before"]
    assert seen["altitude_before_mm"] < 200
    assert 700 < seen["altitude_flying_mm"] < 1400
    assert seen["max_vx_mm_s"] > 300  # half the tilt, forward
    assert seen["frame_shape"][1:] == [640, 3]
    assert seen["frame_shape"][0] in (360, 368)  # (it shows the coded size: 368)
    assert seen["altitude_landed_mm"] < 200


PYARDRONE_FULL = f"""
import json, time
from pyardrone import ARDrone, at

seen = {{}}
drone = ARDrone(host="127.0.0.1", at_port={PORTS.at}, navdata_port={PORTS.navdata},
                video_port={PORTS.video})
try:
    assert drone.navdata_ready.wait(30), "no navdata"
    drone.send(at.CONFIG("general:navdata_options", (1 << 28) - 1))  # every option
    drone.send(at.CONFIG("general:navdata_demo", False))
    end = time.monotonic() + 30
    while not hasattr(drone.navdata, "altitude") and time.monotonic() < end:
        time.sleep(0.02)
    assert hasattr(drone.navdata, "altitude"), "no full navdata"
    first, t0 = drone.navdata.metadata.sequence_number, time.monotonic()
    time.sleep(2.0)
    last, t1 = drone.navdata.metadata.sequence_number, time.monotonic()
    seen["rate_hz"] = (last - first) / (t1 - t0)
    seen["options"] = sorted(k for k in vars(drone.navdata) if k not in ("checksum",))
    seen["demo_bit"] = bool(drone.state.navdata_demo_mask)
    drone.send(at.CONFIG("general:navdata_demo", True))  # back to demo for the next client
    time.sleep(0.5)
finally:
    drone.close()
print(json.dumps(seen))
"""


def test_pyardrone_reads_full_navdata_at_200_hz(drone) -> None:
    seen = _run(PYARDRONE_FULL)
    assert not seen["demo_bit"]
    # every option pyardrone knows, each at the size it checks
    for name in ("demo", "time", "raw_measures", "phys_measures", "altitude", "magneto",
                 "vision_detect", "wifi", "cks"):
        assert name in seen["options"]
    assert 120 < seen["rate_hz"] < 230  # 200 Hz, real time on a shared machine


ARDRONE_SDK = f"""
import json, sys, time
import ardrone
import ardrone.constant
ardrone.constant.NAVDATA_PORT = {PORTS.navdata}
ardrone.constant.VIDEO_PORT = {PORTS.video}
ardrone.constant.COMMAND_PORT = {PORTS.at}
import ardrone.video
FIX = sys.argv[1:] == ["fix"]
if FIX:  # its decoder's two PaVE offsets, set right from the script
    ardrone.video._F_HEADER_SIZE, ardrone.video._F_PAYLOAD_SIZE = 3, 4

def wait(cond, timeout_s, what):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.05)
    return False

seen = {{}}
drone = ardrone.ARDrone("127.0.0.1")
try:
    assert wait(lambda: "demo" in drone.navdata, 30, "demo"), "no demo navdata"
    seen["battery_percent"] = drone.navdata["demo"]["battery"]
    first = drone.image
    drone.takeoff()
    assert wait(lambda: drone.navdata["state"]["fly"], 30, "flying"), "not flying"
    assert wait(lambda: drone.navdata["demo"]["altitude"] > 700, 30, "up"), "not up"
    seen["altitude_flying_mm"] = drone.navdata["demo"]["altitude"]
    drone.move(0.0, -0.5, 0.0, 0.0)  # forward, held until the next command
    vx = []
    for _ in range(40):
        vx.append(drone.navdata["demo"]["vx"])
        time.sleep(0.05)
    seen["max_vx_mm_s"] = max(vx)
    drone.hover()
    seen["decoded"] = wait(lambda: drone.image is not first, 20 if FIX else 8, "a frame")
    seen["image_size"] = list(drone.image.size)
    drone.land()
    assert wait(lambda: not drone.navdata["state"]["fly"], 60, "landed"), "not landed"
    seen["altitude_landed_mm"] = drone.navdata["demo"]["altitude"]
finally:
    drone.halt()
print(json.dumps(seen))
"""


def test_ardrone_sdk_flies_it_unmodified(drone) -> None:
    seen = _run(ARDRONE_SDK)
    assert_fresh_battery(seen["battery_percent"])
    assert 700 < seen["altitude_flying_mm"] < 1400
    assert seen["max_vx_mm_s"] > 300
    assert seen["altitude_landed_mm"] < 200
    assert not seen["decoded"]  # its own decoder's bug (see the module's notes)


def test_ardrone_sdk_decodes_our_video_with_its_offsets_set_right(drone) -> None:
    script = ARDRONE_SDK.replace("FIX = sys.argv[1:] == [\"fix\"]", "FIX = True")
    seen = _run(script)
    assert seen["decoded"]
    assert seen["image_size"][0] == 640
