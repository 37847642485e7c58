"""``autopilot bench hover_image`` / ``land_pad``: the down-camera missions flown by ours and by
the seed reports' baselines, everything else identical (the same world, seed, estimator):

* hover_image: our image detector against seed 000's (ORB 300 + FLANN + homography +
  solvePnPRansac), flown by our controller;
* land_pad: our pad detector and lander; seed 001's detector (multi-scale TM_CCOEFF template
  matching, :mod:`autopilot.perception.baselines`) with our lander; and seed 001's detector
  with seed 001's own landing logic (:mod:`autopilot.behaviors.land_pad_seed001`).

Scenarios: as shipped, and a hard one (1.5 m/s gusts; the target offset further and turned;
for the pad, three decoy pads of other colours around it). Each is flown with a few scenario
seeds. Every run counts: a run without the figure compared (the image never found, the
vehicle never landed) or whose step failed (for a landing: not on the pad) is a *failure*,
shown as such, and counted as an infinite error in the median and the worst over all runs
(a median over half failures or more, or a worst with any, is "fail", never a figure that
leaves them out); the other figures are means over the runs that have them, with that count.
hover_image is scored from the start of the step (``rms_horizontal_error_from_start_m``: the
approach included, so finding the image late costs), with the time to acquire it and the
settled hover error as figures of their own. Every estimate's RMS (against truth) is shown
with its lost share (the control ticks without a usable estimate). For a landing,
``error_m`` is where the vehicle came to rest, also when the step failed and the mission's
fallback landed it (that run is still a failure).

``quick``: one seed of the shipped scenario, shortened (the target near where the step
starts, a short hover, the down camera at 10 Hz), for a CI test that every row still flies and
that the comparisons point the way the full bench finds them (:data:`QUICK`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from autopilot.bench import schedule
from autopilot.bench.pooling import pool_runs
from autopilot.mission import load_mission


@dataclass(frozen=True)
class DownBench:
    mission: str
    group: str  # the metrics group
    #: each row's name and overrides (ours first)
    rows: dict[str, tuple[str, ...]]
    error: str  # the figure compared (lower is better; a run without it is a failure)
    metrics: tuple[str, ...]  # from the group, shown (the error first)
    scenarios: dict[str, tuple[str, ...]]
    #: a run succeeds when its step completed and these group flags are true
    success_flags: tuple[str, ...] = ()
    quick: tuple[str, ...] = field(default=())  # the quick variant's overrides


BENCHES = {
    "hover_image": DownBench(
        "hover_image", "hover", {
            "ours": (),
            "seed000": ("config.perception.image.detector=seed000",)},
        "rms_horizontal_error_from_start_m",
        ("rms_horizontal_error_from_start_m", "found_after_s", "rms_horizontal_error_m",
         "max_horizontal_error_m", "rms_yaw_error_deg", "detection_rate"), {
            "default": (),
            "hard_gusts1.5_offset_turned": (
                "scenario.wind.gust_mps=1.5", "scenario.image.north_east_m=[1.5, -1.2]",
                "scenario.image.yaw_deg=140"),
        },
        quick=("steps.1.hover_image.duration_s=8", "config.vehicle.cameras.down.rate_hz=10")),
    "land_pad": DownBench(
        "land_pad", "landing", {
            "ours": (),
            "seed001_detector": ("config.perception.pad.detector=seed001",),
            "seed001_detector_lander": ("config.perception.pad.detector=seed001",
                                        "steps.1.land_pad.lander=seed001")},
        "error_m",
        ("error_m", "retries", "found_after_s", "time_to_land_s", "touchdown_speed_m_s"), {
            "default": (),
            "hard_gusts1.5_decoys3_offset": (
                "scenario.wind.gust_mps=1.5", "scenario.decoys=3",
                "scenario.pad.north_east_m=[3.5, 2.0]", "scenario.pad.yaw_deg=30"),
        },
        success_flags=("on_pad",),
        # (max_retries 0: a lost pad fails at once rather than climbing to look again, which
        # with seed 001's detector took 76 s of flight and most of the variant's CPU; the down
        # camera at 5 Hz: seed 001's 13 templates a frame are the rest of it — 62 s for the
        # three rows, was 156 s at 10 Hz; the search at 4 m: at 3 m seed 001's templates
        # matched the pad in 13 % of the frames and its row searched for 20 s, at 4 m in 94 %
        # — 31 s for the three rows, with the same directions)
        quick=("scenario.pad.north_east_m=[0.7, -0.5]", "steps.1.land_pad.search_altitude_m=4.0",
               "steps.1.land_pad.max_retries=0", "config.vehicle.cameras.down.rate_hz=5")),
}

#: the rows as the documentation names them
ROW_LABELS = {
    "ours": "ours",
    "seed000": "seed 000's detector, our controller",
    "seed001_detector": "seed 001's detector, our lander",
    "seed001_detector_lander": "seed 001's detector and landing logic",
}

#: what the quick variant (CI) checks of each baseline row against ours: "better" — ours has
#: the lower error; "tie" — ours within ``TIE_M`` of it or lower (the full bench finds them
#: level: the same controller flies both once the target is found)
QUICK = {
    "hover_image": {"seed000": "tie"},
    "land_pad": {"seed001_detector": "tie", "seed001_detector_lander": "better"},
}
TIE_M = 0.02


def run_bench(bench: str, seeds: int = 3, overrides: Sequence[str] = (),
              log: Callable[[str], None] = lambda message: None,
              scenarios: Sequence[str] | None = None, *, quick: bool = False,
              rows: Sequence[str] | None = None, seed_start: int = 1,
              workers: int | None = None,
              announce: Callable[[str], None] | None = None) -> dict:
    """Each scenario flown by each row over ``seeds`` scenario seeds, on ``workers`` processes
    (default one per core, :mod:`autopilot.bench.schedule`); how long it will take goes to
    ``announce`` (default ``log``) before the first flight starts."""
    spec = BENCHES[bench]
    if quick:
        seeds, scenarios, seed_start = 1, ["default"], 1
    wanted = [(name, o) for name, o in spec.scenarios.items()
              if scenarios is None or name in scenarios]
    flown = [(name, o) for name, o in spec.rows.items() if rows is None or name in rows]
    # every flight's mission checked here, before any flies
    flights, jobs, profiles = [], [], []
    for scenario, scenario_overrides in wanted:
        for row, row_overrides in flown:
            for seed in range(seed_start, seed_start + seeds):
                items = [*scenario_overrides, *(spec.quick if quick else ()),
                         f"scenario.seed={seed}", *overrides, *row_overrides]
                plan = load_mission(spec.mission, items)
                flights.append((scenario, row, seed))
                jobs.append((spec.mission, items))
                profiles.append(plan.config.sim.profile)
    workers = schedule.workers_for(workers, len(jobs))
    variant = f"bench {bench}{' quick' if quick else ''}"
    kinds = [schedule.kind_of(spec.mission, p, variant, workers) for p in profiles]
    summaries = schedule.run_ordered(jobs, kinds, workers, announce=announce or log, log=log,
                                     describe=lambda i, _: "{}: {}, seed {}".format(*flights[i]))
    results: dict[str, dict] = {}
    for scenario, scenario_overrides in wanted:
        runs: dict[str, list[dict]] = {row: [] for row, _ in flown}
        for (name, row, seed), summary in zip(flights, summaries, strict=True):
            if name == scenario:
                runs[row].append(score_run(spec, summary, seed))
        table = {r: summarise(v, spec) for r, v in runs.items()}
        first = next(iter(table))
        results[scenario] = {
            "overrides": list(scenario_overrides), "runs": runs, "summary": table,
            "baseline_over_ours": {r: ratio(table[r], table[first], spec.error)
                                   for r in table if r != first}}
    return {"bench": bench, "mission": spec.mission, "seeds": seeds, "seed_start": seed_start,
            "quick": quick,
            "overrides": list(overrides), "compared": spec.error,
            "rows": {r: list(o) for r, o in spec.rows.items() if rows is None or r in rows},
            "scenarios": results}


def merge(results: Sequence[dict]) -> dict:
    """One result from several runs of the same bench (e.g. its rows or scenarios flown as
    separate processes, ``--row``/``--scenario``): runs are pooled per scenario and row, the
    summaries and ratios computed again, ours first."""
    first = results[0]
    spec = BENCHES[first["bench"]]
    pooled = pool_runs(results)
    scenarios = {}
    for scenario in [s for s in spec.scenarios if s in pooled]:
        data = pooled[scenario]
        runs = {row: data["runs"][row] for row in spec.rows if row in data["runs"]}
        table = {row: summarise(v, spec) for row, v in runs.items()}
        head = next(iter(table))
        scenarios[scenario] = {
            "overrides": data["overrides"], "runs": runs, "summary": table,
            "baseline_over_ours": {row: ratio(table[row], table[head], spec.error)
                                   for row in table if row != head}}
    seeds = sorted({r["seed"] for d in scenarios.values() for v in d["runs"].values()
                    for r in v})
    return {**first, "seeds": len(seeds) or first["seeds"],
            "seed_start": seeds[0] if seeds else first.get("seed_start", 1),
            "rows": {row: list(o) for row, o in spec.rows.items()
                     if any(row in d["runs"] for d in scenarios.values())},
            "scenarios": scenarios}


def score_run(spec: DownBench, summary: dict, seed: int) -> dict:
    """One run's figures, and whether it counts as a success (see the module's notes)."""
    metrics = summary.get("metrics") or {}
    group = metrics.get(spec.group) or {}
    estimation = metrics.get("estimation") or {}
    out = {"seed": seed, "status": summary.get("status"), "scored": bool(group),
           **{k: _number(group.get(k)) for k in spec.metrics},
           "estimate_rms_m": _number(estimation.get("rms_position_error_m")),
           "estimate_relative_rms_m": _number(estimation.get("rms_relative_position_error_m")),
           "estimate_lost_share": _number(estimation.get("lost_share")),
           "estimate_within_2sigma": _number(estimation.get("relative_within_2sigma")),
           "estimate_normalised_error_rms_ned":
               estimation.get("relative_normalised_error_rms_ned")}
    problems = []
    if out["status"] != "completed":
        problems.append(f"status {out['status']}")
    if out[spec.error] is None:
        problems.append(f"no {spec.error}")
    problems += [f"not {flag}" for flag in spec.success_flags if group.get(flag) is not True]
    out["success"] = not problems
    out["failure"] = "; ".join(problems) or None
    return out


def _number(value) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def summarise(runs: list[dict], spec: DownBench) -> dict:
    n = len(runs)
    ok = [r for r in runs if r["success"]]
    # the compared figure over all runs, a failure as +inf: a median or worst it reaches is null
    errors = np.array([r[spec.error] if r["success"] else math.inf for r in runs], dtype=float)
    median = float(np.percentile(errors, 50, method="higher")) if n else math.inf
    worst = float(np.max(errors)) if n else math.inf
    out: dict = {"runs": n, "succeeded": len(ok), "failed": n - len(ok),
                 "failures": [{"seed": r["seed"], "why": r["failure"]} for r in runs
                              if not r["success"]],
                 f"{spec.error}_median_all": median if math.isfinite(median) else None,
                 f"{spec.error}_worst_all": worst if math.isfinite(worst) else None}
    for key in (*spec.metrics, "estimate_rms_m", "estimate_lost_share",
                "estimate_within_2sigma"):
        values = [r[key] for r in runs if r.get(key) is not None]
        out[f"{key}_mean"] = float(np.mean(values)) if values else None
        out[f"{key}_n"] = len(values)
    # what the step flew on, relative to the vehicle: median and worst (one degenerate pose
    # can put a run's RMS anywhere, and a mean with it)
    rel = [r["estimate_relative_rms_m"] for r in runs
           if r.get("estimate_relative_rms_m") is not None]
    out["estimate_relative_rms_m_median"] = float(np.median(rel)) if rel else None
    out["estimate_relative_rms_m_worst"] = float(np.max(rel)) if rel else None
    out["estimate_relative_rms_m_n"] = len(rel)
    return out


def ratio(baseline: dict, ours: dict, error: str) -> float | None:
    """The baseline's median error over all runs ÷ ours: null when either median is a
    failure (the table says which)."""
    b, o = baseline[f"{error}_median_all"], ours[f"{error}_median_all"]
    if b is None or o is None or not o:
        return None
    return b / o


def quick_checks(result: dict) -> list[str]:
    """What the quick variant finds wrong: a row that did not fly (a run whose step has no
    figures at all: it never ran; a failed step still flew), and each comparison against
    :data:`QUICK`'s direction. Empty: all is well."""
    problems = []
    expected = QUICK[result["bench"]]
    for scenario, data in result["scenarios"].items():
        table = data["summary"]
        ours = table[next(iter(table))]
        error = result["compared"]
        for row, runs in data["runs"].items():
            if not runs or not all(r.get("scored") for r in runs):
                problems.append(f"{scenario}: {row} did not fly its step (no {result['bench']} "
                                "figures)")
        o = ours[f"{error}_median_all"]
        if o is None:
            problems.append(f"{scenario}: ours failed ({ours['failures']})")
            continue
        for row, direction in expected.items():
            if row not in table:
                continue
            b = table[row][f"{error}_median_all"]
            if b is None:  # the baseline failed: ours is better
                continue
            if direction == "better" and not o < b:
                problems.append(f"{scenario}: ours {o:.3f} not below {row} {b:.3f}")
            if direction == "tie" and not o <= b + TIE_M:
                problems.append(f"{scenario}: ours {o:.3f} not within {TIE_M} m of {row} "
                                f"{b:.3f} or below")
    return problems


