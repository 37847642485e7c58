"""The ``hover_beacon`` step kind: climb to ``search_altitude_m``, find the beacon with the
down camera, fly over it and hover ``altitude_m`` above it for ``hold_s`` (its estimate
refined as it goes); the step fails if the beacon is not found within ``search_timeout_s``.

Its metrics (``metrics.beacon``) score the vehicle's true position against the beacon's true
position (simulator ground truth) over the hold; its report panel draws that error over time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Annotated

import numpy as np
from pydantic import Field

from autopilot.behaviors.base import (
    Behavior,
    BehaviorInputs,
    BehaviorOutput,
    Params,
    RequestKind,
    Status,
    VehicleRequest,
)
from autopilot.flightlog import records as ch
from autopilot.report.panels import NoData, register_panel
from autopilot.status import register_status
from autopilot.steps.registry import Figure, StepKind
from autopilot_beacon.pipeline import beacon_spec
from drivers.base import Setpoint


class HoverBeaconParams(Params):
    hold_s: Annotated[float, Field(gt=0, le=600)] = 8.0
    """How long to hover over the beacon once there."""
    altitude_m: Annotated[float, Field(gt=0.5, le=30)] = 2.5
    """Height of the hover above the beacon."""
    size_m: Annotated[float, Field(gt=0.1, le=5)] = 0.6
    """The beacon's side (for the report and scoring)."""
    search_altitude_m: Annotated[float, Field(gt=1, le=50)] = 6.0
    """Where to look from: straight up over where the step began."""
    search_timeout_s: Annotated[float, Field(gt=0, le=600)] = 30.0
    """The step fails if the beacon is not found this long after it began."""
    arrive_within_m: Annotated[float, Field(gt=0, le=5)] = 0.3
    """The hold starts once the vehicle is this close (horizontally) to the hover point."""


class HoverBeacon(Behavior):
    name = "hover_beacon"

    def __init__(self, params: HoverBeaconParams) -> None:
        self.params = params
        self.phase = "searching"
        self._start_s = 0.0
        self._point = np.zeros(3)
        self._yaw = 0.0
        self._hold_from: float | None = None

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        self._start_s = inputs.now_s
        self._yaw = s.yaw_rad
        self._point = np.array([s.position_ned_m[0], s.position_ned_m[1],
                                -self.params.search_altitude_m])
        return BehaviorOutput(Status.RUNNING, setpoint=self._setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase=self.phase)

    def _setpoint(self, now_s: float) -> Setpoint:
        return Setpoint.position(*self._point, yaw_rad=self._yaw, time_s=now_s)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        now, p = inputs.now_s, self.params
        target = inputs.target
        if target is not None and target.confirmed and not target.stale:
            c = target.position_ned_m
            self._point = np.array([c[0], c[1], c[2] - p.altitude_m])
            if self.phase == "searching":
                self.phase = "approaching"
        elif self.phase == "searching" and now - self._start_s > p.search_timeout_s:
            return BehaviorOutput(Status.FAILED, phase=self.phase,
                                  reason=f"no beacon found in {p.search_timeout_s:g} s")
        off = float(np.hypot(*(inputs.state.position_ned_m[:2] - self._point[:2])))
        if self.phase == "approaching" and off <= p.arrive_within_m:
            self.phase, self._hold_from = "holding", now
        progress = math.nan
        if self._hold_from is not None:
            progress = min(1.0, (now - self._hold_from) / p.hold_s)
            if progress >= 1.0:
                return BehaviorOutput(Status.SUCCEEDED, setpoint=self._setpoint(now),
                                      phase=self.phase, progress=1.0)
        return BehaviorOutput(Status.RUNNING, setpoint=self._setpoint(now), phase=self.phase,
                              progress=progress)


def _hold_intervals(records, intervals) -> list[tuple[float, float]]:
    """The stretches of the step spent in its ``holding`` phase (from its setpoints)."""
    out = []
    for start, end in intervals:
        times = [r["time_s"] for r in records.get(ch.SETPOINTS, [])
                 if r.get("step") == "hover_beacon" and r.get("phase") == "holding"
                 and start <= r["time_s"] <= end]
        if times:
            out.append((times[0], end))
    return out


def errors(records: Mapping[str, Sequence[Mapping]], start_s: float, end_s: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """(times, true horizontal distance between the vehicle and the beacon) in a stretch."""
    t, err = [], []
    for r in records.get(ch.GROUND_TRUTH, []):
        body = (r.get("bodies") or {}).get("beacon")
        if body is None or not start_s <= r["time_s"] <= end_s:
            continue
        v, b = r["vehicle_position_ned_m"], body["position_ned_m"]
        t.append(r["time_s"])
        err.append(math.hypot(v[0] - b[0], v[1] - b[1]))
    return np.array(t), np.array(err)


def metrics(records, intervals, plan) -> dict:
    holds = _hold_intervals(records, intervals)
    if not holds:
        return {"beacon": {"held": False}}
    _, err = errors(records, *holds[0])
    frames = [r for r in records.get(ch.detection_topic("beacon"), [])
              if intervals and intervals[0][0] <= r["time_s"] <= intervals[-1][1]]
    found = next((r["time_s"] for r in frames if r.get("detected")), None)
    out = {"held": True, "hold_s": holds[0][1] - holds[0][0],
           "found_after_s": None if found is None else found - intervals[0][0],
           "detection_rate": (sum(bool(r.get("detected")) for r in frames) / len(frames)
                              if frames else None)}
    if len(err):
        out.update(rms_hover_error_m=float(np.sqrt(np.mean(err ** 2))),
                   max_hover_error_m=float(err.max()), final_hover_error_m=float(err[-1]))
    return {"beacon": out}


def draw_panel(fig, records, phases, target) -> None:
    t, err = errors(records, -math.inf, math.inf)
    if not len(t):
        raise NoData("no ground truth of the beacon in this log")
    ax = fig.subplots()
    ax.plot(t, err, lw=1, label="true horizontal distance to the beacon")
    ax.set(xlabel="time (s)", ylabel="m", title="over the beacon (truth)")
    for start, end, name in phases:
        if name == "hover_beacon":
            ax.axvspan(start, end, color="tab:green", alpha=0.08)
    ax.legend(fontsize=8)


register_panel("beacon", "Over the beacon", draw_panel)
#: its mission status codes (the autopilot's own end at 20)
SEARCHING_OR_HOVERING = register_status(40, "hover beacon in progress")
HOVERED = register_status(41, "hover beacon completed")

STEP = StepKind(
    "hover_beacon", HoverBeaconParams,
    lambda params, ctx: HoverBeacon(params),
    pipelines=lambda params, config: (beacon_spec(config, params.size_m),),
    metrics=metrics, report=("beacon", "detections"),
    # what replay recomputes from the logged frames (the hold's path stays the flight's)
    replay={"beacon": ("detection_rate", "found_after_s")},
    status=(int(SEARCHING_OR_HOVERING), int(HOVERED)),
    description="find a beacon on the ground with the down camera and hover over it "
                "(an example plugin's step kind)",
    summary=((Figure("beacon", "rms_hover_error_m", "over the beacon: error RMS", "m"),
              Figure("beacon", "final_hover_error_m", "final", "m"),
              Figure("beacon", "found_after_s", "found after", "s")),
             (Figure("beacon", "detection_rate", "beacon detected in", "%", "of the frames"),)),
)
