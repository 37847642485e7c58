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
import itertools
import json
import math
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from autopilot.config import InputError

DEFAULT_HOGS = (0, 2, 4, 6)
DEFAULT_FOLLOW_S = 20.0
VIEWER_FPS = 15.0
#: shed above this share of frames counts as shedding (a frame now and then is noise, and the
#: camera itself drops ~1 % on the realistic profile: counted too, since the capture times'
#: span cannot tell them apart)
SHED_SHARE = 0.03
#: the control loop keeps its rate while its tick interval's p99 stays within this many periods
TICK_P99_PERIODS = 1.5
#: the vehicle keeps real time above this factor
VEHICLE_REAL_TIME = 0.95

# What the bench's children run first: pin to a core, die with the bench, optionally lower
# (numerically) the niceness, then become the real program. A launcher rather than Popen's
# preexec_fn: nothing runs between fork and exec in the bench's own process.
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

def _percentile(values: Sequence[float], q: float) -> float | None:
    if not len(values):
        return None
    import numpy as np

    return float(np.percentile(values, q))


def tick_intervals_ms(records: Iterable[Mapping], step: str = "follow_ball") -> list[float]:
    """Intervals between the control ticks of ``step`` (one ``/control/target`` record each)."""
    times = [r["time_s"] for r in records if r.get("step") == step]
    return [1e3 * (b - a) for a, b in itertools.pairwise(times)]


def perception_shed(records: Iterable[Mapping], camera_rate_hz: float | None = None
                    ) -> tuple[int, int]:
    """(frames shed, frames delivered) over the processed frames' span. The decoder numbers
    the frames it decodes, so a gap in the sequence is a decoded frame detection never saw;
    frames the decoder itself never got to (a starved decoder's socket overflows) leave no
    gap, so with ``camera_rate_hz`` the camera's own count over the span of capture times is
    the floor of what was delivered."""
    rows = [r for r in records if r.get("seq") is not None]
    seqs = sorted({int(r["seq"]) for r in rows})
    if not seqs:
        return 0, 0
    delivered = seqs[-1] - seqs[0] + 1
    times = [float(r["time_s"]) for r in rows if r.get("time_s") is not None]
    if camera_rate_hz and len(times) > 1:
        delivered = max(delivered, round((max(times) - min(times)) * camera_rate_hz) + 1)
    return delivered - len(seqs), delivered


def console_shed(viewer: Mapping, fps: float) -> tuple[int, int] | None:
    """(frames shed, frames due) for the viewer: due at its rate over the time it watched, but
    never more than the camera delivered then (sequence numbers); None if it saw nothing."""
    if not viewer.get("frames") or viewer.get("first_seq") is None:
        return None
    delivered = viewer["last_seq"] - viewer["first_seq"] + 1
    watched_s = viewer["last_arrival_s"] - viewer["first_arrival_s"]
    due = min(delivered, round(fps * watched_s) + 1)
    return max(0, due - viewer["frames"]), due


_EVENT = re.compile(r"^\[\s*([0-9.]+) s \| (\d\d):(\d\d):(\d\d(?:\.\d+)?)\]")


def vehicle_real_time_factor(lines: Iterable[str]) -> float | None:
    """Simulated over wall time between the first and the last of ``autopilot sim``'s event
    lines (``[  12.34 s | 13:20:01.123] armed``); None with fewer than two, or too close."""
    points = []
    for line in lines:
        m = _EVENT.match(line)
        if m:
            wall = int(m[2]) * 3600 + int(m[3]) * 60 + float(m[4])
            points.append((float(m[1]), wall))
    if len(points) < 2:
        return None
    (s0, w0), (s1, w1) = points[0], points[-1]
    wall = (w1 - w0) % 86400  # (past midnight)
    return (s1 - s0) / wall if wall >= 5.0 else None


def _share(pair: tuple[int, int] | None) -> float | None:
    return None if pair is None or not pair[1] else pair[0] / pair[1]


def row_from(hogs: int, summary: Mapping | None, records: Mapping | None,
             viewer: Mapping | None, sim_lines: Sequence[str], fps: float,
             failure: str | None = None, truth_real_time_factor: float | None = None,
             camera_rate_hz: float | None = None) -> dict:
    """One load's figures from its run's summary and log records, the viewer's result and the
    simulator's output; ``failure`` says why the run gave no summary (if it did not).
    ``truth_real_time_factor`` stands in for the vehicle's when its lines do not give it (a
    flight that ended before the vehicle armed)."""
    from autopilot.flightlog import records as ch

    records = records or {}
    ticks = tick_intervals_ms(records.get(ch.CONTROL_TARGET, []))
    shed = perception_shed(records.get(ch.detection_topic("ball"), []), camera_rate_hz)
    console = console_shed(viewer, fps) if viewer else None
    metrics = (summary or {}).get("metrics", {})
    latency = metrics.get("latency_ms", {})
    follow = metrics.get("follow", {})
    completed = summary is not None and summary.get("status") == "completed"
    if summary is None:
        why = failure or "no summary"
    elif completed:
        why = None
    else:
        why = f"{summary.get('status')}: {summary.get('reason') or 'no reason given'}"
    return {
        "hogs": hogs,
        "completed": completed,
        "why": why,
        "tick_ms_p50": _percentile(ticks, 50),
        "tick_ms_p99": _percentile(ticks, 99),
        "ticks": len(ticks) + 1 if ticks else 0,
        "latency_ms_p50": latency.get("p50"),
        "latency_ms_p95": latency.get("p95"),
        "perception_shed": shed[0],
        "perception_frames": shed[1],
        "perception_shed_share": _share(shed),
        "console_shed": console[0] if console else None,
        "console_frames_due": console[1] if console else None,
        "console_shed_share": _share(console),
        "viewer_error": (viewer or {}).get("error"),
        "rms_range_error_m": follow.get("rms_range_error_m"),
        "detection_rate": follow.get("detection_rate"),
        "vehicle_real_time_factor": vehicle_real_time_factor(sim_lines)
        or truth_real_time_factor,
        "loop_lag_p99_ms": (summary or {}).get("stats", {}).get("loop_lag_p99_ms"),
    }


