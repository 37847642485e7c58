"""``autopilot bench follow_ball`` / ``follow_marker``: our follower against the seed reports'
rules.

Scenarios of the step's mission — as shipped, a hard one (a figure eight in gusts), and the
stress case (a random walk at 2.5 m/s RMS in 3 m/s gusts, at the vehicle's limits, over a 16 m
area: a walk accelerating at most 2 m/s² loses speed turning back at the edge of a smaller one;
the target's real RMS speed is reported with the figures) — each flown in
lockstep with our controller (``estimator``) and with the seed rules as baselines, everything
else identical (same seed, world, camera, detector). Reports the follow metrics side by side
and, per scenario, each baseline's RMS range error as a multiple of ours.

The seed rules command an AR.Drone (fractions of its maximum tilt, climb and yaw rates), flown
through :class:`~autopilot.control.ardrone.ArDroneTiltModel`. ``quick``: the default scenario
only, with the step shortened to ``QUICK_DURATION_S`` — for CI, which checks that every rule
still flies and that ours stays ahead; the figures of record come from the full bench.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from autopilot.mission import load_mission
from autopilot.run import fly


@dataclass(frozen=True)
class FollowBench:
    step: str  # the step kind whose ``controller`` is switched
    mission: str
    controllers: tuple[str, ...]  # ours first
    scenarios: dict[str, tuple[str, ...]]  # name → mission overrides


#: what each controller is, for the tables generated from ``--json``
CONTROLLERS = {
    "estimator": "ours: target estimate, standoff and feed-forward",
    "seed001": "seed 001: P on pixel errors with dead bands, last circle held (AR.Drone tilt)",
    "seed003": "seed 003: full-scale bang-bang, one axis a frame (AR.Drone tilt)",
    "seed002": "seed 002: P on the marker's camera translation (AR.Drone tilt)",
}
QUICK_DURATION_S = 10.0  # the followed step's length in a quick run


BENCHES = {
    "follow_ball": FollowBench(
        "follow_ball", "follow_ball", ("estimator", "seed001", "seed003"), {
            "default": (),
            "figure8_2mps_gusts": ("scenario.ball.path=figure8", "scenario.ball.speed_mps=2",
                                   "scenario.wind.gust_mps=2"),
            "stress_random_walk_2.5mps_gusts3": (
                "scenario.ball.path=random_walk", "scenario.ball.speed_mps=2.5",
                "scenario.ball.size_m=16", "scenario.wind.gust_mps=3"),
        }),
    "follow_marker": FollowBench(
        "follow_marker", "follow_marker", ("estimator", "seed002"), {
            "default": (),
            "figure8_1mps_gusts": ("scenario.marker.path=figure8",
                                   "scenario.marker.speed_mps=1", "scenario.wind.gust_mps=1"),
            "stress_random_walk_2.5mps_gusts3": (
                "scenario.marker.path=random_walk", "scenario.marker.speed_mps=2.5",
                "scenario.marker.path_size_m=16", "scenario.wind.gust_mps=3"),
        }),
}
METRICS = ("detection_rate", "rms_range_error_m", "rms_image_error_px", "max_lost_s",
           "target_speed_mps_rms")


def _step_index(plan, step: str) -> int:
    try:
        return next(i for i, s in enumerate(plan.steps) if s.name == step)
    except StopIteration:
        raise ValueError(f"mission {plan.mission.name!r} has no {step} step") from None


def run_bench(bench: str = "follow_ball", mission: str | None = None,
              overrides: Sequence[str] = (), log: Callable[[str], None] = lambda message: None,
              scenarios: Sequence[str] | None = None, quick: bool = False) -> dict:
    spec = BENCHES[bench]
    mission = mission or spec.mission
    if quick and scenarios is None:
        scenarios = ("default",)
    results: dict[str, dict] = {}
    for scenario, scenario_overrides in spec.scenarios.items():
        if scenarios is not None and scenario not in scenarios:
            continue
        runs = {}
        for controller in spec.controllers:
            base = load_mission(mission, [*scenario_overrides, *overrides])
            step = _step_index(base, spec.step)
            key = f"steps.{step}.{spec.step}"
            shorten = [f"{key}.duration_s={QUICK_DURATION_S:g}"] if quick else []
            plan = load_mission(mission, [*scenario_overrides, *overrides, *shorten,
                                          f"{key}.controller={controller}"])
            log(f"{scenario}: {controller} …")
            summary = asyncio.run(fly(plan, None))
            follow = summary["metrics"].get("follow") or {}
            runs[controller] = {
                "status": summary["status"],
                **{k: follow.get(k) for k in METRICS},
                "real_time_factor": summary["metrics"]["sim"]["real_time_factor"],
                "reason": summary.get("reason"),
                "follow_time_s": follow.get("follow_time_s"),
                "sim_profile": (summary.get("sim") or {}).get("profile"),
            }
        ours = runs[spec.controllers[0]]["rms_range_error_m"]
        baselines = spec.controllers[1:]
        ratios = {c: _ratio(runs[c]["rms_range_error_m"], ours) for c in baselines}
        better = min(baselines, key=lambda c: runs[c]["rms_range_error_m"] or math.inf)
        results[scenario] = {
            "overrides": list(scenario_overrides),
            "runs": runs,
            "baseline_rms_over_ours": ratios,
            "better_seed_rule": better,
            "better_seed_rule_over_ours": ratios[better],
        }
    return {"bench": bench, "mission": mission, "overrides": list(overrides),
            "scenarios": results, "quick": quick,
            "step_duration_s": QUICK_DURATION_S if quick else None,
            "controllers": {c: CONTROLLERS.get(c, c) for c in spec.controllers}}


def _ratio(baseline: float | None, ours: float | None) -> float | None:
    if baseline is None or not ours:
        return None
    return baseline / ours


def format_table(result: dict) -> str:
    lines = []
    if result.get("quick"):
        lines.append(f"quick: the step cut to {result['step_duration_s']:g} s (figures of "
                     "record: without --quick)")
    for scenario, data in result["scenarios"].items():
        extra = ", ".join(data["overrides"]) or "as shipped"
        lines.append(f"{scenario} ({extra})")
        head = f"  {'controller':<11} {'status':<10}" + "".join(
            f"{m:>{len(m) + 2}}" for m in METRICS) + f"{'rms ÷ ours':>12}"
        lines.append(head)
        for controller, run in data["runs"].items():
            ratio = data["baseline_rms_over_ours"].get(controller)
            cells = "".join(f"{_fmt(run[m]):>{len(m) + 2}}" for m in METRICS)
            lines.append(f"  {controller:<11} {run['status']:<10}{cells}"
                         f"{(f'{ratio:.1f}×' if ratio else '—'):>12}")
        lines.append(f"  better seed rule: {data['better_seed_rule']}, whose RMS range error is "
                     f"{_fmt(data['better_seed_rule_over_ours'])}× ours (target ≥ 3)")
        lines.append("")
    return "\n".join(lines).rstrip()


def _fmt(value) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def merge(results: Sequence[dict]) -> dict:
    """One result from several runs of the same follow bench (its scenarios flown as separate
    processes, ``--scenario``), in the bench's order of scenarios."""
    first = results[0]
    for r in results[1:]:
        for key in ("bench", "quick", "overrides"):
            if r.get(key) != first.get(key):
                raise ValueError(f"cannot merge {first['bench']} results with different {key}")
    pooled = {name: data for r in results for name, data in r["scenarios"].items()}
    order = [s for s in BENCHES[first["bench"]].scenarios if s in pooled]
    return {**first, "scenarios": {s: pooled[s] for s in order},
            "scenarios_flown": order}


