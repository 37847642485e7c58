"""Takeoff, land, hold, and the safe stop (hold briefly, then land)."""

from __future__ import annotations

from typing import Annotated

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
from drivers.base import FlightMode

_ALTITUDE_TOLERANCE_M = 0.3


class TakeoffParams(Params):
    altitude_m: Annotated[float, Field(gt=0.3, le=100)] = 2.0
    """Height to climb to, above where the vehicle armed."""
    timeout_s: Annotated[float, Field(gt=0)] = 30.0
    """The step fails if the vehicle is not armable, or not at ``altitude_m``, this long after
    the step started."""


class Takeoff(Behavior):
    """Wait until the vehicle is armable, arm, and climb to ``altitude_m`` above the arming
    point with the vehicle's takeoff command; done once it holds there (PX4: HOLD after
    TAKEOFF; ArduPilot: GUIDED)."""

    name = "takeoff"

    def __init__(self, params: TakeoffParams) -> None:
        self.params = params
        self._start = 0.0
        self._target_altitude = 0.0
        self._requested = False

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        if inputs.state.in_air:
            return BehaviorOutput(Status.SUCCEEDED, reason="already flying")
        return self.update(inputs)

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        if inputs.now_s - self._start > self.params.timeout_s:
            why = "not armable: " + ", ".join(s.health.problems()) if not self._requested \
                else f"not at {self.params.altitude_m} m"
            return BehaviorOutput(Status.FAILED, reason=f"{why} after {self.params.timeout_s:g} s")
        if not self._requested:
            if not s.health.armable:
                return BehaviorOutput(Status.RUNNING, phase="waiting for health")
            self._requested = True
            self._target_altitude = s.altitude_m + self.params.altitude_m
            return BehaviorOutput(Status.RUNNING, phase="climbing", requests=(
                VehicleRequest(RequestKind.ARM),
                VehicleRequest(RequestKind.TAKEOFF, altitude_m=self.params.altitude_m)))
        # PX4 climbs in TAKEOFF and then HOLDs; ArduPilot climbs and stays in GUIDED (our
        # OFFBOARD). Either way: out of TAKEOFF, in the air, at the altitude asked for. (Modes
        # arrive with the 1 Hz HEARTBEAT, so the altitude is what says the climb is over.)
        if (s.in_air and s.mode in (FlightMode.HOLD, FlightMode.OFFBOARD)
                and abs(s.altitude_m - self._target_altitude) < _ALTITUDE_TOLERANCE_M):
            return BehaviorOutput(Status.SUCCEEDED, phase="climbing")
        return BehaviorOutput(Status.RUNNING, phase="climbing")


class LandParams(Params):
    timeout_s: Annotated[float, Field(gt=0)] = 60.0
    """The step fails if the vehicle has not touched down and disarmed this long after the
    step started."""


class Land(Behavior):
    """Land with the vehicle's LAND mode; done once it has touched down and disarmed."""

    name = "land"

    def __init__(self, params: LandParams) -> None:
        self.params = params
        self._start = 0.0

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        if not inputs.state.armed and not inputs.state.in_air:
            return BehaviorOutput(Status.SUCCEEDED, reason="already on the ground")
        return BehaviorOutput(Status.RUNNING, requests=(VehicleRequest(RequestKind.LAND),),
                              phase="landing")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        if not inputs.state.armed and not inputs.state.in_air:
            return BehaviorOutput(Status.SUCCEEDED, phase="landing")
        if inputs.now_s - self._start > self.params.timeout_s:
            return BehaviorOutput(Status.FAILED, reason="not landed in time")
        return BehaviorOutput(Status.RUNNING, phase="landing")


class HoldParams(Params):
    duration_s: Annotated[float, Field(ge=0)] = 5.0
    """How long to hold position (the vehicle's HOLD mode)."""


class Hold(Behavior):
    """Hold position (the vehicle's HOLD mode) for ``duration_s``."""

    name = "hold"

    def __init__(self, params: HoldParams) -> None:
        self.params = params
        self._start = 0.0

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        return BehaviorOutput(Status.RUNNING, requests=(VehicleRequest(RequestKind.HOLD),),
                              phase="holding")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        if inputs.now_s - self._start >= self.params.duration_s:
            return BehaviorOutput(Status.SUCCEEDED, phase="holding")
        return BehaviorOutput(Status.RUNNING, phase="holding")


