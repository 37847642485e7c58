"""The report's panels, by name: a step kind lists the ones that show it
(:attr:`autopilot.steps.registry.StepKind.report`), and a plugin registers its own here
(:func:`register_panel`) as the shipped ones are (:mod:`autopilot.report.html`).

A panel draws one matplotlib figure from the flight log's records: ``draw(fig, records,
phases, target)`` — ``records`` by channel (:mod:`autopilot.flightlog.records`), ``phases``
the steps' (start, end, name) for shading, ``target`` the followed target it is drawn for
(per-target panels: one each) or the first. It raises :class:`NoData` when the log has nothing
for it (the report says so in its place).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


class NoData(Exception):
    """The log has nothing this panel draws (the message says what is missing)."""


@dataclass(frozen=True, slots=True)
class Panel:
    name: str
    title: str
    draw: Callable[..., None]
    per_target: bool = False  # drawn once per followed target
    shipped: bool = False  # the autopilot's own (shown before the plugins')


#: the panels, in the order the report shows them
PANELS: dict[str, Panel] = {}
#: the panels every report has
ALWAYS = ("trajectory", "velocity", "status")


def register_panel(name: str, title: str, draw: Callable[..., None], *,
                   per_target: bool = False, shipped: bool = False) -> Panel:
    if name in PANELS:
        raise ValueError(f"report panel {name!r} is registered twice")
    PANELS[name] = panel = Panel(name, title, draw, per_target, shipped)
    return panel


def panels_in_order() -> list[Panel]:
    """The autopilot's own panels, then the plugins', each in the order registered."""
    return sorted(PANELS.values(), key=lambda panel: not panel.shipped)
