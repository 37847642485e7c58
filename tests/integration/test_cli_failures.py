"""What a new user meets when something is missing: one line saying what was tried and what to
do, a distinct exit code, never a traceback, and none of the libraries' own chatter."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest

from .sim_process import die_with_parent

pytestmark = pytest.mark.serial  # fixed MAVLink ports, a run's wall time

PORT = 14549  # clear of a running SITL and of the other tests' instances


def _autopilot(*args: str, env: dict | None = None, timeout_s: float = 120.0):
    return subprocess.run([sys.executable, "-m", "autopilot", *args], capture_output=True,
                          text=True, timeout=timeout_s, env={**os.environ, **(env or {})})


def _in_process(capsys, *args: str) -> subprocess.CompletedProcess:
    """The command line's ``main`` in this process (for refusals before anything starts: the
    tests that look at a whole process's output run it as one)."""
    from autopilot.cli import main

    code = main(list(args))
    return subprocess.CompletedProcess(list(args), code, "", capsys.readouterr().err)


def _one_error_line(result) -> str:
    assert "Traceback" not in result.stderr, result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.stderr
    return errors[0]


@pytest.mark.parametrize("driver", ["mavsdk", "pymavlink"])
def test_no_vehicle(driver, tmp_path):
    result = _autopilot("run", "--mission", "follow_ball", "--driver", driver,
                        "--connect", f"udpin://127.0.0.1:{PORT}", "--out", str(tmp_path),
                        "--set", "link.connect_timeout_s=2")
    assert result.returncode == 3
    line = _one_error_line(result)
    assert f"no autopilot heartbeat on udpin://127.0.0.1:{PORT} within 2 s" in line
    assert "serial:///dev/ttyAMA0" in line  # what to do
    # MAVSDK's own console lines went to the run's log, not the terminal
    assert "MAVSDK" not in result.stderr
    if driver == "mavsdk":
        assert "MAVSDK version" in (tmp_path / "autopilot.log").read_text()


@pytest.mark.parametrize(("option", "value", "expected"), [
    ("--connect", "bogus://x", "unsupported MAVLink connection 'bogus://x'"),
    ("--connect", "udpin://127.0.0.1", "unsupported MAVLink connection"),
    ("--connect", "serial://ttyUSB0", "serial:///dev/DEVICE[:BAUD]"),
    ("--connect", "serial:///dev/ttyUSB0:12345", "not a baud rate"),
    ("--video", "bogus://x", "expected udp://HOST:PORT"),
    ("--video", "udp://127.0.0.1", "RTP video needs a port"),
])
def test_malformed_urls_are_refused_before_anything_opens(option, value, expected, tmp_path,
                                                          capsys):
    result = _in_process(capsys, "run", "--mission", "follow_ball", "--driver", "pymavlink",
                         option, value, "--out", str(tmp_path))
    assert result.returncode == 2
    line = _one_error_line(result)
    assert "command line" in result.stderr
    assert expected in result.stderr, line
    assert not (tmp_path / "flight.mcap").exists()


def test_port_already_in_use(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", PORT))
        result = _autopilot("run", "--mission", "follow_ball", "--driver", "pymavlink",
                            "--connect", f"udpin://127.0.0.1:{PORT}", "--out", str(tmp_path))
    assert result.returncode == 4
    assert "address already in use" in _one_error_line(result)


def test_network_link_needs_a_key_or_insecure(tmp_path, capsys):
    result = _in_process(capsys, "run", "--mission", "follow_ball", "--driver", "pymavlink",
                         "--connect", "udpin://0.0.0.0:14549", "--out", str(tmp_path))
    assert result.returncode == 2
    assert "--signing-key" in _one_error_line(result) or "--signing-key" in result.stderr
    result = _in_process(capsys, "sim", "--bind", "0.0.0.0")
    assert result.returncode == 2
    assert "--insecure" in result.stderr


def test_signing_key_file_problems(tmp_path, capsys):
    empty = tmp_path / "empty.key"
    empty.write_text("")
    result = _in_process(capsys, "run", "--mission", "follow_ball", "--driver", "pymavlink",
                         "--signing-key", str(empty), "--out", str(tmp_path))
    assert result.returncode == 2
    assert "the signing key file is empty" in result.stderr
    result = _in_process(capsys, "sim", "--signing-key", str(tmp_path / "missing.key"))
    assert result.returncode == 2
    assert "cannot read the signing key" in result.stderr


def test_rendering_backend_that_cannot_load(tmp_path):
    result = _autopilot("run", "--mission", "follow_ball", "--out", str(tmp_path),
                        env={"MUJOCO_GL": "bogus"})
    assert result.returncode == 6
    line = _one_error_line(result)
    assert "MUJOCO_GL" in line
    assert "egl" in line


def test_a_camera_that_never_delivers_a_frame(no_camera_config, tmp_path):
    """A vehicle answers, but nothing streams to the video port: nothing takes off."""
    import asyncio
    import threading

    from tests.integration.mavtools import served

    ready, stop = threading.Event(), threading.Event()

    def vehicle():
        async def main():
            async with served(no_camera_config):
                ready.set()
                await asyncio.to_thread(stop.wait)

        asyncio.run(main())

    thread = threading.Thread(target=vehicle, daemon=True)
    thread.start()
    try:
        assert ready.wait(30.0)
        from tests.integration.mavtools import CLIENT_URL

        result = _autopilot("run", "--mission", "follow_ball", "--driver", "pymavlink",
                            "--connect", CLIENT_URL, "--video", "udp://127.0.0.1:5609",
                            "--out", str(tmp_path), "--set", "link.connect_timeout_s=3")
    finally:
        stop.set()
        thread.join(10.0)
    assert result.returncode == 5
    line = _one_error_line(result)
    assert "no video from the front camera on udp://127.0.0.1:5609 within 3 s" in line


def test_an_early_ctrl_c_flew_nothing_and_says_so(tmp_path):
    """Ctrl-C before anything took off: exit 130 (and only a signal gives 130), "nothing
    flown", no "forced exit" and no flight time."""
    import signal
    import time

    mission = tmp_path / "ground.yaml"
    mission.write_text("name: ground\nsteps:\n  - standby: {timeout_s: 3000}\n")
    proc = subprocess.Popen([sys.executable, "-m", "autopilot", "run", "--mission",
                             str(mission), "--out", str(tmp_path / "run")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=die_with_parent)
    try:
        for line in proc.stderr:  # the run has begun once its first step starts
            if "step standby started" in line:
                break
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err
    assert "forced exit" not in out + err
    assert "nothing flown" in out, out
    assert "flew for" not in out
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["signal"] == "SIGINT"
    assert summary["flown"] is False
