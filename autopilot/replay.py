"""``autopilot replay DIR``: a logged flight's frames and telemetry through perception and
estimation again, with the flight's configuration or a changed one.

The flight cannot change (the vehicle flew where it flew), so what a replay can tell is how the
detector and the filter would have seen *that* flight: the detection metrics and the estimate
errors (against the simulator's ground truth, when the log has it).

It rebuilds every perception pipeline the flight's steps used (from the plan record: kind,
camera; settings from the — possibly changed — configuration) and drives each in the order the
runtime did: telemetry is added as it arrived (its logged arrival time), the detector's search
hint is taken when the frame arrived, the estimate after the detection finished, and the target
is taken at each logged control tick as the behaviour would have seen it. The frames are the
logged JPEGs, not the camera's raw images, so detections can differ by a fraction of a pixel;
without overrides the detection figures come out the same and the estimate errors within a
percent (``tests/integration/test_replay.py``). Metrics are chosen per step by the registry, as
for the flight.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from autopilot.config import (
    AppConfig,
    ConfigError,
    InputError,
    Located,
    Problem,
    apply_overrides,
    load_yaml,
    validate,
)
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_images, read_log_checked
from autopilot.pipeline import KeepsRecords, Pipeline, PipelineSpec, SensorFed, make_pipeline
from autopilot.resources import default_config_path
from autopilot.steps import STEP_KINDS
from autopilot.steps.metrics import mission_metrics, plan_steps


class ReplayError(InputError):
    pass


def _with_defaults(defaults, logged):
    """``logged`` with every key it lacks taken from ``defaults`` (recursively)."""
    if not isinstance(defaults, dict) or not isinstance(logged, dict):
        return logged
    return {**defaults, **{k: _with_defaults(defaults.get(k), v) for k, v in logged.items()}}


def replay(run_dir: Path, overrides: Sequence[str] = ()) -> dict:
    """Replay ``run_dir/flight.mcap``; a summary shaped like ``summary.json``."""
    path = run_dir / "flight.mcap"
    if not path.is_file():
        raise ReplayError(f"{path}: no such file (a run folder holds flight.mcap)")
    records, complete = read_log_checked(path)
    plan = (records.get(ch.MISSION_PLAN) or [None])[0]
    if plan is None or not isinstance(plan.get("config"), dict) or not plan_steps(records):
        raise ReplayError(f"{path}: the log has no {ch.MISSION_PLAN} record with the flight's "
                          "configuration and steps (written by an older autopilot?)")
    source = f"{path} (the flight's configuration)"
    logged = dict(plan["config"])
    sim = logged.get("sim")
    if isinstance(sim, dict) and sim.get("cameras"):
        # the simulator's cameras are vehicle.cameras: a log from before they moved there
        # kept them under sim (and a log never needs both)
        sim = dict(sim)
        cameras = sim.pop("cameras")
        logged["sim"] = sim
        if not (logged.get("vehicle") or {}).get("cameras"):
            logged["vehicle"] = {**(logged.get("vehicle") or {}), "cameras": cameras}
    # settings the flight's autopilot did not have yet take today's defaults
    logged = _with_defaults(load_yaml(default_config_path()).data, logged)
    cfg: AppConfig = validate(AppConfig, apply_overrides(Located(logged, source, {}),
                                                         overrides))
    specs = _flown_pipelines(records, cfg)
    if not specs:
        raise ReplayError(f"{path}: no step of this flight used a perception pipeline")
    replayed = dict(records)
    estimates, ticks, relative = [], [], []
    frames_replayed = frames_flown = 0
    for spec in specs.values():
        result = _replay_pipeline(path, records, make_pipeline(cfg, spec), spec)
        replayed[ch.detection_topic(spec.key)] = result.detections
        estimates += result.estimates
        ticks += result.ticks
        relative += result.relative
        frames_replayed += len(result.detections)
        frames_flown += result.flown
    if not frames_replayed and not relative:
        cameras = ", ".join(sorted({s.camera for s in specs.values()}))
        raise ReplayError(f"{path}: no logged camera frames of {cameras} to replay "
                          "(frames are logged by default in the simulator; on a vehicle set "
                          "log.frames.vehicle_rate_hz)")
    replayed[ch.TARGET_ESTIMATES] = sorted(estimates, key=lambda r: r["time_s"])
    replayed[ch.CONTROL_TARGET] = sorted(ticks, key=lambda r: r["time_s"])
    if relative or ch.RELATIVE_ESTIMATES in records:
        replayed[ch.RELATIVE_ESTIMATES] = sorted(relative, key=lambda r: r["time_s"])
    # the flight's own figures over the same frames (equal to summary.json's when every
    # frame was logged)
    as_flown = dict(records)
    for key in specs:
        done = {ch.time_key(r["time_s"]) for r in replayed[ch.detection_topic(key)]}
        as_flown[ch.detection_topic(key)] = [
            r for r in records.get(ch.detection_topic(key), []) if ch.time_key(r["time_s"]) in done]
    now, then = mission_metrics(replayed), mission_metrics(as_flown)
    return {
        "status": "replayed",
        "mission": plan.get("mission"),
        "source": str(run_dir),
        "overrides": list(overrides),
        "log_complete": complete,
        "frames": {"replayed": frames_replayed, "in_flight": frames_flown},
        "metrics": _replay_groups(now),
        "flight_metrics": _replay_groups(then),
    }


def _replay_groups(metrics: dict) -> dict:
    """The groups a replay can tell about: what each step kind's replay recomputes (its
    detection figures, its filter's; :attr:`~autopilot.steps.registry.StepKind.replay`),
    then the estimation."""
    groups: dict = {}
    for kind in STEP_KINDS.values():
        for group, keys in kind.replay.items():
            found = metrics.get(group)
            if group in groups or not found:
                continue
            groups[group] = dict(found) if keys is None else {k: found.get(k) for k in keys}
    groups["estimation"] = metrics.get("estimation") or {}
    return groups


def _flown_pipelines(records, cfg: AppConfig) -> dict[str, PipelineSpec]:
    """The pipelines the flight's steps used, as logged; a configuration change that would
    move one to another camera is refused (the frames are the flight's)."""
    specs: dict[str, PipelineSpec] = {}
    for step in plan_steps(records):
        for p in step.get("pipelines") or []:
            spec = PipelineSpec(p["kind"], p["camera"], p.get("truth_body", ""),
                                p.get("size_m") or 0.0, p["name"], p.get("target") or "")
            specs.setdefault(spec.key, spec)
        kind = STEP_KINDS.get(step["name"])
        if kind is None:
            continue
        try:
            params = kind.params.model_validate(step.get("params") or {})
        except ValueError:
            continue
        for now in kind.pipelines(params, cfg):
            flown = specs.get(now.key)
            if flown is not None and flown.camera != now.camera:
                raise ConfigError([Problem("--set", None, f"{now.kind} camera",
                                           f"a replay uses the flight's camera "
                                           f"({flown.camera!r}), not {now.camera!r}")])
    return specs


class _Replayed:
    def __init__(self) -> None:
        self.detections: list[dict] = []
        self.estimates: list[dict] = []
        self.ticks: list[dict] = []
        self.relative: list[dict] = []
        self.flown = 0


def _replay_pipeline(path: Path, records, pipeline: Pipeline, spec: PipelineSpec) -> _Replayed:
    out = _Replayed()
    info = next((c for c in records.get(ch.CAMERA_INFO, []) if c["name"] == spec.camera), None)
    if info is None and spec.camera:
        raise ReplayError(f"{path}: no {ch.CAMERA_INFO} record for camera {spec.camera!r}")
    camera = ch.camera_info_from_record(info) if info is not None else None
    flown_rows = records.get(ch.detection_topic(spec.key), [])
    out.flown = len(flown_rows)
    flown = {ch.time_key(r["time_s"]): r for r in flown_rows}
    # telemetry, and the extra sensor streams (ch.SENSOR_RECORDS) for a pipeline that takes
    # them, merged in arrival order
    inputs = [(s.get("received_s", s["time_s"]), 0, ch.vehicle_state_from_record(s))
              for s in records.get(ch.VEHICLE_STATE, [])]
    if isinstance(pipeline, SensorFed):
        for stream, from_record in ch.SENSOR_RECORDS.items():
            inputs += [(r.get("received_s", r["time_s"]), 1, from_record(r))
                       for r in records.get(ch.sensor_topic(stream), [])]
        inputs.sort(key=lambda item: (item[0], item[1]))
    arrival = [item[0] for item in inputs]
    states = inputs
    ticks = [r for r in records.get(ch.CONTROL_TARGET, []) if r.get("pipeline") == spec.key]
    next_state = next_tick = 0

    def telemetry_until(time_s: float) -> None:
        nonlocal next_state
        while next_state < len(states) and arrival[next_state] <= time_s:
            _, kind, sample = states[next_state]
            if kind == 0:
                pipeline.add_state(sample)
            else:
                pipeline.add_sensor(sample)
            if isinstance(pipeline, KeepsRecords):
                out.relative += pipeline.take_records()
            next_state += 1

    def control_until(time_s: float) -> None:
        """The control ticks before ``time_s``: the target as the behaviour would have had it."""
        nonlocal next_tick
        while next_tick < len(ticks) and ticks[next_tick]["time_s"] < time_s:
            tick = ticks[next_tick]
            telemetry_until(tick["time_s"])  # what had arrived by then, and nothing later
            out.ticks.append(_tick_record(tick, pipeline.target(tick["time_s"])))
            next_tick += 1

    for image in read_images(path, spec.camera) if spec.camera else ():
        live = flown.get(ch.time_key(image.time_s))
        if live is None:
            continue  # logged but never processed in flight (the step was not running)
        frame = cv2.imdecode(np.frombuffer(image.jpeg, np.uint8), cv2.IMREAD_COLOR)
        if frame is None:
            raise ReplayError(f"{path}: the frame at {image.time_s:.3f} s is not a valid JPEG")
        control_until(live.get("received_s", image.time_s))
        telemetry_until(live.get("received_s", image.time_s))
        hint = pipeline.hint(image.time_s, camera)
        detection = pipeline.detect(frame, camera, image.time_s, hint)
        detected_s = live.get("detected_s", image.time_s)
        control_until(detected_s)
        telemetry_until(detected_s)
        out.detections.append(pipeline.detection_record(live["seq"], image.time_s, camera.name,
                                                        detection, hint))
        if detection is not None:
            estimate = pipeline.estimate(image.time_s, camera, detection)
            if estimate is not None:
                out.estimates.append(estimate)
            if isinstance(pipeline, KeepsRecords):
                out.relative += pipeline.take_records()
    if not spec.camera:  # a pipeline without a camera: its inputs and control ticks alone
        for tick in ticks:
            telemetry_until(tick["time_s"])
            control_until(tick["time_s"] + 1e-9)
    telemetry_until(math.inf)
    control_until(math.inf)
    return out


def _tick_record(tick: dict, est) -> dict:
    record = {k: tick.get(k) for k in ("time_s", "pipeline", "step", "step_index")}
    record["present"] = est is not None
    if est is not None:
        record.update(position_ned_m=est.position_ned_m.tolist(),
                      velocity_ned_m_s=est.velocity_ned_m_s.tolist(),
                      position_std_m=est.position_std_m.tolist(), age_s=est.age_s,
                      stale=est.stale, confirmed=est.confirmed)
    return record


def format_replay(result: dict) -> str:
    """The replay's figures next to the flight's, one per line."""
    lines = [f"replayed {result['frames']['replayed']} of {result['frames']['in_flight']} "
             f"frames of {result['source']}"
             + (f" with {' '.join(result['overrides'])}" if result["overrides"] else "")]
    if not result["log_complete"]:
        lines.append("the log was cut short: this replays what it holds")
    lines.append(f"{'':28}{'flight':>10}{'replay':>10}")
    for section in result["metrics"]:
        now, then = result["metrics"][section], result["flight_metrics"].get(section) or {}
        for key, value in now.items():
            if isinstance(value, (list, dict)):
                continue
            lines.append(f"{key:28}{_fmt(then.get(key)):>10}{_fmt(value):>10}")
    return "\n".join(lines)


def _fmt(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.4f}" if isinstance(value, float) else str(value)
