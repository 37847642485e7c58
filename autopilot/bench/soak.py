"""``autopilot bench soak``: an hour of simulated flight (lockstep), missions back to back in
one process and one event loop, as a companion computer flies them: does anything grow?

After each mission (its vehicle closed, its log written and deleted) the process is sampled:
resident memory (``VmRSS``, after a garbage collection: a leak survives one), the event loop's
tasks besides the soak's own, threads, open file descriptors; each run's summary gives its
event loop's lag (p99, max) and stalls. The baseline is the sample after the first round of
every mission (imports, caches, the renderer's first contexts); the verdict compares the last
sample with it: memory growth at most ``max_growth_pct`` (5 %), no more tasks, threads or file
descriptors than at the baseline, every run ended (completed, or safe).
"""

from __future__ import annotations

import asyncio
import gc
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from autopilot.flightlog.safety import outcome
from autopilot.mission import load_mission
from autopilot.run import fly

MISSIONS = ("follow_ball", "survey", "land_on_rover", "orbit", "hover_image", "land_pad",
            "follow_marker")
MAX_GROWTH_PCT = 5.0


def _rss_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _fds() -> int | None:
    try:
        return len(os.listdir("/proc/self/fd"))
    except OSError:
        return None


def sample(sim_s: float, runs: int) -> dict:
    gc.collect()
    current = asyncio.current_task()
    return {"runs": runs, "sim_s": round(sim_s, 1), "wall_s": round(time.perf_counter(), 1),
            "rss_mb": round(_rss_mb(), 1),
            "tasks": len([t for t in asyncio.all_tasks() if t is not current]),
            "threads": len(_own_threads()), "fds": _fds()}


#: how long the verdict waits for threads on their way out (see :func:`soak`)
SETTLE_S = 5.0


def _thread_names() -> list[str]:
    return sorted(t.name for t in _own_threads())


def _own_threads() -> list[threading.Thread]:
    """The process's threads but the event loop's default executor's (``asyncio_N``): that
    pool grows to at most its ``max_workers`` when more blocking calls overlap (as they do on
    a busy machine), and is not a leak; every other thread counts."""
    return [t for t in threading.enumerate() if not t.name.startswith("asyncio_")]


