"""A flight's metrics, chosen per step by the registry.

Each step of the logged plan that has a registered ``metrics`` function is scored over the
intervals it ran in. The summary keeps every scored step under ``steps`` and, at the top, the
first step's group of each name (``follow``, ``estimation``, …): ``metrics.follow`` means the
same for any followed target.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import (
    estimation_metrics,
    follow_metrics,
    step_intervals,
)
from autopilot.steps.registry import STEP_KINDS

Records = Mapping[str, Sequence[Mapping]]


def log_end_s(records: Records) -> float:
    ends = [r["time_s"] for topic in (ch.GROUND_TRUTH, ch.VEHICLE_STATE)
            for r in records.get(topic, [])[-1:]]
    return max([*ends, 0.0])


def plan_steps(records: Records) -> list[Mapping]:
    """The logged plan's step records (``name``, ``index``, ``params``, ``pipelines``, …),
    then the goals' (the goal API's)."""
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    steps = [s for s in plan.get("steps", []) if isinstance(s, Mapping) and "name" in s]
    # goals run through the goal API come after the mission's own steps
    return steps + [g for g in records.get(ch.MISSION_GOALS, [])
                    if isinstance(g, Mapping) and "name" in g]


def steps_metrics(records: Records) -> list[dict]:
    """Each scored step: {"index", "name", "intervals", groups…}."""
    events = records.get(ch.MISSION_EVENTS, [])
    end = log_end_s(records)
    scored = []
    for step in plan_steps(records):
        kind = STEP_KINDS.get(step["name"])
        if kind is None or kind.metrics is None:
            continue
        intervals = step_intervals(events, end, step_index=step["index"])
        groups = kind.metrics(records, intervals, step) if intervals else {}
        scored.append({"index": step["index"], "name": step["name"],
                       "intervals": [list(i) for i in intervals], **groups})
    return scored


def mission_metrics(records: Records) -> dict:
    """The summary's metric groups: the first scored step's at the top, all under ``steps``.
    (A log from before per-step plan records is scored as its one follow_ball step.)"""
    if not plan_steps(records):
        legacy = {"follow": follow_metrics(records), "estimation": estimation_metrics(records)}
        return {k: v for k, v in legacy.items() if v}
    scored = steps_metrics(records)
    top: dict = {}
    for step in scored:
        for name, group in step.items():
            if isinstance(group, dict) and name not in top:
                top[name] = group
    if scored:
        top["steps"] = scored
    return top
