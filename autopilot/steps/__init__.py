"""Mission step kinds, one module each, registered in :mod:`autopilot.steps.registry`.

Importing this package registers every shipped kind, then the kinds of the installed plugins
(:mod:`autopilot.plugins`: the ``autopilot.steps`` and ``autopilot.targets`` entry points). To
add one here: write a module with its parameter model, behaviour, pipelines, metrics and report
panels, call :func:`~autopilot.steps.registry.register`, and import it below; to add one from
another package, declare it as an entry point.
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

from autopilot.plugins import load_plugins

load_plugins()