async def soak(duration_s: float, missions: Sequence[str] = MISSIONS,
               overrides: Sequence[str] = (), log: Callable[[str], None] = lambda m: None,
               max_growth_pct: float = MAX_GROWTH_PCT) -> dict:
    runs: list[dict] = []
    samples = [sample(0.0, 0)]
    names: list[list[str]] = [_thread_names()]  # (each sample's threads, for the verdict)
    started = time.perf_counter()
    sim_total = 0.0
    with tempfile.TemporaryDirectory(prefix="autopilot-soak-") as tmp:
        while sim_total < duration_s:
            i = len(runs)
            mission = missions[i % len(missions)]
            plan = load_mission(mission, [f"scenario.seed={i}", *overrides])
            out = Path(tmp) / f"{i:03d}-{mission}"
            summary = await fly(plan, out)
            size_mb = (out / "flight.mcap").stat().st_size / 1e6 \
                if (out / "flight.mcap").exists() else 0.0
            await asyncio.to_thread(shutil.rmtree, out, True)
            sim_total += float(summary.get("sim_time_s") or 0.0)
            stats = summary.get("stats", {})
            safety = summary.get("metrics", {}).get("safety", {})
            kind, why = outcome(summary["status"], safety)
            runs.append({"mission": mission, "seed": i, "status": summary["status"],
                         "outcome": kind, "why": why, "sim_s": summary.get("sim_time_s"),
                         "wall_s": round(summary.get("wall_time_s") or 0.0, 1),
                         "log_mb": round(size_mb, 1),
                         "loop_lag_p99_ms": stats.get("loop_lag_p99_ms"),
                         "loop_lag_max_ms": stats.get("loop_lag_max_ms"),
                         "loop_stalls": stats.get("loop_stalls", 0)})
            samples.append(sample(sim_total, len(runs)))
            names.append(_thread_names())
            s = samples[-1]
            log(f"{len(runs)}: {mission} {summary['status']} ({kind}); {sim_total:.0f} s "
                f"simulated; RSS {s['rss_mb']:.0f} MB, {s['tasks']} tasks, {s['threads']} "
                f"threads, {s['fds']} fds; loop lag p99 {stats.get('loop_lag_p99_ms') or 0:.1f} ms")
    base_index = min(len(missions), len(samples) - 1)
    base, end = samples[base_index], samples[-1]
    # a thread the last flight told to stop may still be on its way out on a busy machine:
    # a leak is one still there after a few seconds
    waited = 0.0
    while len(_own_threads()) > base["threads"] and waited < SETTLE_S:
        await asyncio.sleep(0.1)
        waited += 0.1
    if waited:
        end = samples[-1] = {**end, "threads": len(_own_threads())}
        names[-1] = _thread_names()
    growth = 100.0 * (end["rss_mb"] - base["rss_mb"]) / base["rss_mb"]
    p99 = [r["loop_lag_p99_ms"] for r in runs if r["loop_lag_p99_ms"] is not None]
    worst = [r["loop_lag_max_ms"] for r in runs if r["loop_lag_max_ms"] is not None]
    checks = {
        "memory_growth_pct": round(growth, 2),
        "memory_ok": growth <= max_growth_pct,
        "tasks_ok": end["tasks"] <= base["tasks"],
        "threads_ok": end["threads"] <= base["threads"],
        # the threads alive at the end that were not at the baseline (a leak names itself)
        "new_threads": sorted(set(names[-1]) - set(names[base_index])),
        "fds_ok": end["fds"] is None or base["fds"] is None or end["fds"] <= base["fds"],
        "runs_ok": all(r["outcome"] != "unsafe" for r in runs),
    }
    return {
        "duration_s": duration_s, "sim_s": round(sim_total, 1),
        "wall_s": round(time.perf_counter() - started, 1), "missions": list(missions),
        "runs": runs, "samples": samples, "baseline": base, "end": end,
        "start": samples[0], "loop_lag_p99_ms": max(p99) if p99 else None,
        "loop_lag_max_ms": max(worst) if worst else None,
        "loop_stalls": sum(r["loop_stalls"] or 0 for r in runs),
        "max_growth_pct": max_growth_pct, **checks,
        "ok": all(v for k, v in checks.items() if k.endswith("_ok")),
    }


def run_bench(duration_s: float, missions: Sequence[str] = MISSIONS,
              overrides: Sequence[str] = (), log: Callable[[str], None] = lambda m: None) -> dict:
    return asyncio.run(soak(duration_s, missions, overrides, log))


def format_table(r: dict) -> str:
    b, e, s = r["baseline"], r["end"], r["start"]
    completed = sum(x["outcome"] == "completed" for x in r["runs"])
    return "\n".join([
        f"soak: {r['sim_s']:.0f} s simulated in {r['wall_s']:.0f} s wall, {len(r['runs'])} "
        f"missions back to back ({completed} completed, "
        f"{sum(x['outcome'] == 'unsafe' for x in r['runs'])} unsafe)",
        f"  memory (RSS)     start {s['rss_mb']:.0f} MB, after the first round "
        f"{b['rss_mb']:.0f} MB, end {e['rss_mb']:.0f} MB: {r['memory_growth_pct']:+.1f} % "
        f"(limit {r['max_growth_pct']:g} %)",
        f"  tasks            baseline {b['tasks']}, end {e['tasks']}",
        f"  threads          baseline {b['threads']}, end {e['threads']}",
        f"  file descriptors baseline {b['fds']}, end {e['fds']}",
        f"  event loop lag   p99 (worst run) {r['loop_lag_p99_ms'] or 0:.1f} ms, max "
        f"{r['loop_lag_max_ms'] or 0:.0f} ms, {r['loop_stalls']} stalls",
        f"  verdict          {'ok' if r['ok'] else 'FAILED'}",
    ])
