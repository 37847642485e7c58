"""What a flight shows as it goes: its values on the ``name::value`` board (status, mode,
battery, height, the target) and the progress line the terminal prints."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from autopilot.behaviors.base import BehaviorInputs
from autopilot.console.view import publish_vehicle
from autopilot.photo_lane import PhotoLane
from autopilot.runtime.flight import Flight
from autopilot.runtime.perception import PerceptionLanes
from autopilot.runtime.recorder import MissionRecorder


class Readout:
    def __init__(self, flight: Flight, recorder: MissionRecorder, perception: PerceptionLanes,
                 photos: PhotoLane, control_by: Callable[[], str]) -> None:
        self.flight = flight
        self.recorder = recorder
        self.perception = perception
        self.photos = photos
        self.control_by = control_by

    def publish(self, inputs: BehaviorInputs) -> None:
        """The runtime's own values on the board (status, mode, battery, height, target)."""
        f = self.flight
        pub = f.values.publish
        s, code = inputs.state, self.recorder.status_code
        pub("status", f"{int(code)} {code.label}")
        pub("control", self.control_by())
        pub("step", f"{f.cursor.step or '-'} / {f.cursor.phase or '-'}")
        publish_vehicle(f.values, s)
        if math.isfinite(f.cursor.progress):
            pub("progress", f"{100 * f.cursor.progress:.0f} %")
        track = self.perception.first_track()
        if track is None:
            return
        det = track.detection
        score = getattr(det, "score", None)
        pub("det.score", round(float(score), 3) if score is not None else
            ("found" if det is not None else "none"))
        if track.frames:
            pub("det.rate", f"{100.0 * track.detections / track.frames:.0f} %")
        est = inputs.target
        if est is not None:
            pub("target.range_m", round(float(np.linalg.norm(
                est.position_ned_m - s.position_ned_m)), 2), "m")
            pub("target.sigma_m", round(float(np.sqrt(np.mean(
                np.diag(est.covariance)[:3]))), 3), "m")
            pub("target.age_s", round(float(est.age_s), 2), "s")

    def progress_line(self) -> str:
        f = self.flight
        s = f.state
        now = f.clock.now()
        code = self.recorder.status_code
        parts = [f"t={now:6.1f}s", f"status={int(code)} {code.label}",
                 f"step={f.cursor.step or '-'}", f"phase={f.cursor.phase or '-'}"]
        if math.isfinite(f.cursor.progress):
            parts.append(f"progress={100 * f.cursor.progress:3.0f}%")
        if self.photos.taken:
            parts.append(f"photos={self.photos.taken}")
        if s is not None:
            parts += [f"mode={s.mode.value}", f"alt={s.altitude_m:4.1f}m"]
        track = self.perception.first_track()
        if track is not None:
            est = track.pipeline.target(now)
            if s is not None and est is not None and not est.stale:
                distance = float(np.linalg.norm(est.position_ned_m - s.position_ned_m))
                parts.append(f"target={distance:4.2f}m")
            if track.frames:
                parts.append(f"det={100.0 * track.detections / track.frames:3.0f}%")
        return " ".join(parts)
