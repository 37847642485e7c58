"""``autopilot replay DIR``: a logged flight's frames and telemetry through perception and
estimation again, with the flight's configuration or a changed one.

The flight cannot change (the vehicle flew where it flew), so what a replay can tell is how the
detector and the filter would have seen *that* flight: the detection metrics and the estimate
errors (against the simulator's ground truth, when the log has it).

It drives the same :class:`~autopilot.pipeline.TargetPipeline` the runtime drives, in the order
the runtime did: telemetry is added as it arrived (its logged arrival time), the detector's
search hint is taken when the frame arrived, the estimate after the detection finished. The
frames are the logged JPEGs, not the camera's raw images, so detections can differ by a
fraction of a pixel; without overrides the detection figures come out the same and the
estimate errors within a percent (``tests/integration/test_replay.py``).
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
    validate,
)
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_images, read_log_checked
from autopilot.flightlog.metrics import estimation_metrics, follow_metrics
from autopilot.pipeline import TargetPipeline, detection_record

#: The follow metrics a replay recomputes (the others describe the flight itself).
DETECTION_KEYS = ("detection_rate", "frames_in_view", "frames_processed",
                  "false_detection_rate", "max_lost_s")


class ReplayError(InputError):
    pass


def replay(run_dir: Path, overrides: Sequence[str] = ()) -> dict:
    """Replay ``run_dir/flight.mcap``; a summary shaped like ``summary.json``."""
    path = run_dir / "flight.mcap"
    if not path.is_file():
        raise ReplayError(f"{path}: no such file (a run folder holds flight.mcap)")
    records, complete = read_log_checked(path)
    plan = (records.get(ch.MISSION_PLAN) or [None])[0]
    if plan is None or not isinstance(plan.get("config"), dict):
        raise ReplayError(f"{path}: the log has no {ch.MISSION_PLAN} record with the flight's "
                          "configuration (written by an older autopilot?)")
    source = f"{path} (the flight's configuration)"
    cfg: AppConfig = validate(AppConfig, apply_overrides(Located(plan["config"], source, {}),
                                                         overrides))
    camera_name = plan["camera"]
    if cfg.perception.ball.camera != camera_name:
        raise ConfigError([Problem("--set", None, "perception.ball.camera",
                                   f"a replay uses the flight's camera ({camera_name!r})")])
    info = next((c for c in records.get(ch.CAMERA_INFO, []) if c["name"] == camera_name), None)
    if info is None:
        raise ReplayError(f"{path}: no {ch.CAMERA_INFO} record for camera {camera_name!r}")
    camera = ch.camera_info_from_record(info)

    flown = {ch.time_key(r["time_s"]): r for r in records.get(ch.BALL_DETECTIONS, [])}
    states = records.get(ch.VEHICLE_STATE, [])  # in arrival order
    arrival = [s.get("received_s", s["time_s"]) for s in states]
    pipeline = TargetPipeline(cfg)
    next_state = 0

    def telemetry_until(time_s: float) -> None:
        nonlocal next_state
        while next_state < len(states) and arrival[next_state] <= time_s:
            pipeline.add_state(ch.vehicle_state_from_record(states[next_state]))
            next_state += 1

    detections, estimates, replayed_ns = [], [], set()
    for image in read_images(path, camera_name):
        live = flown.get(ch.time_key(image.time_s))
        if live is None:
            continue  # logged but never processed in flight (the run ended)
        frame = cv2.imdecode(np.frombuffer(image.jpeg, np.uint8), cv2.IMREAD_COLOR)
        if frame is None:
            raise ReplayError(f"{path}: the frame at {image.time_s:.3f} s is not a valid JPEG")
        telemetry_until(live.get("received_s", image.time_s))
        hint = pipeline.hint(image.time_s, camera)
        detection = pipeline.detect(frame, camera, image.time_s, hint)
        telemetry_until(live.get("detected_s", image.time_s))
        detections.append(detection_record(live["seq"], image.time_s, camera.name, detection,
                                           hint))
        replayed_ns.add(ch.time_key(image.time_s))
        if detection is not None:
            estimate = pipeline.estimate(image.time_s, camera, detection)
            if estimate is not None:
                estimates.append(estimate)
    if not detections:
        raise ReplayError(f"{path}: no logged camera frames of {camera_name!r} to replay "
                          "(frames are logged by default in the simulator; on a vehicle set "
                          "log.frames.vehicle_rate_hz)")

    flight_frames = [r for r in records.get(ch.BALL_DETECTIONS, [])
                     if ch.time_key(r["time_s"]) in replayed_ns]
    replayed = {**records, ch.BALL_DETECTIONS: detections, ch.TARGET_ESTIMATES: estimates}
    as_flown = {**records, ch.BALL_DETECTIONS: flight_frames}
    follow = follow_metrics(replayed)
    return {
        "status": "replayed",
        "mission": plan.get("mission"),
        "source": str(run_dir),
        "overrides": list(overrides),
        "log_complete": complete,
        "frames": {"replayed": len(detections), "in_flight": len(flown)},
        "metrics": {
            "follow": {k: follow.get(k) for k in DETECTION_KEYS} if follow else {},
            "estimation": estimation_metrics(replayed),
        },
        # the same frames as flown, for comparison (equal to summary.json's when every
        # frame was logged)
        "flight_metrics": {
            "follow": {k: v for k, v in follow_metrics(as_flown).items() if k in DETECTION_KEYS},
            "estimation": estimation_metrics(records),
        },
    }


def format_replay(result: dict) -> str:
    """The replay's figures next to the flight's, one per line."""
    lines = [f"replayed {result['frames']['replayed']} of {result['frames']['in_flight']} "
             f"frames of {result['source']}"
             + (f" with {' '.join(result['overrides'])}" if result["overrides"] else "")]
    if not result["log_complete"]:
        lines.append("the log was cut short: this replays what it holds")
    lines.append(f"{'':28}{'flight':>10}{'replay':>10}")
    for section in ("follow", "estimation"):
        now, then = result["metrics"][section], result["flight_metrics"][section]
        for key, value in now.items():
            if isinstance(value, (list, dict)):
                continue
            lines.append(f"{key:28}{_fmt(then.get(key)):>10}{_fmt(value):>10}")
    return "\n".join(lines)


def _fmt(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.4f}" if isinstance(value, float) else str(value)
