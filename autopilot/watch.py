"""Watchers and setpoint guards: what looks over every flight, whatever its steps.

A step's pipelines (:mod:`autopilot.pipeline`) see what the step flies to. Some things matter
to every step: a place not to fly into, seen once, is still not to be flown into by the next
step. A target kind (:mod:`autopilot.targets`, ``TargetKind.watch``) may bring, made from the
configuration once per run:

* a :class:`Watcher`: run on every frame of the cameras the running step already reads
  (it never turns a camera on), after the step's own pipelines have had the frame, in the
  detection executor (:meth:`Watcher.detect`), then on the loop (:meth:`Watcher.update`)
  with the pose at the frame's capture time from the telemetry it is given
  (:meth:`Watcher.add_state`);
* a :class:`SetpointGuard`: every setpoint the runtime streams, whoever made it (a step, the
  fallback, the console), passes through it before the geofence checks it
  (:mod:`autopilot.runtime.commands`); it may change it, and says what it did.

The runtime's room for them is :mod:`autopilot.runtime.watch`: it logs what watchers report
and each guard's interventions (``/control/guard``, and a mission event when one begins),
and counts them in the run's stats (the summary's ``stats``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from drivers.base import CameraInfo, Setpoint, VehicleState

if TYPE_CHECKING:
    from autopilot.config import AppConfig


@dataclass(frozen=True, slots=True)
class WatchReport:
    """What a watcher made of one frame: records for the flight log (``(topic, record)``,
    their channels' schemas registered by the watcher's module) and notes worth a mission
    event (a new thing found)."""

    records: tuple[tuple[str, dict], ...] = ()
    notes: tuple[str, ...] = ()


@runtime_checkable
class Watcher(Protocol):
    name: str  # unique in a run
    kind: str  # its detection's cost on the lockstep clock (``sim.compute_cost_ms``)

    def add_state(self, state: VehicleState) -> None: ...

    def looks_at(self, camera: str, seq: int) -> bool:
        """Whether it takes frame ``seq`` of ``camera`` (e.g. one frame in n)."""

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None) -> object | None:
        """What it sees in a frame (off the loop: touches nothing but its detector)."""

    def update(self, time_s: float, seq: int, camera: CameraInfo,
               detection: object | None) -> WatchReport:
        """Its detection taken in (on the loop), with the pose at ``time_s``."""


@dataclass(frozen=True, slots=True)
class Guarded:
    """A setpoint after a guard: ``action`` None when it let it pass as it was; otherwise
    what it did (``deflected``, …) for what (``subject``: one intervention lasts while the
    guard keeps acting on the same subject), in words (``text``), and a record for the log."""

    setpoint: Setpoint
    action: str | None = None
    subject: str = ""
    text: str = ""
    record: dict = field(default_factory=dict)


@runtime_checkable
class SetpointGuard(Protocol):
    name: str

    def guard(self, setpoint: Setpoint, state: VehicleState) -> Guarded:
        """``setpoint`` as it may go to the vehicle in ``state`` (the newest telemetry)."""


def make_watch(config: AppConfig) -> list[object]:
    """The watchers and guards every registered target kind brings for ``config``, in the
    order the kinds were registered (a kind's ``watch`` returns none when it is off)."""
    from autopilot.targets import TARGET_KINDS

    found: list[object] = []
    for kind in TARGET_KINDS.values():
        if kind.watch is not None:
            parts: Sequence[object] = kind.watch(config)
            found += list(parts)
    return found
