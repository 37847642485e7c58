"""Mission step kinds, one module each, registered in :mod:`autopilot.steps.registry`.

Importing this package registers every shipped kind. To add one: write a module with its
parameter model, behaviour, pipelines, metrics and report panels, call
:func:`~autopilot.steps.registry.register`, and import it below.
"""

from autopilot.steps import (  # noqa: F401 (registers them)
    flight,
    follow_ball,
    follow_marker,
    hover_image,
    land_on_rover,
    land_pad,
    trajectory,
)
from autopilot.steps.registry import STEP_KINDS, StepContext, StepKind, register, step_kind

__all__ = ["STEP_KINDS", "StepContext", "StepKind", "register", "step_kind"]
