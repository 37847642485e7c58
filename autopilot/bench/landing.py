"""``autopilot bench landing``: landing on the moving rover, many seeds, ours against seed 004's
strategy in the same trials (the same seeds: the same rover path, sensor noise and gusts).

* ``ours`` — the shipped land_on_rover: the relative-state filter (UWB ranges, the deck's tag,
  rangefinder, the rover's reports, each at its capture time) and the moving setpoint with the
  deck's velocity and acceleration fed forward;
* ``seed004`` — seed 004's, as its chapter 4 describes it (``strategy: seed004``): one filterpy
  Kalman filter fusing PX4's local position, a UWB position pre-solved in the rover's frame,
  the tag, the rover's compass and the laser altimeter on its 10 Hz update and 5 Hz prediction
  timers (:mod:`autopilot.estimation.seed004`), and its landing action's gain-scheduled PID
  commanding velocity (approach, then descent within its threshold);
* ``ours_uwb_only`` — ours without the tag (``use_marker: false``), the landing a camera
  failure leaves.

For each: ``success_rate`` (completed, on the deck), ``median_error_m`` and ``p95_error_m`` of
the touchdown's distance from the deck's centre over *all* trials — a trial that did not land
on the deck counts as an infinite error, so a p95 over more than 5 % misses is null (never a
figure that leaves the misses out) — the time to land and the retries; and the failing seeds
with the command that replays each. Runs go through :mod:`autopilot.trials` (local workers,
or ``--cluster``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from autopilot.trials import Criterion, TrialsResult, run_trials

MISSION = "land_on_rover"
STRATEGIES: dict[str, tuple[str, ...]] = {
    "ours": (),
    "seed004": ("steps.1.land_on_rover.strategy=seed004",),
    "ours_uwb_only": ("steps.1.land_on_rover.use_marker=false",),
}
CRITERIA = [Criterion("completed"), Criterion("landing.on_deck")]


def _percentile(values: Sequence[float], q: float) -> float | None:
    v = np.asarray(values, dtype=float)
    if not len(v):
        return None
    p = float(np.percentile(v, q, method="higher"))  # (misses are +inf: never averaged)
    return p if math.isfinite(p) else None


def summarise(result: TrialsResult) -> dict:
    errors = []
    for run in result.runs:
        ok = result.succeeded(run) and run["metrics"].get("landing.error_m") is not None
        errors.append(float(run["metrics"]["landing.error_m"]) if ok else math.inf)
    times = [r["metrics"]["landing.time_to_land_s"] for r in result.runs
             if r["metrics"].get("landing.time_to_land_s") is not None]
    retries = [r["metrics"].get("landing.retries", 0.0) for r in result.runs]
    speeds = [r["metrics"]["landing.relative_horizontal_speed_m_s"] for r in result.runs
              if r["metrics"].get("landing.relative_horizontal_speed_m_s") is not None]
    rel = [r["metrics"]["relative.rms_horizontal_error_m"] for r in result.runs
           if r["metrics"].get("relative.rms_horizontal_error_m") is not None]
    within = [r["metrics"]["relative.within_2sigma"] for r in result.runs
              if r["metrics"].get("relative.within_2sigma") is not None]
    # an estimate's RMS is only what it is over the ticks it had an estimate: shown with these
    lost = [r["metrics"]["relative.lost_share"] for r in result.runs
            if r["metrics"].get("relative.lost_share") is not None]
    worst = int(np.argmax(errors)) if errors else None
    return {
        "trials": len(result.runs),
        "success_rate": result.success_rate,
        "median_error_m": _percentile(errors, 50),
        "p95_error_m": _percentile(errors, 95),
        "worst_error_m": (errors[worst] if worst is not None and math.isfinite(errors[worst])
                          else None),
        "worst_seed": result.runs[worst]["seed"] if worst is not None else None,
        "median_time_to_land_s": _percentile(times, 50),
        "p95_time_to_land_s": _percentile(times, 95),
        "mean_retries": float(np.mean(retries)) if retries else None,
        "median_touchdown_horizontal_speed_m_s": _percentile(speeds, 50),
        "median_relative_rms_error_m": _percentile(rel, 50),
        "median_relative_lost_share": _percentile(lost, 50),
        "median_within_2sigma": _percentile(within, 50),
        "failing_seeds": [r["seed"] for r in result.failing],
        "replay": {str(r["seed"]): result.replay_command(r) for r in result.failing},
        "wall_s": result.wall_s,
    }


def run_bench(trials: int, rover_speed_m_s: float, overrides: Sequence[str] = (),
              log: Callable[[str], None] = lambda _: None, *, workers: int | None = None,
              cluster: str | None = None, strategies: Sequence[str] | None = None,
              seed_start: int = 0, announce: Callable[[str], None] | None = None) -> dict:
    out: dict = {"bench": "landing", "mission": MISSION, "rover_speed_m_s": rover_speed_m_s,
                 "trials": trials,
                 "seeds": [seed_start, seed_start + trials - 1], "overrides": list(overrides)}
    for name in strategies or STRATEGIES:
        log(f"{name}: {trials} trials at {rover_speed_m_s:g} m/s")
        result = run_trials(
            MISSION, trials, seed_start=seed_start,
            overrides=[f"scenario.rover.speed_mps={rover_speed_m_s}", *STRATEGIES[name],
                       *overrides],
            criteria=CRITERIA, workers=workers, cluster=cluster, progress=log,
            announce=announce)
        out[name] = summarise(result)
    return out


def format_table(result: dict) -> str:
    names = [n for n in STRATEGIES if n in result]

    def cell(value, fmt="{:.3f}"):
        return "-" if value is None else fmt.format(value)

    lines = [f"landing on the rover at {result['rover_speed_m_s']:g} m/s, "
             f"{result['trials']} trials (seeds {result['seeds'][0]}..{result['seeds'][1]})",
             f"{'':26s}" + "".join(f"{n:>16s}" for n in names)]
    rows = (("success rate", "success_rate", "{:.0%}"),
            ("median error (m)", "median_error_m", "{:.3f}"),
            ("p95 error (m)", "p95_error_m", "{:.3f}"),
            ("worst error (m)", "worst_error_m", "{:.3f}"),
            ("median time to land (s)", "median_time_to_land_s", "{:.1f}"),
            ("mean retries", "mean_retries", "{:.2f}"),
            ("touchdown h-speed (m/s)", "median_touchdown_horizontal_speed_m_s", "{:.2f}"),
            ("estimate rms (m)", "median_relative_rms_error_m", "{:.3f}"),
            ("estimate lost share", "median_relative_lost_share", "{:.2f}"),
            ("within 2 sigma", "median_within_2sigma", "{:.2f}"))
    for label, key, fmt in rows:
        lines.append(f"{label:26s}" + "".join(f"{cell(result[n].get(key), fmt):>16s}"
                                               for n in names))
    for n in names:
        for seed, command in result[n]["replay"].items():
            lines.append(f"{n} failed seed {seed}: {command}")
    return "\n".join(lines)
