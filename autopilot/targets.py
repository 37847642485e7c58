"""The registry of target kinds: what a mission's steps look for in the world, beside the step
kinds (:mod:`autopilot.steps`) that fly to it.

A target kind brings, in one place: its scenario section (``scenario.<name>``: where it is in
the simulated world and how it moves, a pydantic model) and the world builder that turns that
section into simulator bodies; its configuration (how it is found: pydantic models); and the
perception pipelines that find it (registered by kind in :mod:`autopilot.pipeline`, so replay
rebuilds them from a log). Report panels are registered beside them
(:func:`autopilot.report.panels.register_panel`). A kind that matters to every step, not only
to the one that looks for it (the keep-out discs), also brings what watches over every flight
(:attr:`TargetKind.watch`: watchers on the frames the running step reads, setpoint guards;
:mod:`autopilot.watch`).

The shipped kinds (:mod:`autopilot.target_kinds`: ball, marker, image, pad, rover, keep_out) are
registered before the scenario and configuration models are made, so their sections are fields
of those models, at the places ``config.yaml`` has always had them (``perception.<name>``,
``estimation.<name>``, ``rover``; :attr:`TargetKind.config`). Kinds from other packages arrive
through the ``autopilot.targets`` entry point group (:mod:`autopilot.plugins`), as step kinds do
through ``autopilot.steps``; their sections are ``scenario.<name>`` and ``targets.<name>``
(:attr:`TargetKind.settings`), validated by their models as the mission or configuration is
loaded.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel

if TYPE_CHECKING:
    from drivers.sim.config import SimConfig
    from drivers.sim.scenario import ScenarioObject


class World:
    """What a target kind's world builder is given, and may change: the scenario (every
    section: a kind may read a scenario-wide key such as ``decoys``), the simulator's
    configuration (``sim``, which a builder may replace with a changed copy), the scenario's
    seed, and the autopilot's configuration (``config``: what the autopilot knows of the
    target, e.g. the rover's deck; None when there is none)."""

    def __init__(self, scenario: BaseModel, sim: SimConfig, config: BaseModel | None) -> None:
        self.scenario = scenario
        self.sim = sim
        self.seed = int(getattr(scenario, "seed", 0))
        self.config = config
        self.objects: list[ScenarioObject] = []

    def ground(self) -> None:
        """Lay the textured ground (gravel and grass) down, once: a down camera's targets
        need a ground with features around them (the first kind that asks lays it)."""
        from drivers.sim.scenario import FeatureGround

        if not any(isinstance(o, FeatureGround) for o in self.objects):
            self.objects.append(FeatureGround(seed=self.seed + 7))


@dataclass(frozen=True)
class TargetKind:
    name: str
    #: its ``scenario.<name>`` section (None: it is not simulated)
    scenario: type[BaseModel] | None = None
    #: the simulator bodies of a scenario's section: (the section, the :class:`World` being
    #: built) → scenario objects (:mod:`drivers.sim.scenario`), added to the world in the order
    #: the kinds were registered
    build: Callable[[BaseModel, World], Sequence[ScenarioObject]] | None = None
    #: its ``targets.<name>`` configuration section (None: it has none)
    settings: type[BaseModel] | None = None
    description: str = ""
    #: the scenario has this kind's section unless it says ``<name>: null``
    present_by_default: bool = False
    #: more scenario keys the kind reads beside its section: key → (annotation, default)
    scenario_keys: Mapping[str, tuple[Any, Any]] = field(default_factory=dict)
    #: checks across the scenario's sections (the whole scenario → raise ValueError)
    check: Callable[[Any], None] | None = None
    #: a shipped kind's configuration sections, by dotted path (``perception.ball``,
    #: ``rover``): fields of the configuration's models, which are made once the shipped
    #: kinds are registered (a plugin's kind has ``settings`` instead)
    config: Mapping[str, type[BaseModel]] = field(default_factory=dict)
    #: what it watches over in every flight, whatever the steps (:mod:`autopilot.watch`):
    #: (the autopilot's configuration) → watchers and setpoint guards (none: switched off)
    watch: Callable[[Any], Sequence[object]] | None = None


