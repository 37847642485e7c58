"""Overrides (``--set``), validation with located errors and "did you mean", the
simulation profiles, and :func:`load_config`."""

from __future__ import annotations

import collections.abc
import copy
import typing
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import (
    BaseModel,
    ValidationError,
)

from autopilot.config.app import AppConfig
from autopilot.config.base import (
    ConfigError,
    Problem,
)
from autopilot.config.yaml_source import (
    Located,
    dotted_key,
    load_yaml,
)
from autopilot.resources import default_config_path, profile_path, vehicle_path

# ------------------------------------------------------------------------------------------
# Overrides and validation
# ------------------------------------------------------------------------------------------


def apply_overrides(located: Located, overrides: Iterable[str]) -> Located:
    """Apply ``dotted.key=value`` overrides (values parsed as YAML: 3, true, [1, 0, 0], text)."""
    data = copy.deepcopy(located.data)
    lines = dict(located.lines)
    problems = []
    for item in overrides:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            problems.append(Problem("--set", None, item, "expected dotted.key=value"))
            continue
        try:
            value = yaml.safe_load(raw) if raw.strip() else ""
        except yaml.YAMLError:
            value = raw
        parts: list[str | int] = [int(p) if p.isdigit() else p for p in key.split(".")]
        target = data
        for depth, part in enumerate(parts):
            last = depth == len(parts) - 1
            if isinstance(target, list) and isinstance(part, int):
                if part >= len(target):
                    problems.append(Problem("--set", None, dotted_key(parts[:depth + 1]),
                                            f"no item {part} (the list has {len(target)})"))
                    break
            elif not isinstance(target, dict) or isinstance(part, int):
                problems.append(Problem("--set", None, dotted_key(parts[:depth]),
                                        "is not a section; cannot set a key inside it"))
                break
            if last:
                target[part] = value
                key_path = tuple(parts)
                for old in [k for k in lines if k[:len(key_path)] == key_path]:
                    del lines[old]  # (what the file said inside it is gone with it)
                lines[key_path] = ("--set", None)
            else:
                if isinstance(target, dict) and target.get(part) is None:
                    target[part] = {}  # (a section the --set makes: its problems are its)
                    lines[tuple(parts[:depth + 1])] = ("--set", None)
                target = target[part]
    if problems:
        raise ConfigError(problems)
    return Located(data, located.source, lines)


