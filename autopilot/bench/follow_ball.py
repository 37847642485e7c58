"""``autopilot bench follow_ball``: our follower against the seed reports' rules.

Two scenarios of the ``follow_ball`` mission — as shipped (a circle at 1 m/s), and a figure eight
at 2 m/s in gusts — each flown in lockstep with our controller (``estimator``) and with the
seed 001 and seed 003 rules as baselines, everything else identical (same seed, world, camera,
detector). Reports the follow metrics side by side and, per scenario, each baseline's RMS range
error as a multiple of ours.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Sequence

from autopilot.mission import load_mission
from autopilot.run import fly

CONTROLLERS = ("estimator", "seed001", "seed003")
SCENARIOS: dict[str, tuple[str, ...]] = {
    "default": (),
    "figure8_2mps_gusts": ("scenario.ball.path=figure8", "scenario.ball.speed_mps=2",
                           "scenario.wind.gust_mps=2"),
}
METRICS = ("detection_rate", "rms_range_error_m", "rms_image_error_px", "max_lost_s")


def _follow_step_index(plan) -> int:
    return next(i for i, s in enumerate(plan.steps) if s.name == "follow_ball")


def run_bench(mission: str = "follow_ball", overrides: Sequence[str] = (),
              log: Callable[[str], None] = lambda message: None) -> dict:
    results: dict[str, dict] = {}
    for scenario, scenario_overrides in SCENARIOS.items():
        runs = {}
        for controller in CONTROLLERS:
            base = load_mission(mission, [*scenario_overrides, *overrides])
            step = _follow_step_index(base)
            plan = load_mission(mission, [*scenario_overrides, *overrides,
                                          f"steps.{step}.follow_ball.controller={controller}"])
            log(f"{scenario}: {controller} …")
            summary = asyncio.run(fly(plan, None))
            runs[controller] = {
                "status": summary["status"],
                **{k: summary["metrics"]["follow"].get(k) for k in METRICS},
                "real_time_factor": summary["metrics"]["sim"]["real_time_factor"],
            }
        ours = runs["estimator"]["rms_range_error_m"]
        ratios = {c: _ratio(runs[c]["rms_range_error_m"], ours) for c in CONTROLLERS[1:]}
        better = min(CONTROLLERS[1:], key=lambda c: runs[c]["rms_range_error_m"] or math.inf)
        results[scenario] = {
            "overrides": list(scenario_overrides),
            "runs": runs,
            "baseline_rms_over_ours": ratios,
            "better_seed_rule": better,
            "better_seed_rule_over_ours": ratios[better],
        }
    return {"mission": mission, "overrides": list(overrides), "scenarios": results}


def _ratio(baseline: float | None, ours: float | None) -> float | None:
    if baseline is None or not ours:
        return None
    return baseline / ours


def format_table(result: dict) -> str:
    lines = []
    for scenario, data in result["scenarios"].items():
        extra = ", ".join(data["overrides"]) or "as shipped"
        lines.append(f"{scenario} ({extra})")
        head = f"  {'controller':<11} {'status':<10}" + "".join(f"{m:>20}" for m in METRICS) + \
            f"{'rms ÷ ours':>12}"
        lines.append(head)
        for controller, run in data["runs"].items():
            ratio = data["baseline_rms_over_ours"].get(controller)
            cells = "".join(f"{_fmt(run[m]):>20}" for m in METRICS)
            lines.append(f"  {controller:<11} {run['status']:<10}{cells}"
                         f"{(f'{ratio:.1f}×' if ratio else '—'):>12}")
        lines.append(f"  better seed rule: {data['better_seed_rule']}, whose RMS range error is "
                     f"{_fmt(data['better_seed_rule_over_ours'])}× ours (target ≥ 3)")
        lines.append("")
    return "\n".join(lines).rstrip()


def _fmt(value) -> str:
    return "n/a" if value is None else f"{value:.3f}"
