"""The simulated world a mission flies in (``scenario:``): a section for each target kind
(:mod:`autopilot.targets`: the shipped kinds' are fields of :class:`Scenario`, a plugin's are
validated by its kind as the mission loads), the wind, the decoys, the faults. Ignored on real
hardware."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator

import autopilot.target_kinds  # noqa: F401 (registers the shipped kinds before the model is made)
from autopilot.config import ConfigModel, NonNegative
from autopilot.perception.colors import COLORS
from autopilot.targets import TARGET_KINDS, ScenarioProblem, scenario_error
from drivers.sim.faults import Fault


class WindScenario(ConfigModel):
    gust_mps: NonNegative = 0.0
    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ScenarioRules(ConfigModel):
    """The rules every scenario keeps, whatever kinds are registered (:class:`Scenario` is this
    with a field for each shipped kind's section)."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)

    @model_validator(mode="after")
    def _target_sections(self) -> ScenarioRules:
        from autopilot.targets import validate_sections

        validate_sections(self.__pydantic_extra__ or {}, lambda kind: kind.scenario, "scenario",
                          unknown="unknown key", also_known=list(type(self).model_fields))
        return self

    def section(self, kind: str) -> BaseModel | None:
        """A target kind's section (validated), None when the scenario has none."""
        value = getattr(self, kind, None) if kind in type(self).model_fields else \
            (self.__pydantic_extra__ or {}).get(kind)
        return value if isinstance(value, BaseModel) else None

    def targets(self) -> dict[str, BaseModel]:
        """The target sections this scenario has (validated), by kind, in the order the kinds
        were registered."""
        found = {name: self.section(name) for name in TARGET_KINDS}
        return {name: section for name, section in found.items() if section is not None}

    @model_validator(mode="after")
    def _faults_apply(self) -> ScenarioRules:
        for i, f in enumerate(self.faults):
            if f.needs_target is not None and self.section(f.needs_target) is None:
                raise scenario_error(("faults", i), f"{f.kind}: the scenario has no "
                                     f"{f.needs_target}")
            color = getattr(f, "color", None)
            if color is not None and color not in COLORS:
                raise scenario_error(("faults", i, "color"), f"{f.kind}: unknown color "
                                     f"{color!r} (known: {', '.join(COLORS)})")
        return self

    @model_validator(mode="after")
    def _kinds_checks(self) -> ScenarioRules:
        for kind in TARGET_KINDS.values():
            if kind.check is not None:
                try:
                    kind.check(self)
                except ScenarioProblem as problem:
                    raise scenario_error(problem.key, problem.message) from None
        return self


def _fields() -> dict[str, Any]:
    fields: dict[str, Any] = {"seed": (Annotated[int, Field(ge=0)], 0)}
    for kind in TARGET_KINDS.values():  # the shipped kinds, in the order registered
        if kind.scenario is not None:
            default = kind.scenario() if kind.present_by_default else None
            fields[kind.name] = (kind.scenario | None, default)  # null: none
        fields.update(kind.scenario_keys)
    fields.update({
        #: decoys of the scenario's targets, each target kind placing its own (marker: decoy
        #: boards beside its path; pad: decoy pads around it): how many, or (for kinds that
        #: take them) their ids
        "decoys": (Annotated[int, Field(ge=0, le=30)] | list[Annotated[int, Field(ge=0)]], 0),
        "wind": (WindScenario, WindScenario()),
        #: injected faults, each a window after the first arming (drivers/sim/faults.py)
        "faults": (list[Fault], Field(default_factory=list)),
    })
    return fields


#: The simulated world: beside the shipped kinds' sections, a section for each target kind a
#: plugin registered, validated by that kind's scenario model.
Scenario = create_model("Scenario", __base__=ScenarioRules, __module__=__name__,
                        __doc__="The simulated world a mission flies in (``scenario:``).",
                        **_fields())