def validate(model: type[BaseModel], located: Located) -> Any:
    """Validate parsed data against a model; problems name file, line and key path."""
    try:
        return model.model_validate(located.data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors(include_url=False):
            loc = tuple(err["loc"])
            moved = (err.get("ctx") or {}).get("key_path")  # a whole-model check naming a key
            if moved:
                loc = tuple(moved)
            source, line = located.locate(loc)
            if err["type"] == "extra_forbidden":
                message = "unknown key" + unknown_key_hint(model, loc)
            elif err["type"] == "missing":
                message = (f"missing item {loc[-1]}: too few items" if loc
                           and isinstance(loc[-1], int) else "missing required key")
            elif moved:
                message = err["msg"]
            else:
                message = f"{err['msg']} (got {_short(err.get('input'))})"
            problems.append(Problem(source, line, dotted_key(loc), message))
        raise ConfigError(problems) from None


def known_keys(model: Any, loc: Sequence[Any]) -> list[str]:
    """The keys a model allows beside the last of ``loc`` (a path into it): the fields of the
    models that path ends in, through nested models, lists, mappings and unions."""
    current = [model]
    for part in loc[:-1]:
        current = [found for each in current for found in _types_at(each, part)]
    return list(dict.fromkeys(name for each in current for found in _models_in(each)
                              for name in found.model_fields))


def _types_at(annotation: Any, part: Any) -> list[Any]:
    """The types one key (or index) into a value of ``annotation``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        field = annotation.model_fields.get(str(part))
        return [field.annotation] if field is not None else []
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (list, tuple, set, frozenset, dict, collections.abc.Sequence,
                  collections.abc.Mapping):
        return [args[-1]] if args else []
    return [found for arg in args for found in _types_at(arg, part)]  # unions, Annotated


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [found for arg in typing.get_args(annotation) for found in _models_in(arg)]


def unknown_key_hint(model: Any, loc: Sequence[Any]) -> str:
    """``" (did you mean 'x'?)"`` for an unknown key at ``loc``, or ``""``."""
    from autopilot.suggest import did_you_mean

    return did_you_mean(str(loc[-1]), known_keys(model, loc)) if loc else ""


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def merge_located(base: Located, other: Located, prefix: tuple[str, ...] = ()) -> Located:
    """``base`` with ``other``'s section at ``prefix`` deep-merged over it, keeping the source
    lines of every merged key."""
    section: Any = other.data
    for key in prefix:
        section = section.get(key) if isinstance(section, dict) else None
    if not section or not isinstance(section, dict):
        return base  # (a section that is not a mapping is reported by the mission's model)

    def merge(into: dict, new: dict) -> None:
        for key, value in new.items():
            if isinstance(value, dict) and isinstance(into.get(key), dict):
                merge(into[key], value)
            else:
                into[key] = copy.deepcopy(value)

    data = copy.deepcopy(base.data)
    merge(data, section)
    lines = dict(base.lines)
    n = len(prefix)
    lines.update({path[n:]: where for path, where in other.lines.items()
                  if len(path) > n and path[:n] == prefix})
    return Located(data, base.source, lines)


# ------------------------------------------------------------------------------------------
# Simulation profiles
# ------------------------------------------------------------------------------------------

#: ``sim.profile``: which world the simulator flies in. ``realistic`` is ``config.yaml`` as it
#: stands (GNSS-grade navigation, fitted camera calibrations, imperfect sensors); ``ideal``
#: lays ``autopilot/profiles/ideal.yaml`` over it (the kind world: RTK-grade navigation, true
#: intrinsics, no dropped frames), for regression and comparison. Whatever a mission or
#: ``--set`` says is laid over the profile, so each dimension stays settable on its own.
PROFILES = ("realistic", "ideal")


def _chosen(layers: Sequence[Any], overrides: Iterable[str], *path: str) -> Any:
    """The value the last layer to name ``path`` chose: ``--set a.b=…``, else a mission's
    ``config``, else the base configuration's (None: nobody named it)."""
    dotted = ".".join(path)
    for item in reversed(list(overrides)):
        key, sep, raw = item.partition("=")
        if sep and key.strip() == dotted:
            return raw.strip()
    for data in reversed(list(layers)):
        for key in path[:-1]:
            data = data.get(key) if isinstance(data, dict) else None
        if isinstance(data, dict) and path[-1] in data:
            return data[path[-1]]
    return None


def _chosen_profile(layers: Sequence[Any], overrides: Iterable[str]) -> Any:
    """The profile the last layer to name one chose (``sim.profile``)."""
    return _chosen(layers, overrides, "sim", "profile")


def chosen_vehicle(layers: Sequence[Any], overrides: Iterable[str] = ()) -> str | None:
    """The vehicle family the configuration flies, when it is not the default (PX4-like):
    the simulated firmware ``sim.firmware`` names, or the family of the ``driver``
    (:data:`~autopilot.vehicle_kinds.DRIVER_KINDS`)."""
    from autopilot.vehicle_kinds import DRIVER_KINDS

    firmware = _chosen(layers, overrides, "sim", "firmware")
    driver = _chosen(layers, overrides, "driver")
    kind = DRIVER_KINDS.get(driver) if isinstance(driver, str) else None
    family = kind.family if kind is not None else None
    if family is None and isinstance(firmware, str):
        family = firmware
    return family if family != "px4" else None


def with_profile(base: Located, layers: Sequence[Any] = (),
                 overrides: Iterable[str] = ()) -> Located:
    """``base`` with the chosen vehicle's overlay (``autopilot/vehicles/NAME.yaml``, for a
    vehicle other than the default PX4-like one) and then the chosen profile's laid over it
    (under ``layers``, the data a mission and ``--set`` will lay over it afterwards). An
    unknown name is left for validation to report, where it was written."""
    vehicle = chosen_vehicle([base.data, *layers], overrides)
    path = vehicle_path(vehicle) if isinstance(vehicle, str) else None
    if path is not None:
        base = merge_located(base, load_yaml(path))
    name = _chosen_profile([base.data, *layers], overrides)
    if not isinstance(name, str) or name not in PROFILES:
        return base
    path = profile_path(name)
    if path is None:
        return base
    return merge_located(base, load_yaml(path))


def load_config(path: str | Path | None = None, overrides: Iterable[str] = ()) -> AppConfig:
    """Load ``config.yaml`` (the shipped one by default), lay the chosen simulation profile
    over it, apply overrides, validate."""
    overrides = list(overrides)
    located = with_profile(load_yaml(path or default_config_path()), (), overrides)
    return validate(AppConfig, apply_overrides(located, overrides))
