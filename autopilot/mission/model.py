"""The mission model: a mission file's keys, its validated steps, and the plan it flies
(with its configuration)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field

from autopilot.behaviors.base import (
    Params,
)
from autopilot.config import (
    AppConfig,
    ConfigModel,
)
from autopilot.mission.scenario import Scenario
from autopilot.pipeline import PipelineSpec
from autopilot.steps import step_kind

MISSION_KEYS = ("name", "description", "steps", "fallback", "scenario", "config")


class Mission(ConfigModel):
    name: str
    description: str = ""
    steps: Annotated[list[dict[str, Any]], Field(min_length=1)]
    fallback: Literal["land"] = "land"
    scenario: Scenario | None = None
    config: dict[str, Any] = Field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Step:
    name: str
    params: Params


@dataclass(frozen=True, slots=True)
class MissionPlan:
    """A validated mission with the configuration it flies with."""

    mission: Mission
    steps: tuple[Step, ...]
    config: AppConfig
    source: Path
    #: what may not go as the mission's author expects, though it can fly (e.g. an orbit's
    #: centre outside its photos), each naming its step; shown before the flight
    warnings: tuple[str, ...] = ()

    def pipelines(self, index: int) -> tuple[PipelineSpec, ...]:
        """The perception pipelines step ``index`` needs while it runs."""
        step = self.steps[index]
        return step_kind(step.name).pipelines(step.params, self.config)

    def cameras_used(self) -> list[str]:
        """The cameras any step's pipelines read, in the order the steps first use them, then
        those steps take photos with (and, when the mission waits for goals, the photo camera
        goals use by default)."""
        cameras = [spec.camera for spec in self.all_pipelines().values() if spec.camera]
        for step in self.steps:
            kind = step_kind(step.name)
            photo = kind.photo_camera(step.params, self.config)
            if photo is not None:
                cameras.append(photo)
            if kind.waits_for_goals:
                cameras.append(self.config.photos.camera)
        return list(dict.fromkeys(cameras))

    def needs(self) -> list[tuple[int, str, str]]:
        """(step index, step name, need) for what each step needs of its vehicle
        (:attr:`~autopilot.steps.registry.StepKind.needs`)."""
        return [(i, step.name, need) for i, step in enumerate(self.steps)
                for need in step_kind(step.name).needs(step.params, self.config)]

    def all_pipelines(self) -> dict[str, PipelineSpec]:
        """Every pipeline any step needs, by key (steps that share one share its state)."""
        found: dict[str, PipelineSpec] = {}
        for i in range(len(self.steps)):
            for spec in self.pipelines(i):
                found.setdefault(spec.key, spec)
        return found
