"""Step and target kinds from other packages, found through Python entry points (as pytest
finds its plugins and Home Assistant its integrations; a whole example: ``examples/`` in the
repository)::

    # the plugin's pyproject.toml
    [project.entry-points."autopilot.targets"]
    my_target = "my_plugin.target:TARGET"   # a TargetKind (autopilot.targets)
    [project.entry-points."autopilot.steps"]
    my_step = "my_plugin.step:STEP"         # a StepKind (autopilot.steps)

An entry point names a kind (registered as it loads), a sequence of kinds, or a module that
registers its own when imported. Target kinds load first (a step kind may use them). They load
once, when the step registry is first imported; one that fails to load is reported (logged,
and listed by :func:`plugin_errors`) and the rest go on.
"""

from __future__ import annotations

import logging
from importlib.metadata import EntryPoint, entry_points

log = logging.getLogger(__name__)

GROUPS = ("autopilot.targets", "autopilot.steps")

_state = {"loaded": False}
_errors: list[str] = []
#: the plugins loaded: (group, entry point name, its distribution)
LOADED: list[tuple[str, str, str]] = []


def load_plugins() -> None:
    """Load every installed plugin's kinds (once; a no-op after the first call)."""
    if _state["loaded"]:
        return
    _state["loaded"] = True
    import autopilot.steps  # noqa: F401 (the shipped kinds first: a plugin may not shadow one)

    for group in GROUPS:
        for point in sorted(entry_points(group=group), key=lambda p: p.name):
            try:
                _register(group, point.load())
            except Exception as exc:
                where = f"{point.name} = {point.value} ({_distribution(point)})"
                _errors.append(f"{group} {where}: {type(exc).__name__}: {exc}")
                log.warning("the plugin %s could not be loaded: %s: %s", where,
                            type(exc).__name__, exc)
                continue
            LOADED.append((group, point.name, _distribution(point)))


def plugin_errors() -> list[str]:
    return list(_errors)


def _register(group: str, obj: object) -> None:
    from types import ModuleType

    from autopilot.steps.registry import StepKind, register
    from autopilot.targets import TargetKind, register_target

    if isinstance(obj, ModuleType):
        return  # it registered its kinds as it was imported
    for kind in obj if isinstance(obj, (list, tuple)) else [obj]:
        if isinstance(kind, TargetKind) and group == "autopilot.targets":
            register_target(kind)
        elif isinstance(kind, StepKind) and group == "autopilot.steps":
            register(kind)
        else:
            wanted = "TargetKind" if group == "autopilot.targets" else "StepKind"
            raise TypeError(f"expected a {wanted} (or a module registering its own), got "
                            f"{type(kind).__name__}")


def _distribution(point: EntryPoint) -> str:
    dist = point.dist
    return f"{dist.name} {dist.version}" if dist is not None else "?"
