"""Standby: hover and wait for goals (the goal API's ``missions/standby.yaml``, seed 004's
hover service between its action servers).

In the air it holds where the vehicle comes to rest: an offboard position setpoint at the
stopping point (where braking at ``brake_accel_m_s2`` from the present velocity ends), so a
cancelled goal ends in a hover within about a second, without the overshoot of a setpoint at
the position it had when told. On the ground it waits (a takeoff goal starts the flight). It
succeeds — ending the mission, and the process — once the vehicle is on the ground and
disarmed after having flown (a land goal), or after ``timeout_s`` if one is given (counted from
the standby's start, goals included; a mission that ends in the air leaves the vehicle in its
own position hold).
"""

from __future__ import annotations

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
from drivers.base import Setpoint


class StandbyParams(Params):
    timeout_s: Annotated[float, Field(gt=0)] | None = None
    """The step ends this long after it started, goals included; None: it waits until the
    vehicle has landed."""
    exit_when_landed: bool = True
    """Done once the vehicle is on the ground and disarmed after having flown (a land goal)."""
    brake_accel_m_s2: Annotated[float, Field(gt=0, le=10)] = 2.5
    """The deceleration the hover point is worked out with: the vehicle holds where braking
    at this rate from its present velocity would stop it (no overshoot after a cancelled
    goal)."""


class Standby(Behavior):
    name = "standby"
    accepts_goals = True

    def __init__(self, params: StandbyParams) -> None:
        self.params = params
        self._start: float | None = None
        self._flown = False
        self._hold: np.ndarray | None = None
        self._yaw = 0.0

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        if self._start is None:
            self._start = inputs.now_s
        s = inputs.state
        self._flown = self._flown or s.in_air
        if not s.in_air:
            self._hold = None
            return self.update(inputs)
        v = np.asarray(s.velocity_ned_m_s, dtype=float)
        speed = float(np.linalg.norm(v))
        stop = v * speed / (2.0 * self.params.brake_accel_m_s2)  # braking distance
        self._hold = np.asarray(s.position_ned_m, dtype=float) + stop
        self._yaw = s.yaw_rad
        return BehaviorOutput(Status.RUNNING, setpoint=self._setpoint(inputs.now_s),
                              requests=(VehicleRequest(RequestKind.START_OFFBOARD),),
                              phase="hovering")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        self._flown = self._flown or s.in_air
        p = self.params
        if p.timeout_s is not None and inputs.now_s - self._start >= p.timeout_s:
            return BehaviorOutput(Status.SUCCEEDED, setpoint=self._setpoint(inputs.now_s),
                                  phase="timed out")
        if not s.in_air:
            if self._flown and not s.armed and p.exit_when_landed:
                return BehaviorOutput(Status.SUCCEEDED, phase="landed")
            return BehaviorOutput(Status.RUNNING, phase="on the ground")
        if self._hold is None:  # took off under another controller (not a goal): hold here
            return self.activate(inputs)
        return BehaviorOutput(Status.RUNNING, setpoint=self._setpoint(inputs.now_s),
                              phase="hovering")

    def _setpoint(self, now: float) -> Setpoint | None:
        if self._hold is None:
            return None
        return Setpoint.position_velocity(self._hold, (0.0, 0.0, 0.0), yaw_rad=self._yaw,
                                          time_s=now)


__all__ = ["Standby", "StandbyParams"]
