"""Step kinds that only fly: ``takeoff``, ``hold``, ``land`` (no camera, no perception)."""

from __future__ import annotations

from autopilot.behaviors.flight import Hold, HoldParams, Land, LandParams, Takeoff, TakeoffParams
from autopilot.behaviors.standby import Standby, StandbyParams
from autopilot.steps.registry import StepKind, register

register(StepKind("takeoff", TakeoffParams, lambda params, ctx: Takeoff(params),
                  description="arm, take off to altitude_m and hold", status=(1, 2)))
register(StepKind("hold", HoldParams, lambda params, ctx: Hold(params),
                  description="hold position for duration_s", status=(3, 3)))
register(StepKind("land", LandParams, lambda params, ctx: Land(params),
                  description="land and wait for the disarm", status=(8, 9)))

register(StepKind("standby", StandbyParams, lambda params, ctx: Standby(params),
                  description="hover (or wait on the ground) for goals from the goal API; "
                  "done once landed", status=None, waits_for_goals=True,
                  endless=lambda params: params.timeout_s is None))
