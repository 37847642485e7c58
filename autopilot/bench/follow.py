"""``autopilot bench follow_ball`` / ``follow_marker``: our follower against the seed reports'
rules.

Scenarios of the step's mission — as shipped, a hard one (a figure eight in gusts), and the
stress case (a random walk at 2.5 m/s RMS in 3 m/s gusts, at the vehicle's limits, over a 16 m
area: a walk accelerating at most 2 m/s² loses speed turning back at the edge of a smaller one;
the target's real RMS speed is reported with the figures) — each flown in
lockstep over a few scenario seeds with our controller (``estimator``) and with the seed rules
as baselines, everything else identical (same seeds, world, camera, detector). Reports the
follow metrics side by side and, per scenario, each baseline's median RMS range error as a
multiple of ours; a run that did not complete, or has no range error, counts as a failure
(infinite in the median and the worst), never dropped.

The seed rules command an AR.Drone (fractions of its maximum tilt, climb and yaw rates), flown
through :class:`~autopilot.control.ardrone.ArDroneTiltModel`. ``quick``: the default scenario
only, with the step shortened to ``QUICK_DURATION_S`` — for CI, which checks that every rule
still flies and that ours stays ahead; the figures of record come from the full bench.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.bench import schedule
from autopilot.bench.pooling import pool_runs
from autopilot.mission import load_mission


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
              scenarios: Sequence[str] | None = None, quick: bool = False, *,
              seeds: int = 3, seed_start: int = 1,
              controllers: Sequence[str] | None = None, workers: int | None = None,
              announce: Callable[[str], None] | None = None) -> dict:
    """Each scenario flown by each controller over ``seeds`` scenario seeds from
    ``seed_start`` (``scenario.seed``: the target's path draws, noise, gusts); ``quick``: one
    seed of the default scenario, the step shortened. The flights go to ``workers`` processes
    (default one per core, :mod:`autopilot.bench.schedule`); how long they will take goes to
    ``announce`` (default ``log``) before the first starts."""
    spec = BENCHES[bench]
    mission = mission or spec.mission
    if quick:
        scenarios = scenarios or ("default",)
        seeds = 1
    flown = [c for c in spec.controllers if controllers is None or c in controllers]
    wanted = [(name, o) for name, o in spec.scenarios.items()
              if scenarios is None or name in scenarios]
    # every flight's mission checked here, before any flies
    flights, jobs, profiles = [], [], []
    for scenario, scenario_overrides in wanted:
        base = load_mission(mission, [*scenario_overrides, *overrides])
        key = f"steps.{_step_index(base, spec.step)}.{spec.step}"
        shorten = [f"{key}.duration_s={QUICK_DURATION_S:g}"] if quick else []
        for controller in flown:
            for seed in range(seed_start, seed_start + seeds):
                items = [*scenario_overrides, f"scenario.seed={seed}", *overrides, *shorten,
                         f"{key}.controller={controller}"]
                plan = load_mission(mission, items)
                flights.append((scenario, controller, seed))
                jobs.append((mission, items))
                profiles.append(plan.config.sim.profile)
    workers = schedule.workers_for(workers, len(jobs))
    variant = f"bench {bench}{' quick' if quick else ''}"
    kinds = [schedule.kind_of(mission, p, variant, workers) for p in profiles]
    summaries = schedule.run_ordered(jobs, kinds, workers, announce=announce or log, log=log,
                                     describe=lambda i, _: "{}: {}, seed {}".format(*flights[i]))
    results: dict[str, dict] = {}
    for scenario, scenario_overrides in wanted:
        runs: dict[str, list[dict]] = {c: [] for c in flown}
        for (name, controller, seed), summary in zip(flights, summaries, strict=True):
            if name == scenario:
                runs[controller].append(score_run(summary, seed))
        results[scenario] = _scenario_result(list(scenario_overrides), runs, spec)
    return {"bench": bench, "mission": mission, "overrides": list(overrides),
            "seeds": seeds, "seed_start": seed_start,
            "scenarios": results, "quick": quick,
            "step_duration_s": QUICK_DURATION_S if quick else None,
            "controllers": {c: CONTROLLERS.get(c, c) for c in flown}}


def score_run(summary: dict, seed: int) -> dict:
    """One flight's figures; it fails when it did not complete or has no range error."""
    follow = summary["metrics"].get("follow") or {}
    estimation = summary["metrics"].get("estimation") or {}
    run = {
        "seed": seed,
        "status": summary["status"],
        **{k: follow.get(k) for k in METRICS},
        "estimate_rms_m": estimation.get("rms_relative_position_error_m"),
        "estimate_lost_share": estimation.get("lost_share"),
        "estimate_within_2sigma": estimation.get("relative_within_2sigma"),
        "estimate_normalised_error_rms_ned":
            estimation.get("relative_normalised_error_rms_ned"),
        "real_time_factor": summary["metrics"]["sim"]["real_time_factor"],
        "reason": summary.get("reason"),
        "follow_time_s": follow.get("follow_time_s"),
        "sim_profile": (summary.get("sim") or {}).get("profile"),
    }
    run["success"] = run["status"] == "completed" and run["rms_range_error_m"] is not None
    return run


def summarise(runs: list[dict]) -> dict:
    """A controller's runs pooled: the range RMS's median and worst over *all* runs (a failed
    run counted as infinite: a median or worst it reaches is null), the other figures' means
    over the runs that have them (with their count)."""
    n = len(runs)
    errors = np.array([r["rms_range_error_m"] if r["success"] else math.inf for r in runs],
                      dtype=float)
    median = float(np.percentile(errors, 50, method="higher")) if n else math.inf
    worst = float(np.max(errors)) if n else math.inf
    out: dict = {"runs": n, "succeeded": sum(r["success"] for r in runs),
                 "failures": [{"seed": r["seed"], "why": r["reason"] or r["status"]}
                              for r in runs if not r["success"]],
                 "rms_range_error_m_median_all": median if math.isfinite(median) else None,
                 "rms_range_error_m_worst_all": worst if math.isfinite(worst) else None}
    for key in (*METRICS, "estimate_rms_m", "estimate_lost_share", "estimate_within_2sigma"):
        values = [r[key] for r in runs if r.get(key) is not None]
        out[f"{key}_mean"] = float(np.mean(values)) if values else None
        out[f"{key}_n"] = len(values)
    return out


def _scenario_result(overrides: list[str], runs: dict[str, list[dict]],
                     spec: FollowBench) -> dict:
    table = {c: summarise(v) for c, v in runs.items()}
    ours = spec.controllers[0]
    o = (table.get(ours) or {}).get("rms_range_error_m_median_all")
    ratios = {c: _ratio(table[c]["rms_range_error_m_median_all"], o)
              for c in table if c != ours}
    better = min(ratios, key=lambda c: table[c]["rms_range_error_m_median_all"] or math.inf,
                 default=None)
    return {"overrides": overrides, "runs": runs, "summary": table,
            "baseline_rms_over_ours": ratios, "better_seed_rule": better,
            "better_seed_rule_over_ours": ratios.get(better) if better else None}


def _ratio(baseline: float | None, ours: float | None) -> float | None:
    if baseline is None or not ours:
        return None
    return baseline / ours


def format_table(result: dict) -> str:
    lines = [f"{result['bench']}: {result.get('seeds', 1)} seed(s) per scenario; "
             "rms_range_error_m: median (worst) over all runs, a failure counted as infinite "
             "('fail'); other figures: means over the runs that have them"]
    if result.get("quick"):
        lines.append(f"quick: the step cut to {result['step_duration_s']:g} s (figures of "
                     "record: without --quick)")
    keys = [m for m in METRICS if m != "rms_range_error_m"]
    for scenario, data in result["scenarios"].items():
        extra = ", ".join(data["overrides"]) or "as shipped"
        lines.append(f"{scenario} ({extra})")
        lines.append(f"  {'controller':<11} {'ok':>5}  {'rms_range_error_m':>22}" + "".join(
            f"{m:>{len(m) + 2}}" for m in keys) + f"{'rms ÷ ours':>12}")
        for controller, s in data["summary"].items():
            ratio = data["baseline_rms_over_ours"].get(controller)
            cells = "".join(f"{_fmt(s[f'{m}_mean']):>{len(m) + 2}}" for m in keys)
            lines.append(f"  {controller:<11} {s['succeeded']:>2}/{s['runs']:<2}  "
                         f"{_median_worst(s):>22}{cells}"
                         f"{(f'{ratio:.1f}×' if ratio else '—'):>12}")
            for f in s["failures"]:
                lines.append(f"  {'':<11} failed seed {f['seed']}: {f['why']}")
        if data.get("better_seed_rule"):
            lines.append(f"  better seed rule: {data['better_seed_rule']}, whose median RMS "
                         f"range error is {_fmt(data['better_seed_rule_over_ours'])}× ours "
                         "(target ≥ 3)")
        lines.append("")
    return "\n".join(lines).rstrip()


def _median_worst(s: dict) -> str:
    med, worst = s["rms_range_error_m_median_all"], s["rms_range_error_m_worst_all"]
    return ("fail" if med is None else f"{med:.3f}") + \
        (" (fail)" if worst is None else f" ({worst:.3f})")


def _fmt(value) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def merge(results: Sequence[dict]) -> dict:
    """One result from several runs of the same follow bench (its scenarios, controllers or
    seeds flown as separate processes): runs pooled per scenario and controller, summaries
    and ratios computed again, in the bench's order."""
    first = results[0]
    spec = BENCHES[first["bench"]]
    pooled = pool_runs(results)
    order = [s for s in spec.scenarios if s in pooled]
    scenarios = {}
    for scenario in order:
        runs = pooled[scenario]["runs"]
        runs = {c: sorted(runs[c], key=lambda r: r["seed"]) for c in spec.controllers
                if c in runs}
        scenarios[scenario] = _scenario_result(pooled[scenario]["overrides"], runs, spec)
    seeds = sorted({r["seed"] for d in scenarios.values() for v in d["runs"].values()
                    for r in v})
    controllers = {c: CONTROLLERS.get(c, c) for c in spec.controllers
                   if any(c in d["runs"] for d in scenarios.values())}
    return {**first, "scenarios": scenarios, "scenarios_flown": order,
            "seeds": len(seeds), "seed_start": seeds[0] if seeds else 1,
            "controllers": controllers}


def format_markdown(result: dict) -> list[str]:
    """The bench's tables as Markdown (for :mod:`autopilot.bench.tables`). A run that did not
    complete, or has no range error, is a failure (infinite in the median and the worst),
    never dropped."""
    quick = f" (quick variant: the step cut to {result['step_duration_s']:g} s)" \
        if result.get("quick") else ""
    extra = "; overrides: " + ", ".join(f"`{o}`" for o in result["overrides"]) \
        if result.get("overrides") else ""
    controllers = result.get("controllers") or {}
    keys = [m for m in METRICS if m != "rms_range_error_m"]
    out = [f"### `{result['bench']}`", "",
           f"{result.get('seeds', 1)} seed(s) per scenario{quick}{extra}. "
           "`rms_range_error_m`: RMS of the standoff error over the follow step (truth), "
           "median (worst) over all runs, a failed run (not completed, or no figure) counted "
           "as infinite (\"fail\"); the other figures: means over the runs that have them "
           "([n] when not all); `max_lost_s`: the longest stretch without a detection; the "
           "estimate's RMS relative to the vehicle (truth) with its lost share, and the share "
           "of control ticks whose relative error was within its ±2σ on every axis (an honest "
           "σ gives about 0.87); ÷ ours: the median range RMS over ours.", ""]
    out += [f"- `{c}`: {text}" for c, text in controllers.items()]
    for scenario, data in result["scenarios"].items():
        where = ", ".join(f"`{o}`" for o in data["overrides"]) or "as shipped"
        out += ["", f"**{scenario}** ({where})", ""]
        head = ["", "ok", "`rms_range_error_m`", *(f"`{m}`" for m in keys),
                "estimate RMS (lost)", "within 2σ", "÷ ours"]
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + " --- |" * len(head))
        first = next(iter(data["summary"]))
        for controller, s in data["summary"].items():
            ratio = data["baseline_rms_over_ours"].get(controller)
            med = s["rms_range_error_m_median_all"]
            shown = "—" if controller == first else (
                f"{ratio:.1f}×" if ratio is not None else ("∞" if med is None else "n/a"))
            cells = [_cell(s, m, "{:.3f}") for m in keys]
            est = _cell(s, "estimate_rms_m", "{:.3f} m")
            lost = s["estimate_lost_share_mean"]
            est += "" if lost is None else f" ({lost:.0%})"
            within = _cell(s, "estimate_within_2sigma", "{:.2f}")
            out.append("| " + " | ".join([f"`{controller}`", f"{s['succeeded']}/{s['runs']}",
                                           _median_worst(s), *cells, est, within, shown])
                       + " |")
        fails = [f"`{c}`, seed {f['seed']}: {f['why']}"
                 for c, s in data["summary"].items() for f in s["failures"]]
        if fails:
            out += ["", "Failed runs: " + "; ".join(fails) + "."]
    out.append("")
    return out


def _cell(s: dict, key: str, fmt: str) -> str:
    mean, n = s[f"{key}_mean"], s[f"{key}_n"]
    if mean is None:
        return "n/a"
    return fmt.format(mean) + ("" if n == s["runs"] else f" [{n}]")
