"""The behaviour lifecycle and the types it exchanges with the runtime."""

from __future__ import annotations

import abc
import enum
from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
from pydantic import BaseModel, ConfigDict

from autopilot.estimation.target import TargetEstimate
from drivers.base import Setpoint, VehicleState
from drivers.geo import GlobalOrigin


class Status(enum.Enum):
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class RequestKind(enum.Enum):
    ARM = "arm"
    TAKEOFF = "takeoff"
    START_OFFBOARD = "start_offboard"  # the runtime streams the current setpoint first
    HOLD = "hold"
    LAND = "land"
    PRECISION_LAND = "precision_land"  # PX4's AUTO.PRECLAND, on LANDING_TARGET
    LANDING_TARGET = "landing_target"  # report where the landing target is (not logged)
    DISARM = "disarm"  # stop the motors (``force``: in the air too, as PX4's kill)
    RETURN = "return"  # the vehicle's return to launch (PX4 AUTO.RTL): home, then it lands


@dataclass(frozen=True, slots=True)
class VehicleRequest:
    kind: RequestKind
    altitude_m: float | None = None  # TAKEOFF
    #: LANDING_TARGET: the target's position (local NED) at ``time_s``
    position_ned_m: tuple[float, float, float] | None = None
    time_s: float = 0.0
    force: bool = False  # DISARM: in the air too


@dataclass(frozen=True, slots=True, eq=False)
class PhotoRequest:
    """Take a photo now: the step's photo camera's next frame, saved with the pose it was
    taken at. ``planned_ned_m``: where the plan put it; ``look_at_ned_m``: what it is of (an
    orbit's centre), if anything."""

    index: int
    time_s: float
    camera: str
    planned_ned_m: tuple[float, float, float]
    look_at_ned_m: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True)
class Percept:
    """What one perception pipeline has made of its camera's frames, for a step that uses it.
    The detections are the pipeline's own type (a ball, a marker, …)."""

    pipeline: str  # its name (and flight log channel: /perception/<name>)
    kind: str  # what it tracks: "ball", "marker", …
    detection: object | None = None  # result of the newest processed frame (None: not seen)
    last_detection: object | None = None  # newest frame that had the target
    frame_seq: int = -1  # sequence number of the newest processed frame
    target: TargetEstimate | None = None  # its estimate, extrapolated to now


@dataclass(frozen=True, slots=True)
class BehaviorInputs:
    """What a behaviour sees at a control tick: the vehicle, and what the step's perception
    pipelines made of their frames (``percepts``, by pipeline name; ``percept`` is the step's
    first, whose target is ``target``). A step that needs no camera gets none."""

    now_s: float
    state: VehicleState
    target: TargetEstimate | None = None  # the step's target, extrapolated to now
    percept: Percept | None = None
    percepts: tuple[Percept, ...] = ()
    #: where the vehicle armed (local NED; None: not told), and the local frame's place on
    #: Earth (None: not known yet)
    home_ned_m: np.ndarray | None = None
    global_origin: GlobalOrigin | None = None

    @property
    def detection(self):
        return self.percept.detection if self.percept is not None else None

    @property
    def last_detection(self):
        return self.percept.last_detection if self.percept is not None else None

    @property
    def frame_seq(self) -> int:
        return self.percept.frame_seq if self.percept is not None else -1


@dataclass(frozen=True, slots=True)
class BehaviorOutput:
    status: Status
    setpoint: Setpoint | None = None
    requests: tuple[VehicleRequest, ...] = ()
    phase: str = ""
    reason: str = ""
    photos: tuple[PhotoRequest, ...] = ()
    #: how far the step has got (0..1; NaN: it does not say), for status and goal feedback
    progress: float = float("nan")
    #: the step's plan, once, when it has made one (logged on /planning/path as it is: numbers,
    #: lists and numpy arrays, NaN logged as null)
    plan: dict | None = None
    #: a photo will be asked for within a moment (a camera that renders on demand — the
    #: simulator's — is kept running only then)
    photo_soon: bool = False


class Params(BaseModel):
    """A step kind's parameters: what a mission file's step, or a goal, may say.

    Each field is documented by the string on the line after it (an attribute docstring):
    pydantic keeps it as the field's description (``model_fields[name].description``), which
    the goal API's schema and the documentation's step reference show."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False,
                              use_attribute_docstrings=True)


class Behavior(abc.ABC):
    """One step of a mission. ``activate`` is called once with the inputs at that moment,
    then ``update`` at every control tick until the status is not RUNNING."""

    name: ClassVar[str]
    #: a step that waits for goals while it runs (standby: the goal API's goals run from it)
    accepts_goals: ClassVar[bool] = False

    @abc.abstractmethod
    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        """The step starts (or resumes, after manual flight or a goal): ``inputs`` as they are
        at that moment; returns the first output."""

    @abc.abstractmethod
    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        """One control tick: what to fly now, and whether the step is done."""

    def request_failed(self, request: VehicleRequest, reason: str) -> BehaviorOutput:
        """A request was refused or could not be carried out. Default: the step fails."""
        return BehaviorOutput(Status.FAILED, reason=f"{request.kind.value}: {reason}")


@runtime_checkable
class FollowModes(Protocol):
    """A behaviour that follows a target in more than one way (the console's F switches)."""

    def toggle_follow_mode(self) -> str:
        """Switch to the next way of following; returns its name."""
