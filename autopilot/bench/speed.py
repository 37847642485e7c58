"""``autopilot bench speed``: where a simulated second goes. Each mission flies in lockstep as
``autopilot run --stages`` does, in a process of its own, alone, on each sensor profile; its
real-time factor, the CPU milliseconds of each stage per simulated second
(:mod:`drivers.stages`), the process's total CPU and wall time, and what the remaining cost is
bounded by (:func:`bound`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

#: the missions flown by default (every shipped one but standby, which waits for goals)
DEFAULT_MISSIONS = ("follow_ball", "follow_marker", "hover_image", "land_pad", "orbit",
                    "survey", "land_on_rover")
PROFILES = ("realistic", "ideal")
#: the process is CPU-bound when it keeps this share of the machine's cores busy
CPU_BOUND_SHARE = 0.85
#: below it, the work comes in bursts when its threads waited for a core this share of the
#: wall time (summed over threads) or more
BURST_WAIT_SHARE = 0.3


def stage_summary(cpu_s: Mapping[str, float], threads_s: Mapping[str, float],
                  sim_time_s: float | None, wall_s: float, process_cpu_s: float,
                  run_queue_wait_s: float | None = None) -> dict:
    """A run's stages for its summary: CPU seconds by stage and by thread, what no stage
    counted (``other``: the event loop, telemetry hand-over, imports), each stage per
    simulated second, and how long its threads waited for a core (None: not known)."""
    counted = sum(cpu_s.values())
    stages = {**{k: round(v, 4) for k, v in sorted(cpu_s.items())},
              "other": round(max(process_cpu_s - counted, 0.0), 4)}
    per_sim = {} if not sim_time_s else {k: round(v * 1e3 / sim_time_s, 2)
                                         for k, v in stages.items()}
    return {"wall_s": round(wall_s, 3), "sim_time_s": sim_time_s,
            "process_cpu_s": round(process_cpu_s, 3), "cpu_s": stages,
            "threads_cpu_s": {k: round(v, 3) for k, v in sorted(threads_s.items())},
            "run_queue_wait_s": None if run_queue_wait_s is None else round(run_queue_wait_s, 3),
            "ms_per_sim_s": per_sim}


def bound(stages: Mapping, cores: int) -> str:
    """What the run's wall time is bounded by: the CPU when the process kept nearly all the
    cores busy; bursts of work wider than the cores when, with cores idle on average, its
    threads still waited for one (:data:`BURST_WAIT_SHARE` of the wall time or more, summed);
    else the busiest thread (the serial path; the render thread counted with the rasteriser
    it waits for)."""
    wall = stages["wall_s"]
    busy = stages["process_cpu_s"] / wall if wall > 0 else 0.0
    if busy >= CPU_BOUND_SHARE * cores:
        return (f"CPU-bound: {busy:.2f} of {cores} cores busy ({100 * busy / cores:.0f} %); "
                "only less CPU work makes it faster")
    threads = dict(stages["threads_cpu_s"])
    if "rasteriser" in stages["cpu_s"] and "render" in threads:
        threads["render"] += stages["cpu_s"]["rasteriser"]
    name, cpu = max(threads.items(), key=lambda kv: kv[1]) if threads else ("?", 0.0)
    label = "render thread (with the rasteriser)" if name == "render" else f"{name} thread"
    busiest = f"the {label} busy {100 * cpu / wall:.0f} % of the wall time"
    waited = stages.get("run_queue_wait_s")
    if waited is not None and wall > 0 and waited / wall >= BURST_WAIT_SHARE:
        return (f"bursts: {busy:.2f} of {cores} cores busy on average, yet its threads "
                f"waited {waited / wall:.2f} s a second for a core: each frame's work (its "
                "render, camera model, detection, the loop's reply) comes wider than the "
                "cores, with idle gaps between; less CPU work a frame makes it faster, more "
                f"threads would not ({busiest})")
    return (f"serial path: {busiest}, {busy:.2f} of {cores} cores busy; more parallel work "
            f"would use the idle {cores - busy:.2f}")


def fly_one(mission: str, profile: str, overrides: Sequence[str], out: Path) -> dict:
    """One lockstep flight with its stages counted, as its own process."""
    cmd = [sys.executable, "-m", "autopilot", "run", "--mission", mission, "--stages",
           "--out", str(out), "--set", f"sim.profile={profile}"]
    for item in overrides:
        cmd += ["--set", item]
    started = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    summary_path = out / "summary.json"
    if not summary_path.exists():
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return {"status": "error", "reason": " / ".join(tail) or f"exit {proc.returncode}",
                "process_wall_s": round(wall, 2)}
    summary = json.loads(summary_path.read_text())
    stages = summary.get("stages") or {}
    return {"status": summary["status"], "reason": summary.get("reason", ""),
            "real_time_factor": summary["metrics"]["sim"].get("real_time_factor"),
            "stages_ms_per_sim_s": stages.get("ms_per_sim_s", {}),
            "cpu_ms_per_sim_s": round(stages["process_cpu_s"] * 1e3 / stages["sim_time_s"], 1)
            if stages.get("sim_time_s") else None,
            "wall_s": stages.get("wall_s"), "sim_time_s": stages.get("sim_time_s"),
            "process_cpu_s": stages.get("process_cpu_s"),
            "threads_cpu_s": stages.get("threads_cpu_s", {}),
            "run_queue_wait_s": stages.get("run_queue_wait_s"),
            "bound": bound(stages, os.cpu_count() or 1) if stages else "",
            "process_wall_s": round(wall, 2)}


def run_bench(missions: Sequence[str], profiles: Sequence[str], overrides: Sequence[str],
              out: Path, progress: Callable[[str], None]) -> dict:
    """Every mission on every profile, one after another (alone: the timing is the point).
    ``missions.<name>`` holds the first profile's figures, and each profile's under
    ``profiles``."""
    result: dict = {"bench": "speed", "cores": os.cpu_count(), "overrides": list(overrides),
                    "profiles": list(profiles), "missions": {}}
    for mission in missions:
        entry: dict = {"profiles": {}}
        for profile in profiles:
            progress(f"{mission} on the {profile} profile …")
            cell = fly_one(mission, profile, overrides, out / f"{mission}-{profile}")
            entry["profiles"][profile] = cell
            progress(f"{mission} on the {profile} profile: {cell['status']}"
                     + (f", × {cell['real_time_factor']:.2f} real time"
                        if cell.get("real_time_factor") else f" ({cell.get('reason')})"))
        first = entry["profiles"][profiles[0]]
        result["missions"][mission] = {**first, "profile": profiles[0],
                                       "profiles": entry["profiles"]}
    return result


def format_table(result: dict, top: int = 6) -> str:
    """Per mission and profile: the real-time factor, the CPU per simulated second, the
    costliest stages with their shares, and the bound."""
    lines = [f"Lockstep speed on {result['cores']} cores (CPU ms per simulated second)", ""]
    for mission, entry in result["missions"].items():
        for profile, cell in entry["profiles"].items():
            head = f"{mission} ({profile})"
            if cell.get("real_time_factor") is None:
                lines.append(f"{head}: {cell['status']} ({cell.get('reason', '')})")
                continue
            total = cell["cpu_ms_per_sim_s"]
            lines.append(f"{head}: × {cell['real_time_factor']:.2f} real time, "
                         f"{total:.0f} ms CPU per simulated second "
                         f"({cell['process_cpu_s']:.1f} s CPU in {cell['wall_s']:.1f} s)"
                         + ("" if cell["status"] == "completed" else f" — {cell['status']}"))
            ranked = sorted(cell["stages_ms_per_sim_s"].items(), key=lambda kv: -kv[1])
            lines.append("    " + ", ".join(f"{name} {ms:.0f} ({100 * ms / total:.0f} %)"
                                            for name, ms in ranked[:top]))
            lines.append(f"    {cell['bound']}")
    return "\n".join(lines)
