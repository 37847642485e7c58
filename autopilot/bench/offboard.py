"""``autopilot bench offboard``: orbit and survey (seed 004's offboard missions) flown with our
tracker and with seed 004's, everything else identical (the same paths, photo points, vehicle,
world and seeds).

Ours streams the time-parametrised reference — position, with velocity and acceleration as
feed-forward, and the heading with its rate — and lets the reference wait when the vehicle
falls behind. Seed 004's (``control.trajectory.tracker=seed004``) ran a PID on the position
error to the time-indexed setpoints and commanded velocity only.

Scenarios: the shipped orbit and survey, the survey over a concave (U-shaped) polygon, and both
in 1.5 m/s gusts. The table gives each tracker's cross-track error (RMS and worst, against the
planned path, from the true positions), survey coverage and photos (true poses), the orbit's
centre offset in the photos, and how fast the lockstep run was (simulated ÷ wall time).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence

import numpy as np

from autopilot.mission import load_mission
from autopilot.run import fly

U_SHAPE = "[[0,0],[24,0],[24,24],[16,24],[16,8],[8,8],[8,24],[0,24]]"

SCENARIOS: dict[str, tuple[str, tuple[str, ...]]] = {
    "orbit": ("orbit", ()),
    "orbit_gusts1.5": ("orbit", ("scenario.wind.gust_mps=1.5",)),
    "survey": ("survey", ()),
    "survey_concave": ("survey", (f"steps.1.survey.polygon_m={U_SHAPE}",)),
    "survey_gusts1.5": ("survey", ("scenario.wind.gust_mps=1.5",)),
}
TRACKERS = ("ours", "seed004")
METRICS = {
    "orbit": ("rms_cross_track_m", "max_cross_track_m", "rms_cross_track_nav_m",
              "radius_rms_error_m", "photos", "centre_in_frame", "centre_offset_px_max"),
    "survey": ("rms_cross_track_m", "max_cross_track_m", "rms_cross_track_nav_m", "coverage",
               "photos", "forward_overlap_min", "side_overlap_min"),
}


def run_bench(seeds: int = 2, overrides: Sequence[str] = (),
              log: Callable[[str], None] = lambda message: None,
              scenarios: Sequence[str] | None = None) -> dict:
    results: dict[str, dict] = {}
    for scenario, (mission, scenario_overrides) in SCENARIOS.items():
        if scenarios is not None and scenario not in scenarios:
            continue
        runs: dict[str, list[dict]] = {}
        for tracker in TRACKERS:
            runs[tracker] = []
            for seed in range(1, seeds + 1):
                log(f"{scenario}: {tracker}, seed {seed} …")
                plan = load_mission(mission, [
                    *scenario_overrides, f"scenario.seed={seed}", f"sim.seed={seed}",
                    *overrides, f"control.trajectory.tracker={tracker}"])
                summary = asyncio.run(fly(plan, None))
                group = summary["metrics"].get(mission) or {}
                runs[tracker].append({
                    "seed": seed, "status": summary["status"],
                    **{k: group.get(k) for k in METRICS[mission]},
                    "images_planned": group.get("images_planned", group.get("photos_planned")),
                    "real_time_factor": summary["metrics"]["sim"]["real_time_factor"]})
        table = {t: _summarise(r, mission) for t, r in runs.items()}
        results[scenario] = {
            "mission": mission, "overrides": list(scenario_overrides), "runs": runs,
            "summary": table, "seed004_over_ours": seed004_over_ours(table)}
    return {"bench": "offboard", "seeds": seeds, "overrides": list(overrides),
            "scenarios": results}


def seed004_over_ours(table: dict) -> float | None:
    """Seed 004's mean cross-track error over ours, against the vehicle's navigation (what a
    tracker controls: against truth, a GNSS navigation's decimetres swamp both), or against
    truth for results without it."""
    for key in ("rms_cross_track_nav_m_mean", "rms_cross_track_m_mean"):
        ours = (table.get("ours") or {}).get(key)
        base = (table.get("seed004") or {}).get(key)
        if ours and base is not None:
            return base / ours
    return None


def _summarise(runs: list[dict], mission: str) -> dict:
    out: dict = {"runs": len(runs),
                 "completed": sum(r["status"] == "completed" for r in runs)}
    for key in (*METRICS[mission], "real_time_factor"):
        values = [float(r[key]) for r in runs if isinstance(r[key], (int, float))]
        worst = min if key in ("coverage", "photos", "centre_in_frame", "forward_overlap_min",
                               "side_overlap_min", "real_time_factor") else max
        out[f"{key}_mean"] = float(np.mean(values)) if values else None
        out[f"{key}_n"] = len(values)
        # a run without the figure (it never got that far) is never left out of the worst:
        # the worst is then a failure (null), and the mean says over how many runs it is
        out[f"{key}_worst"] = float(worst(values)) if values and len(values) == len(runs) \
            else None
    return out


def format_table(result: dict) -> str:
    lines = [f"orbit and survey: {result['seeds']} seeds per scenario; mean (worst); ÷ ours: "
             "seed 004's mean cross-track error against the navigation over ours"]
    for scenario, data in result["scenarios"].items():
        keys = (*METRICS[data["mission"]], "real_time_factor")
        lines.append("")
        lines.append(f"{scenario} ({', '.join(data['overrides']) or 'as shipped'})")
        lines.append(f"  {'tracker':<9}{'completed':>10}" + "".join(
            f"{k:>{max(len(k), 15) + 2}}" for k in keys) + f"{'÷ ours':>9}")
        for tracker, s in data["summary"].items():
            cells = []
            for k in keys:
                mean, worst, n = s[f"{k}_mean"], s[f"{k}_worst"], s.get(f"{k}_n", s["runs"])
                cell = "n/a" if mean is None else (
                    f"{mean:.3f}" + (f" ({worst:.3f})" if worst is not None
                                     else f" [{n}] (fail)"))
                cells.append(f"{cell:>{max(len(k), 15) + 2}}")
            ratio = seed004_over_ours(data["summary"]) if tracker == "seed004" else None
            lines.append(f"  {tracker:<9}{s['completed']:>6}/{s['runs']:<3}" + "".join(cells)
                         + f"{(f'{ratio:.1f}×' if ratio else '—'):>9}")
    return "\n".join(lines)
