"""The runtime: one event loop, one task per stage, latest-value hand-over between them.

::

    vehicle.frames(camera) ─► detection (executor) ─► [slot] ─► estimation ─► [event] ─┐
       (one lane per camera the active step uses; its pipelines run on each frame)         │
    vehicle.telemetry ─► pose history (every pipeline), latest state ──────────────────────┤
                                                           control (≥ control_rate_hz,
                                                           and on every estimate)
                                                                   │ intent (expires)
                                                                   ▼
                                                      setpoint streaming ─► vehicle

A package of rooms, each one class with one job, wired by :class:`Runtime`
(:mod:`~autopilot.runtime.lifecycle`):

* :mod:`~autopilot.runtime.flight` — the run's shared context (vehicle, plan, log, clock, the
  newest telemetry, where the mission is) and the messages the rooms exchange;
* :mod:`~autopilot.runtime.telemetry` — telemetry taken in (the newest state, the pose history,
  when the vehicle last said something new);
* :mod:`~autopilot.runtime.perception` — the running step's pipelines, by camera in lanes (a
  detection and an estimation task each), and the extra sensor streams;
* :mod:`~autopilot.runtime.control` — the control loop (a tick on every estimate and at least
  every period) and applying what the mission decided;
* :mod:`~autopilot.runtime.failsafes` — telemetry silence and loss, the geofence, the battery
  reserve, a failed step, the emergency stop; one hand-over, ``take_over``;
* :mod:`~autopilot.runtime.commands` — the setpoint stream (an intent with an expiry) and the
  vehicle commands;
* :mod:`~autopilot.runtime.goal_desk` and :mod:`~autopilot.runtime.console_bridge` — what the
  goal API and the console ask of a flight (:mod:`~autopilot.runtime.ports`);
* :mod:`~autopilot.runtime.recorder` — what the flight log keeps of the mission, and what the
  hooks hear; :mod:`~autopilot.runtime.readout` — the values board and the progress line;
  :mod:`~autopilot.runtime.planner` — the real-time planning worker.

* Frames and telemetry carry their capture times end to end: a detection is placed in the world
  with the vehicle pose at its frame's capture time, and the latency of each setpoint computed
  from a frame (capture → sent) is logged. The target a behaviour flew on is logged at every
  control tick (``/control/target``): that, not the filter right after an update, is what the
  estimation metrics score.
* :meth:`Runtime.request_stop` (Ctrl-C, SIGTERM) switches the mission to its safe stop — hold,
  land, disarm — bounded by ``shutdown_timeout_s``; every task belongs to one TaskGroup, so none
  outlives the run.
"""

from autopilot.runtime.control import next_tick_due
from autopilot.runtime.flight import (
    LAND_RETRY_S,
    LANDING_PHASES,
    Intent,
    Lane,
    ProcessedFrame,
    RunStats,
    Service,
    Track,
)
from autopilot.runtime.lifecycle import Runtime
from autopilot.runtime.perception import detect_all, detection_charge

__all__ = [
    "LANDING_PHASES",
    "LAND_RETRY_S",
    "Intent",
    "Lane",
    "ProcessedFrame",
    "RunStats",
    "Runtime",
    "Service",
    "Track",
    "detect_all",
    "detection_charge",
    "next_tick_due",
]
