"""``autopilot bench mavlink``: every shipped mission flown by each MAVLink driver against the
simulator served as each firmware — ``autopilot sim --firmware px4`` (PX4 SITL's ports) and
``--firmware ardupilot`` (ArduCopter SITL's) — exactly as a user runs them, each in its own
process: the simulator with the mission's world and its ground truth recorded, ``autopilot run
--driver pymavlink|mavsdk`` over the firmware's link with the cameras as H.264 streams and the
simulator's camera calibrations, then ``autopilot score`` against the truth.

Real time (a MAVLink vehicle's clock is the wall clock): about a minute and a half a flight,
so the full matrix (7 missions × 2 firmwares × 2 drivers) takes about 45 minutes on 2 cores;
``--mission``, ``--firmware`` and ``--driver`` narrow it. Each cell gives the flight's status
and the headline figures of its scored step (its kind's first figures, as the terminal prints
them), against truth.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

MISSIONS = ("follow_ball", "follow_marker", "hover_image", "land_pad", "orbit", "survey",
            "land_on_rover")
DRIVERS = ("pymavlink", "mavsdk")
#: the headline figures of a step (its kind's first summary figures)
HEADLINE = 3


#: the firmwares flown (``autopilot sim --firmware``): their faces' modules and classes
FACES = {"px4": ("drivers.mavlink.face", "MavlinkFace"),
         "ardupilot": ("drivers.mavlink.face_ardupilot", "ArduPilotFace")}


def _connect(firmware: str, instance: int) -> str:
    """Where the autopilot connects to ``firmware``'s face (the face says)."""
    import importlib

    module, name = FACES[firmware]
    return getattr(importlib.import_module(module), name).companion_url(instance)


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "autopilot", *args]


def _plan(mission: str, overrides: Sequence[str]):
    from autopilot.mission import load_mission

    return load_mission(mission, list(overrides))


