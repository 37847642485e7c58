"""What every room of the runtime reads: the flight's context (vehicle, plan, log, clock, where
the mission is), and the small messages the rooms hand each other."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from autopilot import values
from autopilot.hooks import EventHub
from autopilot.steps import step_kind
from drivers.base import Frame, Setpoint, Vehicle, VehicleState
from drivers.slots import LatestSlot

if TYPE_CHECKING:
    from autopilot.config import AppConfig
    from autopilot.flightlog.log import FlightLog
    from autopilot.mission import MissionExecutor, MissionPlan, Step
    from autopilot.pipeline import Pipeline

#: a step's phases that are already the way down (the battery reserve does not interrupt them)
LANDING_PHASES = frozenset({"landing", "descending", "committed", "touching down",
                            "precision landing"})
#: a landing a failsafe asked for and the vehicle refused (or did not answer within 2 s) is
#: asked for again this long after (s)
LAND_RETRY_S = 1.0


class Service(Protocol):
    """Something the runtime runs for the whole flight beside the mission (the goal API's
    web server): ``run`` until ``stop`` is awaited (``graceful``: the run ended normally;
    otherwise stop at once, the vehicle comes first)."""

    name: str

    async def run(self) -> None: ...

    async def stop(self, graceful: bool = True) -> None: ...


@dataclass(slots=True)
class Intent:
    """A setpoint with an expiry: streamed until ``expires_s``, never after."""

    setpoint: Setpoint
    made_s: float
    expires_s: float
    source_frame_time_s: float | None
    step: str
    phase: str
    sent: bool = False


@dataclass(frozen=True, slots=True)
class ProcessedFrame:
    """A camera frame and what each of its lane's pipelines detected in it (in lane order)."""

    time_s: float
    seq: int
    frame: Frame
    detections: tuple[object | None, ...]
    hints: tuple[object | None, ...] = ()  # where each pipeline was told to look


@dataclass(slots=True)
class Track:
    """What one pipeline has made of its frames so far."""

    pipeline: Pipeline
    detection: object | None = None  # in the newest processed frame
    last_detection: object | None = None  # in the newest frame that had one
    frame_seq: int = -1
    frames: int = 0
    detections: int = 0


@dataclass(slots=True)
class Lane:
    """One camera in use: its pipelines, and the detection and estimation tasks that run them."""

    camera: str
    keys: tuple[str, ...]
    frames: LatestSlot[ProcessedFrame] = field(default_factory=LatestSlot)
    tasks: list[asyncio.Task] = field(default_factory=list)


@dataclass
class RunStats:
    frames: int = 0  # camera frames processed by the active steps' pipelines
    detections: int = 0  # pipeline detections in them
    setpoints_sent: int = 0
    frames_log_dropped: int = 0
    loop_lag_p50_ms: float | None = None  # how late the event loop answered (wall clock)
    loop_lag_p99_ms: float | None = None
    loop_lag_max_ms: float | None = None
    loop_stalls: int = 0  # the loop silent for runtime.loop_stall_s or longer
    #: frames perception and the console skipped while the loop ran late (real time), by
    #: lane ("front", "console:front"), and the lowest share of frames taken
    frames_yielded: dict[str, int] = field(default_factory=dict)
    lowest_frame_share: float | None = None
    armed: bool = False  # the vehicle was armed at some time during the run (it flew)
    #: the setpoint guards' interventions (autopilot.watch: acting on one subject, a zone,
    #: as long as it lasts) and the setpoints they changed
    guard_interventions: int = 0
    guarded_setpoints: int = 0


@dataclass(slots=True)
class Cursor:
    """Where the mission is: the running step (or goal), its phase and progress."""

    step: str = ""
    phase: str = ""
    index: int = -1
    progress: float = math.nan


class StepBook:
    """The mission's steps, then the goals run so far (a goal's index is its place here), with
    what each uses: its pipelines (keys) and the camera its photos come from."""

    def __init__(self, plan: MissionPlan, config: AppConfig) -> None:
        self.steps: list[Step] = list(plan.steps)
        self.mission_steps = len(plan.steps)
        self.pipeline_keys = [tuple(spec.key for spec in plan.pipelines(i))
                              for i in range(len(plan.steps))]
        self.photo_camera = [step_kind(step.name).photo_camera(step.params, config)
                             for step in plan.steps]

    def add(self, step: Step, keys: tuple[str, ...], photo_camera: str | None) -> int:
        """A goal's step, appended; returns its index."""
        self.steps.append(step)
        self.pipeline_keys.append(keys)
        self.photo_camera.append(photo_camera)
        return len(self.steps) - 1

    def name(self, index: int) -> str:
        return self.steps[index].name if 0 <= index < len(self.steps) else ""


class Flight:
    """The run's shared context, one per :class:`~autopilot.runtime.Runtime`: what the rooms
    read (the vehicle, the plan, the log, the clock, the newest telemetry, where the mission
    is) and the outcome they set. Each field has one writer, named beside it."""

    def __init__(self, vehicle: Vehicle, plan: MissionPlan, log: FlightLog,
                 progress: Callable[[str], None] | None) -> None:
        self.vehicle = vehicle
        self.plan = plan
        self.config = plan.config
        self.log = log
        self.clock = vehicle.clock
        self.progress = progress  # the console's lines (None: quiet)
        #: what happens, for hooks and the console (:mod:`autopilot.hooks`)
        self.events = EventHub()
        #: the ``name::value`` board (:mod:`autopilot.values`)
        self.values = values.board()
        self.stats = RunStats()
        self.book = StepBook(plan, plan.config)
        self.cursor = Cursor()  # (written by the control loop)
        self.state: VehicleState | None = None  # the newest telemetry (the telemetry room)
        self.executor: MissionExecutor | None = None  # (the lifecycle, when the run starts)
        self.status = "running"  # the outcome (the control loop, the failsafes, the lifecycle)
        self.reason = ""
        #: the safe stop asked for (Ctrl-C, SIGTERM, the goal API's abort, the console's L)
        self.stop_reason: str | None = None
        self.stop_requested = asyncio.Event()
        self.control_ended = False
        #: the control loop's wake-up: a fresh estimate's frame time, or NaN (act now)
        self.wake: LatestSlot[float] = LatestSlot()

    @property
    def in_air(self) -> bool:
        return self.state is not None and self.state.in_air

    def nudge(self) -> None:
        """Wake the control loop now (something needs acting on before the next tick)."""
        self.wake.put(math.nan)

    def request_stop(self, reason: str) -> None:
        if self.stop_reason is None:
            self.stop_reason = reason
        self.stop_requested.set()
        self.nudge()