def _estimate_cell(s: dict) -> str:
    """The estimate's RMS relative to the vehicle, median (worst); in results from before
    that was measured, the mean RMS against truth, marked "abs"."""
    if s.get("estimate_relative_rms_m_median") is not None:
        n = s["estimate_relative_rms_m_n"]
        return (f"{s['estimate_relative_rms_m_median']:.3f} "
                f"({s['estimate_relative_rms_m_worst']:.3f}) m"
                + ("" if n == s["runs"] else f" [{n}]"))
    return _cell(s["estimate_rms_m_mean"], s["estimate_rms_m_n"], s["runs"], "{:.3f} m abs")


def _cell(mean: float | None, n: int, runs: int, fmt: str) -> str:
    if mean is None:
        return "n/a"
    return fmt.format(mean) + ("" if n == runs else f" [{n}]")


def format_table(result: dict) -> str:
    spec = BENCHES[result["bench"]]
    e = spec.error
    lines = [f"{result['mission']}: {result['seeds']} seed(s) per scenario"
             f"{' (quick)' if result.get('quick') else ''}; {e}: median (worst) over all runs, "
             "a failure counted as infinite ('fail'); other figures: mean over the runs that "
             "have them ([n] when not all)"]
    keys = (*spec.metrics[1:], "estimate_lost_share")
    est_head = "estimate RMS rel. median (worst)"
    for scenario, data in result["scenarios"].items():
        lines.append("")
        lines.append(f"{scenario} ({', '.join(data['overrides']) or 'as shipped'})")
        width = max(12, *(len(r) + 2 for r in data["summary"]))
        lines.append(f"  {'':<{width}}{'ok':>7}{e:>{len(e) + 10}}" + "".join(
            f"{k:>{len(k) + 2}}" for k in keys) + f"{est_head:>{len(est_head) + 2}}"
            + f"{'÷ ours':>9}")
        for row, s in data["summary"].items():
            med, worst = s[f"{e}_median_all"], s[f"{e}_worst_all"]
            err = ("fail" if med is None else f"{med:.3f}") + \
                (" (fail)" if worst is None else f" ({worst:.3f})")
            cells = "".join(
                f"{_cell(s[f'{k}_mean'], s[f'{k}_n'], s['runs'], '{:.3f}'):>{len(k) + 2}}"
                for k in keys) + f"{_estimate_cell(s):>{len(est_head) + 2}}"
            r = data["baseline_over_ours"].get(row)
            shown = "—" if row == next(iter(data["summary"])) else (
                f"{r:.1f}×" if r is not None else ("∞" if med is None else "n/a"))
            lines.append(f"  {row:<{width}}{s['succeeded']:>3}/{s['runs']:<3}"
                         f"{err:>{len(e) + 10}}{cells}{shown:>9}")
            for f in s["failures"]:
                lines.append(f"  {'':<{width}}  failed seed {f['seed']}: {f['why']}")
    return "\n".join(lines)