def fly_one(mission: str, firmware: str, driver: str, out: Path, *, instance: int = 6,
            timeout_s: float = 400.0, overrides: Sequence[str] = ()) -> dict:
    """One flight: the simulator, the autopilot, the score; the run's summary (or why not).
    ``overrides`` (``KEY=VALUE``) go to both processes: the world's (``scenario.*``,
    ``sim.*``) to the simulator, the mission's to the autopilot."""
    truth, run = out / "truth", out / "run"
    plan = _plan(mission, overrides)
    rover = "rover_link" in {need for _, _, need in plan.needs()}
    sim_args = ["sim", "--firmware", firmware, "--instance", str(instance), "--mission",
                mission, "--out", str(truth)]
    if rover:
        sim_args += ["--set", "sim.rover_link.mavlink=true"]
    sets = [arg for item in overrides for arg in ("--set", item)]
    sim_args += sets
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with open(out / "sim.log", "w") as sim_log:
        sim = subprocess.Popen(_cli(*sim_args), stdout=sim_log, stderr=subprocess.STDOUT,
                               env=env, start_new_session=True)
        try:
            if not _ready(out / "sim.log", sim, 120.0):
                return {"status": "not run", "reason": "the simulator did not start"}
            run_args = ["run", "--mission", mission, "--driver", driver, "--connect",
                        _connect(firmware, instance), "--out", str(run), "--overwrite"]
            for camera in plan.cameras_used():
                run_args += ["--calibration", f"{camera}={truth / f'{camera}_calibration.yaml'}"]
            if rover:
                run_args += ["--set", "link.rover_system_id=2"]
            run_args += sets
            started = time.monotonic()
            with open(out / "run.log", "w") as run_log:
                try:
                    subprocess.run(_cli(*run_args), stdout=run_log, stderr=subprocess.STDOUT,
                                   env=env, timeout=timeout_s, check=False)
                except subprocess.TimeoutExpired:
                    return {"status": "timeout", "reason": f"not done in {timeout_s:g} s"}
            wall_s = time.monotonic() - started
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(sim.pid, signal.SIGINT)
            try:
                sim.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(sim.pid, signal.SIGKILL)
                sim.wait()
    summary_path = run / "summary.json"
    if not summary_path.exists():
        return {"status": "no summary", "reason": (out / "run.log").read_text()[-400:]}
    subprocess.run(_cli("score", str(run), "--truth", str(truth / "truth.mcap")),
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    summary = json.loads(summary_path.read_text())
    return {"status": summary.get("status"), "reason": summary.get("reason") or "",
            "wall_s": round(wall_s, 1), "figures": headline(summary.get("metrics") or {})}


def _ready(path: Path, proc: subprocess.Popen, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            return False
        if "Ctrl-C to stop" in path.read_text(errors="replace"):
            return True
        time.sleep(0.5)
    return False


def headline(metrics: dict) -> dict[str, float | bool]:
    """The scored steps' first figures (``group.key`` → value), as the terminal prints them."""
    from autopilot.steps.registry import STEP_KINDS

    out: dict[str, float | bool] = {}
    for step in metrics.get("steps") or ():
        kind = STEP_KINDS.get(step.get("name"))
        if kind is None or not kind.summary:
            continue
        for figure in kind.summary[0][:HEADLINE]:
            value = (step.get(figure.group) or {}).get(figure.key)
            if isinstance(value, (int, float, bool)):
                out[f"{figure.group}.{figure.key}"] = value
    return out


def run_bench(missions: Sequence[str] = MISSIONS, firmwares: Sequence[str] = tuple(FACES),
              drivers: Sequence[str] = DRIVERS, *, out_dir: Path | None = None,
              instance: int = 6, overrides: Sequence[str] = (),
              log: Callable[[str], None] = print) -> dict:
    cells = []
    with tempfile.TemporaryDirectory(prefix="bench-mavlink-") as tmp:
        base = out_dir or Path(tmp)
        for mission in missions:
            for firmware in firmwares:
                for driver in drivers:
                    out = base / f"{mission}-{firmware}-{driver}"
                    out.mkdir(parents=True, exist_ok=True)
                    log(f"{mission} on {firmware} through {driver} ...")
                    cell = fly_one(mission, firmware, driver, out, instance=instance,
                                   overrides=overrides)
                    log(f"  {cell['status']} {cell.get('figures', cell.get('reason', ''))}")
                    cells.append({"mission": mission, "firmware": firmware, "driver": driver,
                                  **cell})
    return {"bench": "mavlink", "overrides": list(overrides), "cells": cells}


def merge(results: list[dict]) -> dict:
    """Several runs' cells (missions, firmwares or drivers flown apart) as one result; a cell
    flown twice keeps its later flight."""
    cells: dict[tuple[str, str, str], dict] = {}
    for result in results:
        for c in result["cells"]:
            cells[(c["mission"], c["firmware"], c["driver"])] = c
    order = {m: i for i, m in enumerate(MISSIONS)}
    return {"bench": "mavlink", "overrides": list(results[0].get("overrides") or ()),
            "cells": sorted(
        cells.values(), key=lambda c: (order.get(c["mission"], len(order)), c["firmware"],
                                      c["driver"]))}


def format_table(result: dict) -> str:
    """A table per mission: a row per firmware and driver, its status and figures."""
    lines: list[str] = []
    missions = dict.fromkeys(c["mission"] for c in result["cells"])
    for mission in missions:
        cells = [c for c in result["cells"] if c["mission"] == mission]
        keys = list(dict.fromkeys(k for c in cells for k in c.get("figures", {})))
        lines.append(mission)
        head = f"  {'firmware':<10} {'driver':<10} {'status':<10}" + "".join(
            f" {k.split('.', 1)[1]:>24}" for k in keys)
        lines.append(head)
        for c in cells:
            row = f"  {c['firmware']:<10} {c['driver']:<10} {c['status']:<10}"
            for k in keys:
                v = c.get("figures", {}).get(k)
                row += f" {_fmt(v):>24}"
            lines.append(row)
        for c in cells:
            if c["status"] != "completed":
                lines.append(f"  ({c['firmware']} through {c['driver']}: "
                             f"{c.get('reason') or c['status']})")
        lines.append("")
    return "\n".join(lines).rstrip()


def _fmt(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    return f"{value:.3f}" if isinstance(value, float) else str(value)
