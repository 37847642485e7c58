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
    #: where it goes in the report (lower first; the autopilot's own are numbered below 100,
    #: a panel that does not say goes after them)
    order: int = 100


#: the panels, in the order the report shows them
PANELS: dict[str, Panel] = {}
#: the panels every report has
ALWAYS = ("trajectory", "velocity", "status")


def register_panel(name: str, title: str, draw: Callable[..., None], *,
                   per_target: bool = False, order: int = 100) -> Panel:
    if name in PANELS:
        raise ValueError(f"report panel {name!r} is registered twice")
    PANELS[name] = panel = Panel(name, title, draw, per_target, order)
    return panel


def panels_in_order() -> list[Panel]:
    """The panels by their ``order`` (then as registered)."""
    return sorted(PANELS.values(), key=lambda panel: panel.order)


#: the steps' shades, in turn
STEP_COLOURS = ["#e8eef7", "#f7efe3", "#e9f5e9", "#f5e8f0", "#eeeeee"]


def shade_steps(ax, phases) -> None:
    """Each step shaded, its name above the plot: staggered over three rows so that short
    neighbouring steps' names do not print over each other."""
    for i, (a, b, step) in enumerate(phases):
        ax.axvspan(a, b, color=STEP_COLOURS[i % len(STEP_COLOURS)], zorder=0)
        ax.text(a, 1.02 + 0.07 * (i % 3), f" {step}", transform=ax.get_xaxis_transform(),
                va="bottom", fontsize=7, color="#555", clip_on=False)
