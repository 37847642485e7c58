"""``autopilot trials MISSION``: many seeded lockstep runs of a mission, in parallel, and the
distribution of every metric.

Trial *i* flies the mission with ``scenario.seed = seed_start + i`` (the world's randomness:
sensor noise, gusts, the rover's path, …), the ``--set`` overrides, and each ``--vary`` key
drawn for that seed (``key=LOW:HIGH`` uniformly, ``key=A,B,C`` one of the values): the same
seed gives the same trial wherever it runs. Each run is a whole ``autopilot run`` on the
simulator's lockstep clock (deterministic for its seed), in a worker process.

Where the runs go: local worker processes (``--workers``, default one per core), or an existing
Ray cluster (``--cluster ADDRESS``; ``local`` starts a Ray instance on this machine), one Ray
task per run; the results are gathered and tabulated the same way. On a cluster every node
needs this project installed (``pip install autopilot[cluster]``) and MuJoCo's headless
rendering (``MUJOCO_GL=egl``).

The table: for every numeric metric of the runs (``group.name``), its median, 95th percentile
and worst value with the seed that gave it (worse is larger for errors, times, speeds and
retries; smaller for shares, rates, coverage and counts of what was achieved); for yes/no
metrics, the share that was yes and a seed that said no. A run *fails* when its mission did not
complete or a ``--success`` criterion does not hold (default: completed, and on the deck / pad
for a landing); the failing seeds are listed with the command that replays each.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autopilot.bench import schedule

_HIGHER_IS_BETTER = re.compile(
    r"(coverage|within|on_deck|on_pad|landed|photos|detected|success|availability|rate$|"
    r"updates|frames|ticks|centre_in_frame|images|share_inside|completed)")
_NEUTRAL = re.compile(r"(rover_speed|use_uwb|use_marker|speed_m_s_planned|planned)")


class TrialsError(ValueError):
    """A bad ``--vary`` or ``--success``, or no runs."""


@dataclass(frozen=True, slots=True)
class Vary:
    key: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()

    def value(self, seed: int, index: int) -> str:
        rng = np.random.default_rng((seed, 7727, index))
        if self.choices:
            return self.choices[int(rng.integers(len(self.choices)))]
        return f"{float(rng.uniform(self.low, self.high)):.6g}"


def parse_vary(text: str) -> Vary:
    """``key=LOW:HIGH`` (uniform) or ``key=A,B,C`` (one of them)."""
    key, sep, spec = text.partition("=")
    if not sep or not key.strip() or not spec.strip():
        raise TrialsError(f"--vary {text!r}: expected KEY=LOW:HIGH or KEY=A,B,C")
    if ":" in spec and "," not in spec:
        low, _, high = spec.partition(":")
        try:
            lo, hi = float(low), float(high)
        except ValueError:
            raise TrialsError(f"--vary {text!r}: LOW and HIGH must be numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
            raise TrialsError(f"--vary {text!r}: need finite LOW <= HIGH")
        return Vary(key.strip(), lo, hi)
    choices = tuple(c.strip() for c in spec.split(",") if c.strip())
    if not choices:
        raise TrialsError(f"--vary {text!r}: no values")
    return Vary(key.strip(), choices=choices)


@dataclass(frozen=True, slots=True)
class Criterion:
    """``group.metric`` (truthy), or ``group.metric OP NUMBER`` (OP: < <= > >= ==)."""

    key: str
    op: str = ""
    value: float = 0.0

    def holds(self, metrics: dict) -> bool:
        if self.key in ("completed", "status"):
            return metrics.get("status") == "completed"
        v = metrics.get(self.key)
        if v is None:
            return False
        if not self.op:
            return bool(v)
        v = float(v)
        return {"<": v < self.value, "<=": v <= self.value, ">": v > self.value,
                ">=": v >= self.value, "==": v == self.value}[self.op]

    def __str__(self) -> str:
        return f"{self.key}{self.op}{self.value:g}" if self.op else self.key


def parse_criterion(text: str) -> Criterion:
    m = re.fullmatch(r"\s*([\w.]+)\s*(<=|>=|==|<|>)?\s*([-+0-9.eE]+)?\s*", text)
    if m is None or (m.group(2) is None) != (m.group(3) is None):
        raise TrialsError(f"--success {text!r}: expected KEY or KEY<=NUMBER (< <= > >= ==)")
    return Criterion(m.group(1), m.group(2) or "", float(m.group(3)) if m.group(3) else 0.0)


def flatten(metrics: dict, prefix: str = "") -> dict[str, float | bool]:
    """Numeric and yes/no metrics by dotted name (lists and texts left out)."""
    out: dict[str, float | bool] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            if key == "steps":
                continue
            out.update(flatten(value, name + "."))
        elif isinstance(value, bool):
            out[name] = value
        elif isinstance(value, int | float) and value is not None and math.isfinite(value):
            out[name] = float(value)
    return out


def trial_overrides(overrides: Sequence[str], varies: Sequence[Vary],
                    seed: int) -> tuple[list[str], dict[str, str]]:
    values = {v.key: v.value(seed, i) for i, v in enumerate(varies)}
    return ([f"scenario.seed={seed}", *overrides, *(f"{k}={v}" for k, v in values.items())],
            values)


def run_trial(mission: str, overrides: Sequence[str], seed: int,
              out_dir: str | None = None) -> dict:
    """One run (in a worker process): its status, metrics (flattened), and wall time."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import shutil
    import tempfile

    from autopilot.mission import load_mission
    from autopilot.run import fly

    started = time.perf_counter()
    # a run always writes its log, as `autopilot run` does (the frame log's encoding takes
    # its turn on the lockstep clock): the replay command then flies exactly this run
    where = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix=f"trial{seed}-"))
    try:
        plan = load_mission(mission, list(overrides))
        summary = asyncio.run(fly(plan, where))
    except Exception as exc:  # a run that could not fly is a result too, not a crash
        return {"seed": seed, "status": "error", "reason": f"{type(exc).__name__}: {exc}",
                "metrics": {}, "wall_s": time.perf_counter() - started, "sim_s": 0.0}
    finally:
        if not out_dir:
            shutil.rmtree(where, ignore_errors=True)
    return {"seed": seed, "status": summary.get("status"), "reason": summary.get("reason", ""),
            "metrics": flatten({k: v for k, v in summary.get("metrics", {}).items()
                                if k not in ("sim", "latency_ms")}),
            "wall_s": time.perf_counter() - started,
            "sim_s": float(summary.get("sim_time_s") or 0.0)}


