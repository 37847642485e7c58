"""Pooling one bench's results flown as separate processes (its rows, controllers, scenarios or
seeds apart): shared by the benches' ``merge`` functions."""

from __future__ import annotations

from collections.abc import Sequence


def pool_runs(results: Sequence[dict]) -> dict[str, dict]:
    """Scenario → ``{"overrides", "runs": {row: [run, ...]}}`` with every result's runs of that
    scenario and row together. Results of different benches, variants or overrides are never
    pooled (ValueError)."""
    first = results[0]
    for r in results[1:]:
        for key in ("bench", "quick", "overrides"):
            if r.get(key) != first.get(key):
                raise ValueError(f"cannot merge {first['bench']} results with different {key}")
    pooled: dict[str, dict] = {}
    for r in results:
        for scenario, data in r["scenarios"].items():
            into = pooled.setdefault(scenario, {"overrides": data["overrides"], "runs": {}})
            for row, runs in data["runs"].items():
                into["runs"].setdefault(row, []).extend(runs)
    return pooled
