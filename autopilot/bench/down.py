"""``autopilot bench hover_image`` / ``land_pad``: the down-camera missions flown with our
detector and with the seed report's (seed 000: ORB 300 + FLANN + homography + solvePnPRansac;
seed 001: multi-scale TM_CCOEFF template matching), everything else identical (the same
estimator, controller, world, seed; :mod:`autopilot.perception.baselines`).

Scenarios: as shipped, and a hard one (1.5 m/s gusts; the target offset further and turned;
for the pad, three decoy pads of other colours around it). Each is flown with a few scenario
seeds; the table gives each detector's figures (mean and worst over the seeds) and the
baseline's error as a multiple of ours. ``estimate_rms_m``: the RMS error of the target's
estimate the controller flew on, against truth. For a landing, ``error_m`` is where the vehicle
came to rest, also when the step failed and the mission's fallback landed it (a failed step
shows in ``completed`` and ``retries``).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.mission import load_mission
from autopilot.run import fly


@dataclass(frozen=True)
class DownBench:
    mission: str
    group: str  # the metrics group
    detector_key: str  # the configuration key choosing the detector
    detectors: tuple[str, ...]  # ours first
    error: str  # the figure compared (lower is better)
    metrics: tuple[str, ...]
    scenarios: dict[str, tuple[str, ...]]


BENCHES = {
    "hover_image": DownBench(
        "hover_image", "hover", "config.perception.image.detector", ("ours", "seed000"),
        "rms_horizontal_error_m",
        ("rms_horizontal_error_m", "max_horizontal_error_m", "rms_yaw_error_deg",
         "detection_rate", "estimate_rms_m"), {
            "default": (),
            "hard_gusts1.5_offset_turned": (
                "scenario.wind.gust_mps=1.5", "scenario.image.north_east_m=[1.5, -1.2]",
                "scenario.image.yaw_deg=140"),
        }),
    "land_pad": DownBench(
        "land_pad", "landing", "config.perception.pad.detector", ("ours", "seed001"),
        "error_m",
        ("error_m", "on_pad", "retries", "time_to_land_s", "touchdown_speed_m_s",
         "estimate_rms_m"), {
            "default": (),
            "hard_gusts1.5_decoys3_offset": (
                "scenario.wind.gust_mps=1.5", "scenario.decoys=3",
                "scenario.pad.north_east_m=[3.5, 2.0]", "scenario.pad.yaw_deg=30"),
        }),
}


def run_bench(bench: str, seeds: int = 3, overrides: Sequence[str] = (),
              log: Callable[[str], None] = lambda message: None,
              scenarios: Sequence[str] | None = None) -> dict:
    spec = BENCHES[bench]
    results: dict[str, dict] = {}
    for scenario, scenario_overrides in spec.scenarios.items():
        if scenarios is not None and scenario not in scenarios:
            continue
        runs: dict[str, list[dict]] = {}
        for detector in spec.detectors:
            runs[detector] = []
            for seed in range(1, seeds + 1):
                log(f"{scenario}: {detector}, seed {seed} …")
                plan = load_mission(spec.mission, [
                    *scenario_overrides, f"scenario.seed={seed}", *overrides,
                    f"{spec.detector_key}={detector}"])
                summary = asyncio.run(fly(plan, None))
                group = summary["metrics"].get(spec.group) or {}
                estimation = summary["metrics"].get("estimation") or {}
                runs[detector].append({
                    "seed": seed, "status": summary["status"],
                    **{k: group.get(k) for k in spec.metrics if k != "estimate_rms_m"},
                    "estimate_rms_m": estimation.get("rms_position_error_m")})
        table = {d: _summarise(r, spec) for d, r in runs.items()}
        ours = table[spec.detectors[0]][f"{spec.error}_mean"]
        results[scenario] = {
            "overrides": list(scenario_overrides), "runs": runs, "summary": table,
            "baseline_over_ours": {d: _ratio(table[d][f"{spec.error}_mean"], ours)
                                   for d in spec.detectors[1:]}}
    return {"bench": bench, "mission": spec.mission, "seeds": seeds,
            "overrides": list(overrides), "compared": spec.error, "scenarios": results}


def _summarise(runs: list[dict], spec: DownBench) -> dict:
    out: dict = {"runs": len(runs),
                 "completed": sum(r["status"] == "completed" for r in runs)}
    for key in spec.metrics:
        values = [r[key] for r in runs if isinstance(r[key], (int, float))
                  and not isinstance(r[key], bool)]
        flags = [r[key] for r in runs if isinstance(r[key], bool)]
        if flags:
            out[f"{key}_share"] = sum(flags) / len(runs)
        elif values:
            out[f"{key}_mean"] = float(np.mean(values))
            out[f"{key}_max"] = float(np.max(values))
        else:
            out[f"{key}_mean"] = out[f"{key}_max"] = None
    return out


def _ratio(baseline: float | None, ours: float | None) -> float | None:
    if baseline is None or not ours:
        return None
    return baseline / ours


def format_table(result: dict) -> str:
    spec = BENCHES[result["bench"]]
    lines = [f"{result['mission']}: {result['seeds']} seeds per scenario; mean (worst)"]
    for scenario, data in result["scenarios"].items():
        lines.append("")
        lines.append(f"{scenario} ({', '.join(data['overrides']) or 'as shipped'})")
        head = f"  {'detector':<10}{'completed':>10}" + "".join(
            f"{m:>{max(len(m), 15) + 2}}" for m in spec.metrics) + f"{'÷ ours':>9}"
        lines.append(head)
        for detector, s in data["summary"].items():
            cells = []
            for m in spec.metrics:
                if f"{m}_share" in s:
                    cell = f"{s[f'{m}_share']:.2f}"
                else:
                    mean, worst = s[f"{m}_mean"], s[f"{m}_max"]
                    cell = "n/a" if mean is None else f"{mean:.3f} ({worst:.3f})"
                cells.append(f"{cell:>{max(len(m), 15) + 2}}")
            ratio = data["baseline_over_ours"].get(detector)
            lines.append(f"  {detector:<10}{s['completed']:>6}/{s['runs']:<3}" + "".join(cells)
                         + f"{(f'{ratio:.1f}×' if ratio else '—'):>9}")
    return "\n".join(lines)