@dataclass
class TrialsResult:
    mission: str
    overrides: list[str]
    varies: list[Vary]
    criteria: list[Criterion]
    runs: list[dict] = field(default_factory=list)
    backend: str = "local"
    workers: int = 1
    wall_s: float = 0.0

    def succeeded(self, run: dict) -> bool:
        data = {**run["metrics"], "status": run["status"]}
        return all(c.holds(data) for c in self.criteria)

    @property
    def failing(self) -> list[dict]:
        return [r for r in self.runs if not self.succeeded(r)]

    @property
    def success_rate(self) -> float:
        return 1.0 - len(self.failing) / len(self.runs) if self.runs else 0.0

    def replay_command(self, run: dict) -> str:
        words = ["autopilot", "run", "--mission", self.mission]
        for item in run["overrides"]:
            words += ["--set", item]
        return " ".join(shlex.quote(w) for w in words)

    def distribution(self) -> dict[str, dict]:
        names = sorted({k for r in self.runs for k in r["metrics"]})
        out = {}
        for name in names:
            rows = [(r["seed"], r["metrics"][name]) for r in self.runs if name in r["metrics"]]
            if all(isinstance(v, bool) for _, v in rows):
                no = [s for s, v in rows if not v]
                out[name] = {"n": len(rows), "kind": "yes/no",
                             "share_yes": sum(bool(v) for _, v in rows) / len(rows),
                             "worst": not no,
                             "worst_seed": no[0] if no else None}
                continue
            values = np.array([float(v) for _, v in rows])
            seeds = [s for s, _ in rows]
            better_high = bool(_HIGHER_IS_BETTER.search(name))
            neutral = bool(_NEUTRAL.search(name))
            k = int(np.argmin(values) if better_high else np.argmax(values))
            out[name] = {"n": len(rows), "kind": "number",
                         "median": float(np.median(values)),
                         "p95": float(np.percentile(values, 5 if better_high else 95)),
                         "worst": None if neutral else float(values[k]),
                         "worst_seed": None if neutral else seeds[k],
                         "mean": float(np.mean(values))}
        return out

    def to_json(self) -> dict:
        return {"mission": self.mission, "trials": len(self.runs), "backend": self.backend,
                "workers": self.workers, "overrides": self.overrides,
                "vary": [v.key for v in self.varies],
                "success": [str(c) for c in self.criteria],
                "success_rate": self.success_rate,
                "failing_seeds": [r["seed"] for r in self.failing],
                "replay": {str(r["seed"]): self.replay_command(r) for r in self.failing},
                "metrics": self.distribution(),
                "runs": [{k: v for k, v in r.items()} for r in self.runs],
                "wall_s": self.wall_s}

    def table(self) -> str:
        lines = [f"{self.mission}: {len(self.runs)} trials ({self.backend}, "
                 f"{self.workers} workers), success {100 * self.success_rate:.0f} % "
                 f"[{', '.join(str(c) for c in self.criteria)}]",
                 f"{'metric':44s} {'median':>10s} {'p95':>10s} {'worst':>10s} {'seed':>6s}"]
        for name, d in self.distribution().items():
            if d["kind"] == "yes/no":
                lines.append(f"{name:44s} {100 * d['share_yes']:9.0f}% {'':>10s} "
                             f"{'no' if d['worst_seed'] is not None else 'yes':>10s} "
                             f"{d['worst_seed'] if d['worst_seed'] is not None else '':>6}")
            else:
                worst = "" if d["worst"] is None else f"{d['worst']:10.4g}"
                seed = "" if d["worst_seed"] is None else d["worst_seed"]
                lines.append(f"{name:44s} {d['median']:10.4g} {d['p95']:10.4g} {worst:>10s} "
                             f"{seed:>6}")
        if self.failing:
            lines.append("failing seeds (replay each with the command shown):")
            for r in self.failing:
                why = r["reason"] or ", ".join(
                    str(c) for c in self.criteria
                    if not c.holds({**r["metrics"], "status": r["status"]}))
                lines.append(f"  seed {r['seed']}: {r['status']}: {why}")
                lines.append(f"    {self.replay_command(r)}")
        else:
            lines.append("no failing seeds")
        return "\n".join(lines)


