"""``autopilot bench load``: does the autopilot keep flying when its CPU is busy?

For each load N, one real-time follow_ball (shortened: ``--follow-s``) with everything a
companion computer runs, each in a process of its own:

* the vehicle, ``autopilot sim`` (H.264 video out), pinned to a core of its own (the first core
  this process may use): it stands in for the flight controller and camera, which never share
  the companion computer's CPU;
* on the other core, pinned together: the autopilot (``autopilot run --driver mavsdk`` or
  pymavlink, H.264 video in, ``--console``), a console viewer pulling the front camera's MJPEG
  (as a browser on the operator's machine would), and N busy processes (pure-Python spin loops).

Per N: completed or not (and the run's reason), the control tick's interval p50/p99 over the
follow step (from the run's ``/control/target`` records: one per tick), glass-to-setpoint latency
p50/p95 (the run's summary), frames shed by perception (frames the camera delivered during the
follow step that detection never saw: gaps in the processed frames' sequence numbers), frames
shed by the console (frames the viewer should have had at its rate, from the frames the camera
delivered while it watched, that never came), the range RMS (``autopilot score`` against the
simulator's truth) and the vehicle's own real-time factor (simulated over wall time between
the simulator's first and last event lines, else its truth log's last time over the wall time
since it came up: a vehicle that falls behind the wall clock makes its telemetry look old,
which is not the autopilot's load).

Every process the bench starts is in a session of its own, is stopped when the bench ends
(normally, on an error, on Ctrl-C or SIGTERM) and, through ``PR_SET_PDEATHSIG``, is killed by the
kernel if the bench itself is killed; the busy processes also stop when their parent is gone.
Only 127.0.0.1 ports are bound: a free ``autopilot sim --instance`` (its MAVLink ports), a free
video port pair (RTP, RTCP), a free console port.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from autopilot.bench.load_figures import (
    conclusions,
    row_from,
)
from autopilot.config import InputError

DEFAULT_HOGS = (0, 2, 4, 6)
DEFAULT_FOLLOW_S = 20.0
VIEWER_FPS = 15.0
_LAUNCHER = """\
import ctypes, os, signal, sys
core, parent, nice = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
os.sched_setaffinity(0, {core})
try:
    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
except (OSError, AttributeError):
    pass
if os.getppid() != parent:  # the bench died before the line above
    sys.exit(1)
if nice:
    try:
        os.nice(nice)
    except OSError:
        pass
os.execv(sys.argv[4], sys.argv[4:])
"""

# A busy process: pure Python, spinning; it also stops when its parent is gone.
_HOG = """\
import os
parent = os.getppid()
while os.getppid() == parent:
    for _ in range(200000):
        pass