def conclusions(rows: Sequence[Mapping], control_rate_hz: float) -> dict:
    """The curve's landmarks: the highest load that completed, the lowest at which perception
    sheds, the highest up to which control kept its rate (every load up to it)."""
    by_load = sorted(rows, key=lambda r: r["hogs"])
    limit_ms = TICK_P99_PERIODS * 1e3 / control_rate_hz
    completed = [r["hogs"] for r in by_load if r["completed"]]
    measured = [r for r in by_load if r["perception_shed_share"] is not None]
    shedding = [r["hogs"] for r in measured if r["perception_shed_share"] > SHED_SHARE]
    held = None
    for r in by_load:
        if r["tick_ms_p99"] is None or r["tick_ms_p99"] > limit_ms:
            break
        held = r["hogs"]
    return {"max_hogs_completed": max(completed) if completed else None,
            "perception_measured": bool(measured),
            "perception_sheds_from": min(shedding) if shedding else None,
            "control_rate_held_to": held, "tick_p99_limit_ms": limit_ms}


# ----------------------------------------------------------------------------------------------
# the bench
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
              cores: tuple[int, int] | None = None) -> dict:
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
            rows.append(fly_one(n, folder / f"hogs{n}", mission, driver, overrides, cores,
                                follow_s, fps, log))
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
        if out is None:
            shutil.rmtree(folder, ignore_errors=True)
    rate = plan.config.runtime.control_rate_hz
    return {"bench": "load", "mission": "follow_ball", "hogs": list(hogs),
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

def format_table(r: Mapping) -> str:
    def num(x, fmt="{:.0f}"):
        return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)

    def pct(x):
        return "–" if x is None else f"{100 * x:.1f} %"

    head = (f"{'busy':>4}  {'completed':<9}  {'tick ms p50/p99':>15}  "
            f"{'glass→setpoint ms p50/p95':>25}  {'perception shed':>15}  "
            f"{'console shed':>12}  {'range RMS':>9}  {'vehicle':>7}")
    lines = [
        f"load: follow_ball ({r['follow_s']:g} s following) in real time over "
        f"{r['driver']}, H.264 video; the vehicle alone on core {r['vehicle_core']}, the "
        f"autopilot, a console viewer ({r['viewer_fps']:g} fps MJPEG) and N busy processes "
        f"on core {r['autopilot_core']}",
        head, "-" * len(head)]
    notes = []
    for row in r["rows"]:
        rtf = row["vehicle_real_time_factor"]
        lines.append(
            f"{row['hogs']:>4}  {'yes' if row['completed'] else 'NO':<9}  "
            f"{num(row['tick_ms_p50']) + ' / ' + num(row['tick_ms_p99']):>15}  "
            f"{num(row['latency_ms_p50']) + ' / ' + num(row['latency_ms_p95']):>25}  "
            f"{pct(row['perception_shed_share']):>15}  {pct(row['console_shed_share']):>12}  "
            f"{num(row['rms_range_error_m'], '{:.3f} m'):>9}  "
            f"{num(rtf, '{:.2f}×'):>7}")
        if row["why"]:
            notes.append(f"  {row['hogs']} busy: {row['why']}")
        if rtf is not None and rtf < VEHICLE_REAL_TIME:
            notes.append(f"  {row['hogs']} busy: the vehicle ran at {rtf:.2f}× real time (its "
                         "core was not its own): its telemetry looked old for that reason")
    lines += notes
    completed, sheds, held = (r["max_hogs_completed"], r["perception_sheds_from"],
                              r["control_rate_held_to"])
    lines += [
        f"completed up to {completed} busy processes" if completed is not None
        else "no load completed",
        (f"perception sheds over {100 * SHED_SHARE:g} % of frames from {sheds} busy"
         if sheds is not None else "perception shed no more than "
         f"{100 * SHED_SHARE:g} % of frames at any load" if r["perception_measured"]
         else "perception not measured (no flight reached the follow step)")
        + "; control kept its rate (tick p99 ≤ "
        f"{r['tick_p99_limit_ms']:.0f} ms) " + (f"up to {held} busy" if held is not None
                                                else "at no load"),
        "(tick: the control step, at least "
        f"{r['control_rate_hz']:g} Hz and on every estimate; vehicle: its real-time factor)"]
    return "\n".join(lines)
