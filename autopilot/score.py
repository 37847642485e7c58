"""``autopilot score RUN_DIR --truth TRUTH``: score a flight flown through a MAVLink driver
against the ground truth that ``autopilot sim --out DIR`` recorded.

The autopilot never sees ground truth; the simulator never sees detections. This joins the
two logs after the fact: the run's log holds its detections and setpoints on its own clock,
and the time mapping its driver measured (TIMESYNC: local − vehicle boot time, logged every
second); the simulator's log holds ground truth on the vehicle's boot clock, and its cameras
as they really are (detections are scored against where the target truly appeared in them).
Truth is shifted onto the run's clock by the mapping of its time (interpolated: a lagging
clock moves it), and the run's metrics (each step's, as the registry picks them) are computed
as for an in-process run.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from autopilot.config import InputError
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.steps.metrics import mission_metrics


class ScoreError(InputError):
    pass


def score(run_dir: Path, truth_path: Path) -> dict:
    """The metric groups of the run in ``run_dir`` (``follow``, ``estimation``, …, and
    ``steps``); also written into its ``summary.json``."""
    log_path = run_dir / "flight.mcap"
    for path in (log_path, truth_path):
        if not path.is_file():
            raise ScoreError(f"{path}: no such file")
    records = read_log(log_path)
    syncs = [r for r in records.get(ch.TIME_SYNC, [])
             if r.get("vehicle_to_local_s") is not None
             and math.isfinite(r["vehicle_to_local_s"])]
    if not syncs:
        raise ScoreError(f"{log_path}: no time mapping to the vehicle's clock (channel "
                         f"{ch.TIME_SYNC}); was it flown through a MAVLink driver?")
    recorded = read_log(truth_path)
    truth = recorded.get(ch.GROUND_TRUTH, [])
    if not truth:
        raise ScoreError(f"{truth_path}: no ground truth (channel {ch.GROUND_TRUTH})")
    # the mapping as it was when each truth sample was taken (it moves when the vehicle's
    # clock drifts, or lags as a starved simulator's does); held beyond the first and last
    syncs.sort(key=lambda r: r["time_s"])
    offsets = np.array([r["vehicle_to_local_s"] for r in syncs])
    vehicle_s = np.array([r["time_s"] for r in syncs]) - offsets
    order = np.argsort(vehicle_s, kind="stable")
    shifted = np.interp([r["time_s"] for r in truth], vehicle_s[order], offsets[order])
    records[ch.GROUND_TRUTH] = [{**r, "time_s": r["time_s"] + float(off)}
                                for r, off in zip(truth, shifted, strict=True)]
    if recorded.get(ch.CAMERA_TRUTH):  # (a recording from before these were kept has none)
        records[ch.CAMERA_TRUTH] = recorded[ch.CAMERA_TRUTH]
    metrics = ch.clean(mission_metrics(records))
    summary_path = run_dir / "summary.json"
    if summary_path.is_file():
        summary = json.loads(summary_path.read_text())
        summary.setdefault("metrics", {}).update(metrics)
        summary["scored_against"] = str(truth_path)
        summary_path.write_text(json.dumps(summary, indent=2) + "\n")
    return metrics
