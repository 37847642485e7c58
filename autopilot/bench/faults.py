"""``autopilot bench faults``: every shipped mission × every fault that applies to it, several
seeds each, through :mod:`autopilot.trials` (lockstep, seeded, replayable).

Each run ends in one of three outcomes (:func:`autopilot.flightlog.safety.outcome`, judged on
the simulator's ground truth):

* **completed** — the mission completed, and the vehicle ended safe;
* **safe** — the mission did not complete (aborted, fell back, failed) but the vehicle ended
  disarmed, on the ground, or held/landing/returning by itself, without a crash or breach;
* **unsafe** — a crash (tilt or impact), a flyaway, a breach of the fence the bench flies with
  (``failsafe.geofence``: :data:`FENCE`), the vehicle left flying under the autopilot, or a
  run that raised (a traceback).

Faults start a few seconds into each mission's main step (the first step after take-off), so
they hit the part that matters: ``start_s`` is seconds after the arming (see
drivers/sim/faults.py). The table lists, per cell, the counts and the completed share, and the
worst seeds (unsafe first, then safe) with the command that replays each.
"""

from __future__ import annotations

import json
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from autopilot.bench import schedule
from autopilot.flightlog.safety import outcome
from autopilot.trials import run_trial, trial_overrides

#: the fence every bench run flies with (the autopilot's own failsafe, judged on the truth)
FENCE = ("failsafe.geofence.max_distance_m=80", "failsafe.geofence.max_altitude_m=30")
#: mission → (when its main step is well under way, s after arming; the cameras its steps
#: use; overrides that keep it short: a follow or hover step lasts 20 s past the fault's start)
MISSIONS: dict[str, tuple[float, tuple[str, ...], tuple[str, ...]]] = {
    "follow_ball": (10.0, ("front",), ("steps.1.follow_ball.duration_s=26",)),
    "follow_marker": (10.0, ("front",), ("steps.1.follow_marker.duration_s=26",)),
    "hover_image": (10.0, ("down",), ("steps.1.hover_image.duration_s=26",)),
    "land_pad": (6.0, ("down",), ()),
    "land_on_rover": (7.0, ("down",), ()),
    "orbit": (7.0, ("down",), ()),
    "survey": (10.0, ("down",), ()),
}


@dataclass(frozen=True, slots=True)
class FaultCase:
    name: str  # the cell's column: the kind, with a variant after a slash
    kind: str
    params: tuple[tuple[str, object], ...]
    #: which missions it applies to (None: all); a camera fault applies to missions using it
    missions: tuple[str, ...] | None = None

    def fault(self, start_s: float, camera: str | None) -> dict:
        out = {"kind": self.kind, "start_s": start_s, **dict(self.params)}
        if self.kind.startswith("camera_") and camera is not None:
            out["camera"] = camera
        return out


CASES: tuple[FaultCase, ...] = (
    FaultCase("camera_dropout", "camera_dropout", (("duration_s", 3.0),)),
    FaultCase("camera_freeze", "camera_freeze", (("duration_s", 3.0),)),
    FaultCase("camera_corrupt/noise", "camera_corrupt", (("duration_s", 3.0), ("mode", "noise"))),
    FaultCase("camera_corrupt/black", "camera_corrupt", (("duration_s", 2.0), ("mode", "black"))),
    FaultCase("camera_corrupt/exposure", "camera_corrupt",
              (("duration_s", 3.0), ("mode", "exposure"), ("gain", 3.0))),
    FaultCase("telemetry_dropout", "telemetry_dropout", (("duration_s", 2.0),)),
    FaultCase("telemetry_delay", "telemetry_delay", (("duration_s", 5.0), ("delay_s", 0.3))),
    FaultCase("link_loss", "link_loss", (("duration_s", 15.0), ("fraction", 0.3))),
    FaultCase("ekf_glitch", "ekf_glitch", (("duration_s", 5.0), ("magnitude_m", 3.0),
                                           ("direction_deg", 45.0))),
    FaultCase("gps_loss", "gps_loss", (("duration_s", 20.0),)),
    FaultCase("rangefinder_dropout", "rangefinder_dropout", (("duration_s", 10.0),)),
    FaultCase("motor_failure", "motor_failure", (("efficiency", 0.7), ("motor", 1))),
    FaultCase("battery_sag/low", "battery_sag", (("remaining_fraction", 0.12),)),
    FaultCase("battery_sag/critical", "battery_sag", (("remaining_fraction", 0.06),)),
    FaultCase("wind_step", "wind_step", (("duration_s", 10.0), ("speed_m_s", 8.0),
                                         ("direction_deg", 90.0))),
    FaultCase("wind_step/gusts", "wind_step", (("duration_s", 10.0), ("speed_m_s", 6.0),
                                               ("gust_mps", 4.0), ("direction_deg", 200.0))),
    FaultCase("rover_stop/stop", "rover_stop", (("duration_s", 4.0), ("mode", "stop")),
              ("land_on_rover",)),
    FaultCase("rover_stop/reverse", "rover_stop", (("duration_s", 3.0), ("mode", "reverse")),
              ("land_on_rover",)),
    FaultCase("decoy_crossing", "decoy_crossing", (("duration_s", 6.0),), ("follow_ball",)),
)


def cells(missions: Sequence[str] | None = None, kinds: Sequence[str] | None = None
          ) -> list[tuple[str, FaultCase, dict]]:
    """(mission, case, fault) for every cell that applies."""
    out = []
    for mission, (start_s, cameras, _) in MISSIONS.items():
        if missions and mission not in missions:
            continue
        for case in CASES:
            if kinds and case.kind not in kinds and case.name not in kinds:
                continue
            if case.missions is not None and mission not in case.missions:
                continue
            out.append((mission, case, case.fault(start_s, cameras[0] if cameras else None)))
    return out


