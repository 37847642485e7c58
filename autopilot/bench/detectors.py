"""The registry of ``autopilot bench perception``'s detector benches, and what they share:
the options (frames per cell, the vehicle's motion during each exposure) and the table helpers.
:mod:`autopilot.bench.perception` (front camera: ball, marker) and
:mod:`autopilot.bench.down_perception` (down camera: image, pad) each register theirs here."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.config import AppConfig


@dataclass(frozen=True, slots=True)
class BenchOptions:
    """How many frames, and how the vehicle moves while each is exposed."""

    #: Frames per marker distance and obliquity, and per ball distance.
    marker_frames: int = 40
    ball_frames: int = 30
    seed: int = 0
    #: The vehicle's angular velocity, per body axis: normal with this σ (rad/s). At the
    #: front camera's 4 ms exposure, 0.15 rad/s blurs by 0.2 px (none below 0.5 px); one
    #: frame in ten or so by more than that.
    rate_std_rad_s: float = 0.15
    #: Its velocity, per NED axis (m/s): blur from translation (over the distance to the
    #: ground along the boresight, when the camera looks down).
    speed_std_m_s: float = 0.3


DEFAULT_OPTIONS = BenchOptions()
#: For the test suite: a few frames per cell (about 20 s).
QUICK_OPTIONS = BenchOptions(marker_frames=8, ball_frames=6)


@dataclass(frozen=True)
class DetectorBench:
    """One detector's bench: ``run(config, options, log)`` returns its JSON section;
    ``table(section)`` its lines of the printed table."""

    name: str
    run: Callable[[AppConfig, BenchOptions, Callable[[str], None]], dict]
    table: Callable[[dict], list[str]]


BENCHES: dict[str, DetectorBench] = {}


def register(bench: DetectorBench) -> DetectorBench:
    BENCHES[bench.name] = bench
    return bench




def percentile(values: Sequence[float], q: float) -> float | None:
    """The ``q``-th percentile of ``values``, None for none."""
    return float(np.percentile(values, q)) if len(values) else None


def num(value: float | None, fmt: str) -> str:
    """A table cell: ``value`` formatted, a dash for none."""
    return "—" if value is None else format(value, fmt)
