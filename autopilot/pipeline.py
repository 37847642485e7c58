"""Perception pipelines: one camera's frames → detections → a tracked target.

A pipeline is one synchronous object that the runtime drives in flight (detection in an
executor, the rest on the loop) and ``autopilot replay`` drives over a logged flight, in the
same order and with the same code:

1. :meth:`Pipeline.hint` — where the tracked target should appear in a frame, from the
   estimate and the vehicle's pose at the frame's capture time (the detector searches there
   first);
2. :meth:`Pipeline.detect` — the target in the frame (CPU-heavy, thread-safe to run off the loop
   while nothing else touches the pipeline's detector);
3. :meth:`Pipeline.estimate` — the detection placed in the world with the pose at capture time,
   through the pipeline's filter; returns the estimate record the flight log keeps;
4. :meth:`Pipeline.target` — the estimate extrapolated to a moment (what a behaviour flies on).

Telemetry reaches it through :meth:`Pipeline.add_state` as it arrives. Each pipeline logs its
per-frame records on ``/perception/<name>`` (:meth:`Pipeline.detection_record`) and its
estimates on ``/estimation/target`` (with its name). Kinds of pipeline (ball, marker, …) are
registered here by name (:func:`register`), so that steps declare the ones they need and replay
can rebuild them from a log.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from autopilot.config import AppConfig
from autopilot.estimation.target import TargetEstimate
from drivers.base import CameraInfo, VehicleState


def estimate_record(name: str, time_s: float, result, measurement,
                    est: TargetEstimate, **extra) -> dict:
    """The flight log's record of one filter update (``/estimation/target``), the same for
    every pipeline; ``extra``: what its kind adds (a heading, …)."""
    std = np.sqrt(np.diag(est.covariance))
    return {"time_s": time_s, "pipeline": name, "measurement_time_s": time_s,
            "accepted": result.accepted, "reinitialised": result.reinitialised,
            "mahalanobis2": result.mahalanobis2,
            "measured_position_ned_m": measurement.position_ned_m,
            "position_ned_m": est.position_ned_m, "velocity_ned_m_s": est.velocity_ned_m_s,
            "position_std_m": std[:3], "velocity_std_m_s": std[3:],
            "position_cov_m2": est.covariance[:3, :3].reshape(-1), "updates": est.updates,
            **extra}


class Pipeline(Protocol):
    name: str  # unique in a run; the log channel /perception/<name>
    kind: str  # the registered kind ("ball", "marker", …)
    camera: str  # the camera it reads

    def add_state(self, state: VehicleState) -> None: ...

    def hint(self, time_s: float, camera: CameraInfo) -> object | None: ...

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None) -> object | None: ...

    def estimate(self, time_s: float, camera: CameraInfo, detection: object) -> dict | None: ...

    def target(self, time_s: float) -> TargetEstimate | None: ...

    def detection_record(self, seq: int, time_s: float, camera: str, detection: object | None,
                         hint: object | None) -> dict: ...

    def hint_from_record(self, record: dict) -> object | None:
        """The hint a logged per-frame record carries (for replay)."""



@runtime_checkable
class SensorFed(Protocol):
    """A pipeline that also takes the vehicle's extra sensor streams (UWB ranges, the rover's
    reports: :data:`drivers.capabilities.SENSOR_STREAMS`), as they arrive."""

    def add_sensor(self, sample: object) -> None: ...


@runtime_checkable
class KeepsRecords(Protocol):
    """A pipeline that keeps records of its own for the flight log (``/relative/estimates``),
    taken after each input."""

    def take_records(self) -> list[dict]: ...

@dataclass(frozen=True, slots=True)
class PipelineSpec:
    """A pipeline a step needs: its kind, the camera it reads, and what scoring needs to know
    of its target in the simulator's ground truth (the truth body's name, its size)."""

    kind: str
    camera: str
    truth_body: str = ""
    target_size_m: float = 0.0
    name: str = ""  # default: the kind
    #: what to look for, when the step says (an image pipeline: the reference image's file)
    target: str = ""

    @property
    def key(self) -> str:
        return self.name or self.kind


Factory = Callable[[AppConfig, PipelineSpec], Pipeline]
_FACTORIES: dict[str, Factory] = {}


def register(kind: str, factory: Factory) -> None:
    _FACTORIES[kind] = factory


def make_pipeline(config: AppConfig, spec: PipelineSpec) -> Pipeline:
    try:
        factory = _FACTORIES[spec.kind]
    except KeyError:
        raise ValueError(f"no perception pipeline of kind {spec.kind!r} "
                         f"(known: {', '.join(sorted(_FACTORIES))})") from None
    return factory(config, spec)


def pipeline_kinds() -> list[str]:
    return sorted(_FACTORIES)