def run_bench(seeds: int = 2, missions: Sequence[str] | None = None,
              kinds: Sequence[str] | None = None, overrides: Sequence[str] = (),
              progress: Callable[[str], None] | None = None, workers: int | None = None,
              seed_start: int = 0, announce: Callable[[str], None] | None = None) -> dict:
    """Every (cell, seed) run is one :func:`autopilot.trials.run_trial` (a whole lockstep
    ``autopilot run`` in a worker process), all in one pool so that both cores stay busy
    (:mod:`autopilot.bench.schedule`: how long they will take goes to ``announce``, default
    ``progress``, before the first starts)."""
    from autopilot.mission import load_mission

    plan = cells(missions, kinds)
    jobs, profiles = [], []
    for index, (mission, _case, fault) in enumerate(plan):
        items = [*FENCE, *MISSIONS[mission][2], *overrides,
                 "scenario.faults=" + json.dumps([fault], separators=(",", ":"))]
        for seed in range(seed_start, seed_start + seeds):
            seeded, _ = trial_overrides(items, (), seed)
            # nothing flies on an invalid mission
            profiles.append(load_mission(mission, seeded).config.sim.profile)
            jobs.append((index, mission, seed, seeded))
    started = time.perf_counter()
    results: dict[int, list[dict]] = {i: [] for i in range(len(plan))}
    workers = schedule.workers_for(workers, len(jobs))
    say = progress or (lambda _: None)
    kinds = [schedule.kind_of(mission, profile, "bench faults", workers)
             for (_, mission, _, _), profile in zip(jobs, profiles, strict=True)]

    def died(i: int, exc: BaseException) -> dict:  # a worker that died (a crash, memory)
        return {"seed": jobs[i][2], "status": "error", "metrics": {},
                "reason": f"{type(exc).__name__}: {exc}"}

    def describe(i: int, run: dict) -> str:
        index = jobs[i][0]
        mission, case, _ = plan[index]
        if len(results[index]) < seeds:
            return f"{mission} × {case.name}, seed {jobs[i][2]}: {run['status']}"
        kinds_ = [outcome(r["status"], r["metrics"])[0] for r in results[index]]
        return (f"{mission} × {case.name}: {kinds_.count('completed')} completed, "
                f"{kinds_.count('safe')} safe, {kinds_.count('unsafe')} unsafe")

    runs = [(mission, seeded, seed) for _, mission, seed, seeded in jobs]
    for i, run in schedule.run_all(runs, kinds, workers, run_trial, announce=announce or say,
                                   log=say, describe=describe, on_error=died):
        run["overrides"] = jobs[i][3]
        results[jobs[i][0]].append(run)
    rows = []
    for index, (mission, case, fault) in enumerate(plan):
        counts = {"completed": 0, "safe": 0, "unsafe": 0}
        worst = []
        for run in sorted(results[index], key=lambda r: r["seed"]):
            kind, why = outcome(run["status"], run["metrics"])
            counts[kind] += 1
            if kind != "completed":
                worst.append({"seed": run["seed"], "outcome": kind,
                              "why": why or run.get("reason", ""),
                              "reason": run.get("reason", ""),
                              "replay": replay_command(mission, run["overrides"])})
        worst.sort(key=lambda w: (w["outcome"] != "unsafe", w["seed"]))
        n = len(results[index])
        rows.append({"mission": mission, "fault": case.name, **counts, "runs": n,
                     "completed_share": counts["completed"] / max(n, 1),
                     "worst": worst[:3], "fault_spec": fault})
    total = {k: sum(r[k] for r in rows) for k in ("completed", "safe", "unsafe", "runs")}
    return {"seeds": seeds, "seed_start": seed_start, "fence": list(FENCE), "cells": rows,
            "total": total, "wall_s": round(time.perf_counter() - started, 1),
            "workers": workers}


def replay_command(mission: str, overrides: Sequence[str]) -> str:
    words = ["autopilot", "run", "--mission", mission]
    for item in overrides:
        words += ["--set", item]
    return " ".join(shlex.quote(w) for w in words)


def format_table(result: dict) -> str:
    rows = result["cells"]
    missions = list(dict.fromkeys(r["mission"] for r in rows))
    faults = list(dict.fromkeys(r["fault"] for r in rows))
    by = {(r["mission"], r["fault"]): r for r in rows}
    width = max([len(f) for f in faults] + [10])
    lines = [f"fault injection: {len(rows)} cells × {result['seeds']} seeds; each cell "
             "completed/safe/unsafe (completed share)", "",
             " " * width + "  " + "  ".join(f"{m[:13]:>13}" for m in missions)]
    for fault in faults:
        cells_text = []
        for m in missions:
            r = by.get((m, fault))
            cells_text.append(f"{'—':>13}" if r is None else
                              f"{r['completed']}/{r['safe']}/{r['unsafe']} "
                              f"({100 * r['completed_share']:.0f}%)".rjust(13))
        lines.append(f"{fault:<{width}}  " + "  ".join(cells_text))
    t = result["total"]
    lines += ["", f"total: {t['runs']} runs: {t['completed']} completed, {t['safe']} ended "
              f"safe, {t['unsafe']} unsafe"]
    worst = [(r, w) for r in rows for w in r["worst"]]
    worst.sort(key=lambda rw: rw[1]["outcome"] != "unsafe")
    if worst:
        lines += ["", "worst seeds (replay each with its command):"]
        for r, w in worst[:12]:
            lines.append(f"  {w['outcome']:>6}  {r['mission']} × {r['fault']} seed "
                         f"{w['seed']}: {w['why']}")
            lines.append(f"          {w['replay']}")
    return "\n".join(lines)