TARGET_KINDS: dict[str, TargetKind] = {}


class ScenarioProblem(ValueError):
    """What a kind's :attr:`TargetKind.check` finds wrong, at the scenario key it names
    (``"decoys"``, or a path: ``("pad", "ids")``): the error points at that key, or at the
    ``--set`` argument that wrote it."""

    def __init__(self, key: str | tuple, message: str) -> None:
        super().__init__(message)
        self.key = (key,) if isinstance(key, str) else tuple(key)
        self.message = message


def keyed_error(kind: str, message: str, key_path: tuple) -> Exception:
    """A validation error at ``key_path`` (from the mission's or configuration's top: the
    loader names its file and line, or the ``--set`` argument); ``message`` is plain text."""
    from pydantic_core import PydanticCustomError

    return PydanticCustomError(kind, message.replace("{", "(").replace("}", ")"),
                               {"key_path": key_path})


def scenario_error(key: tuple, message: str) -> Exception:
    """A validation error at ``scenario.<key>``."""
    return keyed_error("scenario", message, ("scenario", *key))


def config_sections(parent: str) -> dict[str, type[BaseModel]]:
    """The registered kinds' configuration sections directly under ``parent`` (``""``: the
    top level), by key, in the order the kinds were registered."""
    found: dict[str, type[BaseModel]] = {}
    for kind in TARGET_KINDS.values():
        for path, model in kind.config.items():
            head, _, key = path.rpartition(".")
            if head == parent:
                if key in found:
                    raise ValueError(f"configuration section {path!r} is claimed twice")
                found[key] = model
    return found


def register_target(kind: TargetKind) -> TargetKind:
    if kind.name in TARGET_KINDS:
        if TARGET_KINDS[kind.name] is kind:
            return kind
        raise ValueError(f"target kind {kind.name!r} is registered twice")
    TARGET_KINDS[kind.name] = kind
    return kind


def target_kind(name: str) -> TargetKind:
    try:
        return TARGET_KINDS[name]
    except KeyError:
        raise KeyError(f"no target kind {name!r} (known: {', '.join(sorted(TARGET_KINDS))})"
                       ) from None


def validate_sections(sections: dict, model_of: Callable[[TargetKind], type[BaseModel] | None],
                      prefix: str, *, unknown: str, also_known: Sequence[str] = (),
                      list_known: bool = False, fill_defaults: bool = False) -> None:
    """Validate in place the plugins' target sections in ``sections`` (``scenario.<name>``,
    ``targets.<name>``: each by its kind's ``model_of`` model). A name no kind registered is
    refused (``unknown`` and a "did you mean", or with ``list_known`` the known names); with
    ``fill_defaults`` every kind with such a model has its section afterwards (the model's
    defaults when it was absent)."""
    from autopilot.plugins import load_plugins
    from autopilot.suggest import did_you_mean

    load_plugins()
    known = [*also_known, *(k for k, t in TARGET_KINDS.items() if model_of(t) is not None)]
    for key, value in list(sections.items()):  # in the order written: the first problem
        kind = TARGET_KINDS.get(key)
        if kind is None:
            hint = did_you_mean(key, known)
            if not hint and list_known:
                hint = f" (known: {', '.join(known)})" if known else " (none is installed)"
            raise keyed_error("unknown_key", unknown + hint, (prefix, key))
        sections[key] = validate_section(kind, model_of(kind), value, (prefix, key))
    if fill_defaults:
        for name, kind in TARGET_KINDS.items():
            if name not in sections and model_of(kind) is not None:
                sections[name] = validate_section(kind, model_of(kind), None, (prefix, name))


def validate_section(kind: TargetKind, model: type[BaseModel] | None, value: Any,
                     key_path: tuple) -> BaseModel:
    """``value`` as ``model``; a pydantic error naming ``key_path`` + the key inside it (the
    configuration loader places it on its file's line)."""
    from pydantic import ValidationError

    if model is None:
        raise keyed_error("target", f"the {kind.name} target takes no section here", key_path)
    try:
        return model.model_validate({} if value is None else value)
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        loc = tuple(err["loc"])
        message = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise keyed_error("target", message, (*key_path, *loc)) from None