def _land_now() -> BehaviorOutput:
    """A failsafe's answer that lands the vehicle where it is (the vehicle's LAND mode)."""
    return BehaviorOutput(Status.RUNNING, requests=(VehicleRequest(RequestKind.LAND),),
                          phase="landing")


class ReturnHome(Behavior):
    """A failsafe for when there is just enough left to get home (the battery reserve): the
    vehicle's own return to launch (it climbs to its return altitude, flies home and lands), done
    once it has landed and disarmed. A vehicle that refuses to return lands where it is; so
    does one that does not take up its return within ``engage_s``, or leaves it (a mode other
    than return or landing, e.g. a hold the geofence commanded) for ``engage_s``: once, it
    does not fight a mode changed again after that (the pilot's)."""

    name = "return_home"
    RETURN_MODES = (FlightMode.RETURN, FlightMode.LAND, FlightMode.PRECLAND)

    def __init__(self, timeout_s: float = 600.0, engage_s: float = 5.0) -> None:
        self._timeout_s = timeout_s
        self._engage_s = engage_s
        self._start: float | None = None  # when first activated
        self._off_since: float | None = None
        self._landing = False

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        """Start returning; activated again (back from manual flight), it goes on where it was:
        a landing it had decided on stays a landing, and its timeout keeps running."""
        if self._start is None:
            self._start = inputs.now_s
        self._off_since = inputs.now_s  # until the vehicle is seen returning
        if not inputs.state.armed and not inputs.state.in_air:
            return BehaviorOutput(Status.SUCCEEDED, reason="already on the ground")
        if self._landing or not inputs.state.in_air:
            return self._land()
        return BehaviorOutput(Status.RUNNING, requests=(VehicleRequest(RequestKind.RETURN),),
                              phase="returning")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        if not s.armed and not s.in_air:
            return BehaviorOutput(Status.SUCCEEDED, phase="landed")
        if self._start is not None and inputs.now_s - self._start > self._timeout_s:
            return BehaviorOutput(Status.FAILED, reason="not home and landed in time")
        phase = "landing" if self._landing else "returning"
        if self._landing or not s.in_air or s.mode in self.RETURN_MODES:
            self._off_since = None
            return BehaviorOutput(Status.RUNNING, phase=phase)
        if self._off_since is None:
            self._off_since = inputs.now_s
        if inputs.now_s - self._off_since >= self._engage_s:
            return self._land()
        return BehaviorOutput(Status.RUNNING, phase=phase)

    def request_failed(self, request: VehicleRequest, reason: str) -> BehaviorOutput:
        if request.kind is RequestKind.RETURN:
            return self._land()
        return BehaviorOutput(Status.FAILED, reason=f"{request.kind.value}: {reason}")

    def _land(self) -> BehaviorOutput:
        self._landing = True
        return _land_now()


class SafeStop(Behavior):
    """The failsafe: hold for a moment, then land and wait for the disarm. Requests that fail
    are retried by going straight to LAND."""

    name = "safe_stop"

    def __init__(self, hold_s: float = 1.0, timeout_s: float = 60.0) -> None:
        self._hold_s = hold_s
        self._timeout_s = timeout_s
        self._start = 0.0
        self._landing = False

    def activate(self, inputs: BehaviorInputs) -> BehaviorOutput:
        self._start = inputs.now_s
        if not inputs.state.armed and not inputs.state.in_air:
            return BehaviorOutput(Status.SUCCEEDED, reason="already on the ground")
        if not inputs.state.in_air:  # armed on the ground: just land (disarms)
            self._landing = True
            return _land_now()
        return BehaviorOutput(Status.RUNNING, requests=(VehicleRequest(RequestKind.HOLD),),
                              phase="holding")

    def update(self, inputs: BehaviorInputs) -> BehaviorOutput:
        s = inputs.state
        if not s.armed and not s.in_air:
            return BehaviorOutput(Status.SUCCEEDED, phase="landed")
        if inputs.now_s - self._start > self._timeout_s:
            return BehaviorOutput(Status.FAILED, reason="not landed in time")
        if not self._landing and inputs.now_s - self._start >= self._hold_s:
            self._landing = True
            return _land_now()
        return BehaviorOutput(Status.RUNNING, phase="landing" if self._landing else "holding")

    def request_failed(self, request: VehicleRequest, reason: str) -> BehaviorOutput:
        if request.kind is RequestKind.HOLD:
            self._landing = True
            return _land_now()
        return BehaviorOutput(Status.FAILED, reason=f"{request.kind.value}: {reason}")
