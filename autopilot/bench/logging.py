"""``autopilot bench logging``: what writing the flight log costs a lockstep run.

The same lockstep ``follow_ball`` flight (deterministic: identical in every run) is flown
alternately with the flight log written (``flight.mcap`` with every camera frame as JPEG, the
simulator's default) and without it (records kept in memory for the metrics, nothing
written, no frame encoded). The cost is the ratio of wall times, median over the pairs:
alternating spreads the machine's own slow moments (hypervisor steal, reported) over both.
Target: at most 15 % slower.
"""

from __future__ import annotations

import asyncio
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from autopilot.mission import load_mission
from autopilot.process import StealMeter
from autopilot.run import fly

TARGET_OVERHEAD_PCT = 15.0


def _flight(mission: str, overrides: Sequence[str],
            out: Path | None) -> tuple[float, float, dict]:
    """Wall time, CPU time (all of the process's threads: the renderer's too) and summary."""
    plan = load_mission(mission, list(overrides))
    started, cpu = time.perf_counter(), time.process_time()
    summary = asyncio.run(fly(plan, out))
    return time.perf_counter() - started, time.process_time() - cpu, summary


def run_bench(mission: str = "follow_ball", overrides: Sequence[str] = (), pairs: int = 3,
              log: Callable[[str], None] = lambda message: None) -> dict:
    steal = StealMeter()
    with_log, without, cpu_with, cpu_without, sizes = [], [], [], [], []
    frames = 0
    with tempfile.TemporaryDirectory(prefix="autopilot-bench-") as tmp:
        _flight(mission, overrides, None)  # warm-up: imports, caches, the renderer
        for i in range(pairs):
            out = Path(tmp) / f"run{i}"
            wall, cpu, summary = _flight(mission, overrides, out)
            with_log.append(wall)
            cpu_with.append(cpu)
            frames = summary["stats"].get("frames_logged", 0)
            sizes.append((out / "flight.mcap").stat().st_size)
            shutil.rmtree(out)
            wall_off, cpu_off, _ = _flight(mission, overrides, None)
            without.append(wall_off)
            cpu_without.append(cpu_off)
            log(f"pair {i + 1}: {wall:.2f} s ({cpu:.1f} s CPU) with the log, {wall_off:.2f} s "
                f"({cpu_off:.1f} s CPU) without")

    def overhead(a: list[float], b: list[float]) -> float:
        return 100.0 * (statistics.median(x / y for x, y in zip(a, b, strict=True)) - 1.0)

    return {
        "mission": mission, "overrides": list(overrides), "pairs": pairs,
        "sim_time_s": summary["sim_time_s"],
        "wall_with_log_s": with_log, "wall_without_log_s": without,
        "cpu_with_log_s": cpu_with, "cpu_without_log_s": cpu_without,
        "overhead_pct": overhead(with_log, without),
        "cpu_overhead_pct": overhead(cpu_with, cpu_without), "target_pct": TARGET_OVERHEAD_PCT,
        "frames_logged": frames, "log_size_mb": statistics.median(sizes) / 1e6,
        "cpu_steal_pct": steal.percent(),
    }


def format_table(r: dict) -> str:
    steal = r["cpu_steal_pct"]
    rows = [
        ("flight", f"{r['mission']} {' '.join(r['overrides'])}".strip(),
         f"lockstep, {r['sim_time_s']:.1f} s simulated"),
        ("wall time with log", " ".join(f"{w:.2f}" for w in r["wall_with_log_s"]), "s"),
        ("wall time without", " ".join(f"{w:.2f}" for w in r["wall_without_log_s"]), "s"),
        ("logging overhead", f"{r['overhead_pct']:.1f}",
         f"% of wall time (median of {r['pairs']} pairs; target ≤ {r['target_pct']:.0f})"),
        ("CPU time with log", " ".join(f"{w:.1f}" for w in r["cpu_with_log_s"]), "s"),
        ("CPU time without", " ".join(f"{w:.1f}" for w in r["cpu_without_log_s"]), "s"),
        ("logging CPU cost", f"{r['cpu_overhead_pct']:.1f}",
         "% of CPU time (all threads; steadier than wall time on a shared machine)"),
        ("frames logged", str(r["frames_logged"]), f"JPEG, flight.mcap {r['log_size_mb']:.1f} MB"),
        ("hypervisor steal", "n/a" if steal is None else f"{steal:.1f}", "% of CPU time"),
    ]
    return "\n".join(f"{a:<22}{b:>24}  {c}" for a, b, c in rows)