"""


class LoadBenchError(InputError):
    pass


# ----------------------------------------------------------------------------------------------
# cores and processes
# ----------------------------------------------------------------------------------------------

def pick_cores(allowed: Iterable[int] | None = None) -> tuple[int, int]:
    """(the vehicle's core, the autopilot's core): the first two this process may use."""
    cores = sorted(os.sched_getaffinity(0) if allowed is None else allowed)
    if len(cores) < 2:
        raise LoadBenchError(
            f"autopilot bench load needs two cores (the vehicle on one of its own, the "
            f"autopilot and the load on the other); this process may use {len(cores)} "
            f"({', '.join(map(str, cores)) or 'none'}): run it on a machine with two cores or "
            "more, or widen its CPU affinity (taskset)")
    return cores[0], cores[1]


def pinned(argv: Sequence[str], core: int, nice: int = 0) -> list[str]:
    """``argv`` run through the launcher: pinned to ``core``, killed when this process dies."""
    return [sys.executable, "-c", _LAUNCHER, str(core), str(os.getpid()), str(nice), *argv]


def hog_argv() -> list[str]:
    return [sys.executable, "-c", _HOG]


class Processes:
    """The bench's children: each in a session of its own, all stopped by :meth:`close`
    (a context manager: on any exit)."""

    def __init__(self) -> None:
        self.procs: dict[str, subprocess.Popen] = {}
        self._files: list = []

    def __enter__(self) -> Processes:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self, name: str, argv: Sequence[str], core: int, *, nice: int = 0,
              output: Path | None = None) -> subprocess.Popen:
        if name in self.procs:
            raise ValueError(f"{name}: already started")
        out = subprocess.DEVNULL
        if output is not None:
            out = open(output, "wb")  # noqa: SIM115 (closed in close())
            self._files.append(out)
        proc = subprocess.Popen(pinned(argv, core, nice), stdin=subprocess.DEVNULL, stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True)
        self.procs[name] = proc
        return proc

    def start_hogs(self, count: int, core: int) -> list[subprocess.Popen]:
        return [self.start(f"hog{i}", hog_argv(), core) for i in range(count)]

    def stop(self, name: str, first: int = signal.SIGINT, grace_s: float = 10.0) -> int | None:
        """Ask ``name`` to end with ``first`` (its session's whole group), then SIGTERM, then
        SIGKILL; its exit code."""
        proc = self.procs.get(name)
        if proc is None:
            return None
        for sig, wait_s in ((first, grace_s), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
            if proc.poll() is not None:
                break
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, sig)  # (its own session: the group is its pid)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(wait_s)
        return proc.poll()

    def close(self) -> None:
        """Every child still running: SIGTERM, then SIGKILL; files closed."""
        alive = [p for p in self.procs.values() if p.poll() is None]
        for proc in alive:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        for proc in alive:
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(max(0.1, deadline - time.monotonic()))
        for proc in alive:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        for f in self._files:
            f.close()
        self._files.clear()


# ----------------------------------------------------------------------------------------------
# ports
# ----------------------------------------------------------------------------------------------

def _udp_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_instance(rng: random.Random) -> int:
    """An ``autopilot sim --instance`` whose MAVLink ports (14580+N, 18570+N, and 14540+N the
    autopilot listens on) are free on 127.0.0.1 (away from 0, which other tools use)."""
    for k in rng.sample(range(20, 200), 180):
        if all(_udp_free(p) for p in (14580 + k, 18570 + k, 14540 + k)):
            return k
    raise LoadBenchError("no free autopilot sim instance (ports 14600-14780) on 127.0.0.1")


def free_video_port(rng: random.Random) -> int:
    """An even UDP port with the next one (RTCP) free too."""
    for port in rng.sample(range(25000, 32000, 2), 500):
        if _udp_free(port) and _udp_free(port + 1):
            return port
    raise LoadBenchError("no free UDP port pair for the video on 127.0.0.1")


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ----------------------------------------------------------------------------------------------
# the console viewer (a process of its own)
# ----------------------------------------------------------------------------------------------

def viewer_main(base: str, out: str, fps: float, wait_s: float) -> None:
    """Pull ``base``'s front-camera MJPEG at ``fps`` until the stream ends; write what arrived
    (counts, sequence numbers, arrival times) to ``out`` every second and at the end."""
    import urllib.error
    import urllib.request

    deadline = time.monotonic() + wait_s
    result = {"frames": 0, "first_seq": None, "last_seq": None, "first_arrival_s": None,
              "last_arrival_s": None, "error": None}

    def save() -> None:
        tmp = out + ".tmp"
        with open(tmp, "w") as f:
            json.dump(result, f)
        os.replace(tmp, out)

    save()
    while True:  # the console comes up once the autopilot has its vehicle
        try:
            with urllib.request.urlopen(base + "/api/status", timeout=2):
                break
        except (OSError, urllib.error.URLError):
            if time.monotonic() > deadline:
                result["error"] = "the console never answered"
                save()
                return
            time.sleep(0.5)
    saved = time.monotonic()
    try:
        with urllib.request.urlopen(f"{base}/video/front.mjpg?fps={fps:g}", timeout=30) as resp:
            while True:
                line = resp.readline()
                if not line:
                    break  # the run ended
                if not line.startswith(b"--"):
                    continue
                fields = {}
                while (line := resp.readline()) not in (b"\r\n", b""):
                    key, _, value = line.decode("latin-1").partition(":")
                    fields[key.strip().lower()] = value.strip()
                resp.read(int(fields.get("content-length", 0)))
                now = time.monotonic()
                seq = int(fields.get("x-frame-seq", -1))
                result["frames"] += 1
                if result["first_seq"] is None:
                    result["first_seq"], result["first_arrival_s"] = seq, now
                result["last_seq"], result["last_arrival_s"] = seq, now
                if now - saved > 1.0:
                    save()
                    saved = now
    except (OSError, ValueError) as exc:  # (the run ending mid-frame, too)
        result["error"] = f"{type(exc).__name__}: {exc}"
    save()


def _viewer_argv(base: str, out: Path, fps: float, wait_s: float) -> list[str]:
    code = ("import sys; from autopilot.bench.load import viewer_main; "
            "viewer_main(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]))")
    return [sys.executable, "-c", code, base, str(out), f"{fps:g}", f"{wait_s:g}"]


# ----------------------------------------------------------------------------------------------
# figures from what the processes left
# ----------------------------------------------------------------------------------------------

def short_mission(follow_s: float) -> str:
    """follow_ball's mission file text with its follow step shortened to ``follow_s``."""
    from autopilot import resources

    text = (resources.missions_dir() / "follow_ball.yaml").read_text()
    original = "follow_ball: {duration_s: 60}"
    if original not in text:
        raise LoadBenchError("the shipped follow_ball mission no longer has "
                             f"'{original}': update autopilot/bench/load.py")
    return text.replace(original, f"follow_ball: {{duration_s: {follow_s:g}}}")


def camera_rate_hz(mission: Path, overrides: Sequence[str]) -> float | None:
    """The frame rate of the camera the ball is followed with, as the flown mission
    configures it."""
    from autopilot.mission import load_mission

    with contextlib.suppress(Exception):  # (no figure rather than no row)
        cfg = load_mission(mission, list(overrides)).config
        return float(cfg.vehicle.cameras[cfg.perception.ball.camera].rate_hz)
    return None


def _wait_for_line(path: Path, text: str, proc: subprocess.Popen, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            if text in path.read_text(errors="replace"):
                return True
        if proc.poll() is not None:
            return False
        time.sleep(0.2)
    return False


def _last_line(path: Path) -> str:
    with contextlib.suppress(OSError):
        lines = [x for x in path.read_text(errors="replace").splitlines() if x.strip()]
        if lines:
            return lines[-1].strip()[:200]
    return ""


def fly_one(hogs: int, folder: Path, mission: Path, driver: str, overrides: Sequence[str],
            cores: tuple[int, int], follow_s: float, fps: float,
            log: Callable[[str], None]) -> dict:
    """One load: the processes started, the flight flown, everything stopped; its row."""
    from autopilot.flightlog import records as ch
    from autopilot.flightlog.log import read_log
    from autopilot.score import score

    rng = random.Random()
    vehicle_core, autopilot_core = cores
    sim_dir, run_dir = folder / "sim", folder / "run"
    sim_out, run_out = folder / "sim.log", folder / "run.log"
    viewer_out = folder / "viewer.json"
    sets = [a for o in overrides for a in ("--set", o)]
    run_limit_s = 240.0 + 3.0 * follow_s
    failure = None
    folder.mkdir(parents=True, exist_ok=True)
    with Processes() as procs:
        procs.start_hogs(hogs, autopilot_core)
        instance, video = free_instance(rng), free_video_port(rng)
        # The vehicle has a core of its own, and a higher priority where this user may, so
        # that whatever else runs on the machine does not slow it.
        sim = procs.start("sim", [sys.executable, "-m", "autopilot", "sim", "--mission",
                                  str(mission), "--instance", str(instance), "--video",
                                  f"front=udp://127.0.0.1:{video}", "--out", str(sim_dir),
                                  *sets], vehicle_core, nice=-10, output=sim_out)
        ready = _wait_for_line(sim_out, "PX4-compatible simulated vehicle", sim, 180.0)
        ready_s = stop_s = time.monotonic()  # (its clock starts just before it says so)
        if not ready:
            failure = "the vehicle did not start: " + (_last_line(sim_out) or "no output")
        else:
            console = free_tcp_port()
            log(f"{hogs} busy: vehicle up (instance {instance}); flying")
            run = procs.start("run", [
                sys.executable, "-m", "autopilot", "run", "--mission", str(mission),
                "--driver", driver, "--connect", f"udpin://127.0.0.1:{14540 + instance}",
                "--video", f"front=udp://127.0.0.1:{video}",
                "--calibration", f"front={sim_dir / 'front_calibration.yaml'}",
                "--console", f"127.0.0.1:{console}", "--out", str(run_dir), *sets],
                autopilot_core, output=run_out)
            procs.start("viewer", _viewer_argv(f"http://127.0.0.1:{console}", viewer_out, fps,
                                               run_limit_s), autopilot_core)
            try:
                code = run.wait(run_limit_s)
            except subprocess.TimeoutExpired:
                code = procs.stop("run", signal.SIGINT, 60.0)
                failure = f"did not end within {run_limit_s:.0f} s (stopped)"
            if failure is None and not (run_dir / "summary.json").is_file():
                failure = f"the autopilot exited with code {code}: " + \
                    (_last_line(run_out) or "no output")
            procs.stop("viewer", signal.SIGTERM, 10.0)
        stop_s = time.monotonic()
        procs.stop("sim", signal.SIGINT, 30.0)  # (it lands a vehicle still armed, then exits)
        for i in range(hogs):
            procs.stop(f"hog{i}", signal.SIGTERM, 2.0)
    summary = records = truth_rtf = None
    if ready and (sim_dir / "truth.mcap").is_file() and stop_s - ready_s > 5.0:
        with contextlib.suppress(Exception):  # (a damaged log: no figure, not a crash)
            truth = read_log(sim_dir / "truth.mcap").get(ch.GROUND_TRUTH, [])
            truth_rtf = truth[-1]["time_s"] / (stop_s - ready_s) if truth else None
    if (run_dir / "summary.json").is_file():
        if (sim_dir / "truth.mcap").is_file():
            try:
                score(run_dir, sim_dir / "truth.mcap")
            except Exception as exc:  # a run too short to score still has its other figures
                log(f"{hogs} busy: not scored ({type(exc).__name__}: {exc})")
        summary = json.loads((run_dir / "summary.json").read_text())
        if (run_dir / "flight.mcap").is_file():
            records = read_log(run_dir / "flight.mcap")
    viewer = None
    with contextlib.suppress(OSError, ValueError):
        viewer = json.loads(viewer_out.read_text())
    sim_lines = sim_out.read_text(errors="replace").splitlines() if sim_out.is_file() else []
    row = row_from(hogs, summary, records, viewer, sim_lines, fps, failure, truth_rtf,
                   camera_rate_hz(mission, overrides))
    log(f"{hogs} busy: {'completed' if row['completed'] else 'NOT completed: ' + row['why']}")
    return row


def run_bench(hogs: Sequence[int], follow_s: float = DEFAULT_FOLLOW_S, driver: str = "mavsdk",
              overrides: Sequence[str] = (), log: Callable[[str], None] = lambda m: None,
              out: Path | None = None, fps: float = VIEWER_FPS,
              cores: tuple[int, int] | None = None, repeat: int = 1) -> dict:
    """Fly follow_ball at each load of ``hogs``, ``repeat`` times each (a row per flight)."""
    from autopilot.mission import load_mission

    cores = cores or pick_cores()
    folder = Path(tempfile.mkdtemp(prefix="bench-load-")) if out is None else out
    folder.mkdir(parents=True, exist_ok=True)
    mission = folder / "follow_ball.yaml"
    mission.write_text(short_mission(follow_s))
    plan = load_mission(str(mission), overrides)  # nothing flies on an invalid mission
    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGTERM) if main else None

    def terminated(signum, frame):  # SIGTERM: as Ctrl-C, so that every child is stopped
        raise KeyboardInterrupt

    if main:  # (signal handlers are the main thread's; elsewhere the caller's own apply)
        signal.signal(signal.SIGTERM, terminated)
    rows = []
    try:
        for n in hogs:
            for k in range(1, repeat + 1):
                where = folder / (f"hogs{n}" if repeat == 1 else f"hogs{n}-{k}")
                rows.append(fly_one(n, where, mission, driver, overrides, cores, follow_s,
                                    fps, log))
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
        if out is None:
            shutil.rmtree(folder, ignore_errors=True)
    rate = plan.config.runtime.control_rate_hz
    return {"bench": "load", "mission": "follow_ball", "hogs": list(hogs), "repeat": repeat,
            "follow_s": follow_s, "driver": driver, "overrides": list(overrides),
            "vehicle_core": cores[0], "autopilot_core": cores[1], "viewer_fps": fps,
            "control_rate_hz": rate, "rows": rows, **conclusions(rows, rate),
            "out": str(out) if out is not None else None}


def parse_hogs(text: str) -> list[int]:
    """``4`` (that load alone) or ``0,1,2,4``."""
    try:
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        values = []
    if not values or any(v < 0 or v > 64 for v in values):
        raise LoadBenchError(f"--hogs {text}: a number of busy processes (0-64), or a "
                             "comma-separated list of them, e.g. 0,1,2,4")
    return sorted(set(values))


# ----------------------------------------------------------------------------------------------
# the table
# ----------------------------------------------------------------------------------------------
