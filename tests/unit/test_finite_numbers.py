"""NaN and Infinity are refused wherever a goal, a mission step or the configuration takes a
number, with the key named (issue 31: Infinity in a duration was accepted and reading the goal
back then failed with a 500; NaN in an offset ended the run in a traceback)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel, ValidationError

from autopilot.config import ConfigError, load_config
from autopilot.goals import goal_kinds
from autopilot.mission import load_mission
from autopilot.resources import default_config_path
from autopilot.steps.registry import STEP_KINDS

BAD = (math.nan, math.inf, -math.inf)


def _examples() -> dict[str, dict]:
    """One valid parameter set per step kind: from the shipped missions, else the defaults."""
    found: dict[str, dict] = {}
    for name in sorted(p.stem for p in Path('missions').glob('*.yaml')):
        for step in load_mission(name).steps:
            found.setdefault(step.name, step.params.model_dump(mode="python"))
    found.setdefault("goto", {"position_m": [4.0, 3.0, -6.0]})  # (no shipped mission flies one)
    for kind, spec in STEP_KINDS.items():
        if kind not in found:
            try:
                found[kind] = spec.params().model_dump(mode="python")
            except ValidationError:
                continue
    return found


def _numeric_leaves(value, path=()):
    """Every float in ``value`` (dicts, lists and tuples walked), with its path."""
    if isinstance(value, float):
        yield path
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _numeric_leaves(item, (*path, key))
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            yield from _numeric_leaves(item, (*path, i))


def _replaced(value, path, new):
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(value, dict):
        return {**value, head: _replaced(value[head], rest, new)}
    items = list(value)
    items[head] = _replaced(items[head], rest, new)
    return items


def _refused_naming(model: type[BaseModel], data: dict, path) -> bool:
    """Whether ``data`` is refused with an error at ``path`` (a bound such as ``gt=0`` may
    be the one that names a NaN; either way the key is named)."""
    try:
        model.model_validate(data)
    except ValidationError as exc:
        return any(tuple(e["loc"])[:len(path)] == tuple(path) for e in exc.errors())
    return False


def _shapes(bad: float) -> list:
    """What an unset numeric field might take: a number, a pair, a triple, a list of pairs."""
    return [bad, [bad, bad], [bad, bad, bad], [[bad, bad]] * 3]


EXAMPLES = _examples()


def test_every_goal_kind_has_an_example():
    assert set(goal_kinds()) <= set(EXAMPLES)


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_nan_and_infinity_are_refused_in_every_number_of_every_step_kind(kind):
    model, example = STEP_KINDS[kind].params, EXAMPLES[kind]
    model.model_validate(example)  # the example itself is fine
    paths = list(_numeric_leaves(example))
    assert paths or kind in ("land",), f"{kind}: no number to try"
    for path in paths:
        for bad in BAD:
            assert _refused_naming(model, _replaced(example, path, bad), path), (kind, path, bad)
    # fields that may hold numbers but are unset (None) in the example: refused in every
    # shape tried, and as not finite in at least one (the shape it takes)
    properties = model.model_json_schema().get("properties", {})
    for key, schema in properties.items():
        if example.get(key) is None and '"number"' in json.dumps(schema):
            for bad in BAD:
                errors = []
                for value in _shapes(bad):
                    try:
                        model.model_validate({**example, key: value})
                    except ValidationError as exc:
                        errors += exc.errors()
                    else:
                        pytest.fail(f"{kind}.{key} = {value} accepted")
                assert any(e["type"] == "finite_number" and e["loc"][0] == key
                           for e in errors), (kind, key, bad)


def test_a_goal_with_infinity_in_json_is_refused_naming_the_key():
    model = STEP_KINDS["hold"].params
    with pytest.raises(ValidationError) as exc:
        model.model_validate(json.loads('{"duration_s": Infinity}'))
    assert exc.value.errors()[0]["loc"] == ("duration_s",)
    assert exc.value.errors()[0]["type"] == "finite_number"


def _config_keys(value, path=()):
    """Every float key of the configuration (lists left out: ``--set`` names keys)."""
    if isinstance(value, float):
        yield ".".join(path)
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _config_keys(item, (*path, str(key)))


@pytest.mark.parametrize(("which", "bad"), enumerate([".nan", ".inf", "-.inf"]))
def test_nan_and_infinity_in_the_configuration_are_refused_naming_the_key(which, bad):
    keys = list(_config_keys(yaml.safe_load(default_config_path().read_text())))
    assert len(keys) > 50
    for key in keys[which::3]:  # each key tried with one of the three
        with pytest.raises(ConfigError) as exc:
            load_config(overrides=[f"{key}={bad}"])
        assert key.split(".")[-1] in str(exc.value), (key, str(exc.value))