def format_markdown(result: dict) -> list[str]:
    """The bench's tables as Markdown (for :mod:`autopilot.bench.tables`). A run that did not
    complete, or has no range error, is a failure in the ratio column, never dropped."""
    quick = f" (quick variant: the step cut to {result['step_duration_s']:g} s)" \
        if result.get("quick") else ""
    controllers = result.get("controllers") or {}
    out = [f"### `{result['bench']}`", "",
           f"One seed per scenario{quick}. `rms_range_error_m`: RMS of the standoff error over "
           "the follow step (truth); `max_lost_s`: the longest stretch without a detection; "
           "÷ ours: the controller's range RMS over ours (\"fail\": the run did not complete or "
           "has no figure).", ""]
    out += [f"- `{c}`: {text}" for c, text in controllers.items()]
    for scenario, data in result["scenarios"].items():
        where = ", ".join(f"`{o}`" for o in data["overrides"]) or "as shipped"
        out += ["", f"**{scenario}** ({where})", ""]
        head = ["", "status", *(f"`{m}`" for m in METRICS), "÷ ours"]
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + " --- |" * len(head))
        first = next(iter(data["runs"]))
        for controller, run in data["runs"].items():
            ratio = data["baseline_rms_over_ours"].get(controller)
            failed = run["status"] != "completed" or run.get("rms_range_error_m") is None
            shown = "—" if controller == first else (
                "fail" if failed or ratio is None else f"{ratio:.1f}×")
            cells = [_fmt(run.get(m)) for m in METRICS]
            out.append("| " + " | ".join([f"`{controller}`", run["status"], *cells, shown])
                       + " |")
    out.append("")
    return out