def format_markdown(result: dict) -> list[str]:
    """The bench's tables as Markdown (for :mod:`autopilot.bench.tables`)."""
    spec = BENCHES[result["bench"]]
    e = spec.error
    keys = spec.metrics[1:]
    quick = " (quick variant)" if result.get("quick") else ""
    extra = "; overrides: " + ", ".join(f"`{o}`" for o in result["overrides"]) \
        if result["overrides"] else ""
    out = [f"### `{result['bench']}`", "",
           f"{result['seeds']} seed(s) per scenario{quick}{extra}. "
           f"`{e}`: median (worst) over all runs, a failed run counted as infinite (\"fail\"); "
           "the other figures: means over the runs that have them ([n] when not all); the "
           "estimate's RMS relative to the vehicle (what the step flew on: median (worst); "
           "\"abs\": from older runs, the mean against truth, the navigation's error in it) "
           "with its lost share, and the share of control ticks "
           "whose error relative to the vehicle was within its ±2σ on every axis (an honest σ "
           "gives about 0.87).", ""]
    for scenario, data in result["scenarios"].items():
        where = ", ".join(f"`{o}`" for o in data["overrides"]) or "as shipped"
        out.append(f"**{scenario}** ({where})")
        out.append("")
        head = ["", "ok", f"`{e}`", *(f"`{k}`" for k in keys), "estimate RMS (lost)",
                "within 2σ", "÷ ours"]
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + " --- |" * len(head))
        first = next(iter(data["summary"]))
        for row, s in data["summary"].items():
            med, worst = s[f"{e}_median_all"], s[f"{e}_worst_all"]
            err = ("fail" if med is None else f"{med:.3f}") + \
                (" (fail)" if worst is None else f" ({worst:.3f})")
            cells = [_cell(s[f"{k}_mean"], s[f"{k}_n"], s["runs"], "{:.3f}") for k in keys]
            est = _estimate_cell(s)
            lost = s["estimate_lost_share_mean"]
            est += "" if lost is None else f" ({lost:.0%})"
            r = data["baseline_over_ours"].get(row)
            shown = "—" if row == first else (
                f"{r:.1f}×" if r is not None else ("∞" if med is None else "n/a"))
            within = _cell(s.get("estimate_within_2sigma_mean"),
                           s.get("estimate_within_2sigma_n", 0), s["runs"], "{:.2f}")
            out.append("| " + " | ".join([ROW_LABELS.get(row, row),
                                           f"{s['succeeded']}/{s['runs']}", err, *cells, est,
                                           within, shown]) + " |")
        fails = [f"{ROW_LABELS.get(row, row)}, seed {f['seed']}: {f['why']}"
                 for row, s in data["summary"].items() for f in s["failures"]]
        if fails:
            out += ["", "Failed runs: " + "; ".join(fails) + "."]
        out.append("")
    return out
