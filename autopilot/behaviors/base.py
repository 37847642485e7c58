"""The behaviour lifecycle and the types it exchanges with the runtime."""

from __future__ import annotations

import abc
import enum
from dataclasses import dataclass
from typing import ClassVar

from pydantic import BaseModel, ConfigDict

from autopilot.estimation.target import TargetEstimate
from autopilot.perception.ball import BallDetection
from drivers.base import Setpoint, VehicleState


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


@dataclass(frozen=True, slots=True)
class VehicleRequest:
    kind: RequestKind
    altitude_m: float | None = None  # TAKEOFF


@dataclass(frozen=True, slots=True)
class BehaviorInputs:
    now_s: float
    state: VehicleState
    target: TargetEstimate | None = None  # the tracked target, extrapolated to now
    detection: BallDetection | None = None  # result of the newest processed frame
    last_detection: BallDetection | None = None  # newest frame that had the target
    frame_seq: int = -1  # sequence number of the newest processed frame


@dataclass(frozen=True, slots=True)
class BehaviorOutput:
    status: Status
    setpoint: Setpoint | None = None
    requests: tuple[VehicleRequest, ...] = ()
    phase: str = ""
    reason: str = ""


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Behavior(abc.ABC):
    """One step of a mission. ``activate`` is called once with the inputs at that moment,
    then ``update`` at every control tick until the status is not RUNNING."""

    name: ClassVar[str]

    @abc.abstractmethod
    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput: ...

    @abc.abstractmethod
    def update(self, inputs: BehaviorInputs) -> BehaviorOutput: ...

    def request_failed(self, request: VehicleRequest, reason: str) -> BehaviorOutput:
        """A request was refused or could not be carried out. Default: the step fails."""
        return BehaviorOutput(Status.FAILED, reason=f"{request.kind.value}: {reason}")