def default_criteria(runs: Sequence[dict]) -> list[Criterion]:
    criteria = [Criterion("completed")]
    keys = {k for r in runs for k in r["metrics"]}
    for key in ("landing.on_deck", "landing.on_pad"):
        if key in keys:
            criteria.append(Criterion(key))
    return criteria


def run_trials(mission: str, trials: int, *, seed_start: int = 0,
               overrides: Sequence[str] = (), varies: Sequence[Vary] = (),
               criteria: Sequence[Criterion] | None = None, workers: int | None = None,
               cluster: str | None = None, out_dir: Path | None = None,
               progress: Callable[[str], None] | None = None,
               announce: Callable[[str], None] | None = None) -> TrialsResult:
    """Fly ``trials`` seeded runs and gather them (see the module's notes); how long the local
    runs will take goes to ``announce`` (default ``progress``) before they start."""
    if trials < 1:
        raise TrialsError("--trials must be at least 1")
    from autopilot.mission import load_mission

    # a mission file travels as an absolute path (a worker's directory may differ)
    if Path(mission).is_file():
        mission = str(Path(mission).resolve())
    if out_dir is not None:
        out_dir = Path(out_dir).resolve()
    # nothing flies on an invalid mission: check it (and every varied value) here first
    jobs, profiles = [], []
    for i in range(trials):
        seed = seed_start + i
        items, values = trial_overrides(overrides, varies, seed)
        profiles.append(load_mission(mission, items).config.sim.profile)
        jobs.append((seed, items, values))
    workers = schedule.workers_for(workers, trials)
    result = TrialsResult(mission, list(overrides), list(varies), list(criteria or []),
                          backend="ray" if cluster else "local", workers=workers)
    started = time.perf_counter()
    if cluster:
        done = _run_ray(jobs, mission, workers, cluster, out_dir)
    else:
        done = _run_local(jobs, mission, workers, out_dir, profiles, progress,
                          announce or progress)
    for job, run in done:
        seed, items, values = job
        run.update(overrides=items, values=values)
        result.runs.append(run)
        if progress is not None and cluster:
            progress(f"trial seed {seed}: {run['status']} ({len(result.runs)}/{trials}, "
                     f"{run['wall_s']:.1f} s)")
    result.runs.sort(key=lambda r: r["seed"])
    if not result.criteria:
        result.criteria = default_criteria(result.runs)
    result.wall_s = time.perf_counter() - started
    return result


def _out(out_dir: Path | None, seed: int) -> str | None:
    return str(out_dir / f"seed{seed}") if out_dir is not None else None


def _run_local(jobs, mission, workers, out_dir, profiles, progress, announce):
    """The runs on local worker processes (:mod:`autopilot.bench.schedule`: how long they
    will take is said before they start, the time left after each)."""
    say = progress or (lambda _: None)
    kinds = [schedule.kind_of(mission, p, "trial", workers) for p in profiles]
    runs = [(mission, items, seed, _out(out_dir, seed)) for seed, items, _ in jobs]

    def describe(i: int, run: dict) -> str:
        return f"trial seed {jobs[i][0]}: {run['status']} ({run['wall_s']:.1f} s)"

    for i, run in schedule.run_all(runs, kinds, workers, run_trial, announce=announce or say,
                                   log=say, describe=describe):
        yield jobs[i], run


def _run_ray(jobs, mission, workers, cluster, out_dir):
    try:
        import ray
    except ImportError:
        raise TrialsError("--cluster needs Ray: pip install 'autopilot[cluster]'") from None
    started_here = not ray.is_initialized()
    if started_here:
        address = None if cluster == "local" else cluster
        # a local instance listens on loopback only (Ray's own token authentication on top)
        ray.init(address=address, include_dashboard=False, log_to_driver=False,
                 configure_logging=False,
                 **({"num_cpus": workers, "_node_ip_address": "127.0.0.1"}
                    if address is None else {}),
                 runtime_env={"env_vars": {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}})
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        refs = {remote.remote(mission, items, seed, _out(out_dir, seed)): (seed, items, values)
                for seed, items, values in jobs}
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            for ref in done:
                yield refs.pop(ref), ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()


def print_result(result: TrialsResult, as_json: bool) -> None:
    if as_json:
        print(json.dumps(result.to_json(), indent=1, default=float))
    else:
        print(result.table())
