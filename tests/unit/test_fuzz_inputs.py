"""Fuzzing the files people write (Hypothesis): mission files, configuration files and
``--set`` overrides. Whatever goes in — random YAML structures, wrong types, out-of-range and
huge numbers, unicode, YAML tags and anchors, plain garbage — the answer is a valid plan or a
:class:`ConfigError` naming the file, line and key; never another exception (a traceback).

Bounded in CI (the ``ci`` profile); ``pytest --hypothesis-profile=long tests/unit/
test_fuzz_inputs.py`` runs many more examples."""

from __future__ import annotations

import contextlib
import copy
import math
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from autopilot.config import ConfigError, InputError, load_config
from autopilot.mission import MissionPlan, find_mission, load_mission
from autopilot.resources import default_config_path

SHIPPED = ["follow_ball", "survey", "orbit", "land_on_rover", "standby", "land_pad"]

scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(10 ** 30), max_value=10 ** 30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.sampled_from(["", "nan", "inf", "-1e999", "1e999", "🚁", "ä", "\u202e", "0x10", "yes",
                     "~", "NULL", "[1, 2", "{a: b", "front", "down", "orange", "lateral"]))
documents = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(st.one_of(st.text(max_size=12), st.sampled_from(
            ["steps", "name", "scenario", "config", "fallback", "description", "takeoff",
             "follow_ball", "survey", "goto", "orbit", "land", "altitude_m", "duration_s",
             "polygon_m", "ball", "seed", "wind", "rover", "speed_mps"])), inner,
            max_size=6)),
    max_leaves=25)

FUZZ = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                      HealthCheck.function_scoped_fixture])


@contextlib.contextmanager
def _written(text: str) -> Iterator[Path]:
    """``text`` as a mission file in a folder of its own, removed afterwards."""
    with tempfile.TemporaryDirectory(prefix="fuzz-") as folder:
        path = Path(folder) / "mission.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        yield path


def _load_mission_text(text: str):
    """A plan, or the ConfigError that names the problem; anything else fails the test."""
    with _written(text) as path:
        return _load_mission_text_at(path)


def _load_mission_text_at(path: Path):
    try:
        return load_mission(str(path))
    except ConfigError as exc:
        error = exc
    assert error.problems, "a ConfigError must name at least one problem"
    for problem in error.problems:
        assert str(problem)  # printable, with its source
    return error


def _dump(data) -> str:
    return yaml.safe_dump(data, allow_unicode=True, sort_keys=False)


@FUZZ
@given(documents)
def test_any_yaml_structure_as_a_mission(data):
    result = _load_mission_text(_dump(data))
    assert isinstance(result, (MissionPlan, ConfigError))


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _paths(value, (*prefix, i))


def _replace(node, path, value):
    if not path:
        return value
    out = copy.deepcopy(node)
    parent = out
    for key in path[:-1]:
        parent = parent[key]
    parent[path[-1]] = value
    return out


_MISSIONS = {name: yaml.safe_load(find_mission(name).read_text()) for name in SHIPPED}


@FUZZ
@given(st.sampled_from(SHIPPED), st.data(), documents)
def test_a_shipped_mission_with_one_value_changed(name, data, value):
    original = _MISSIONS[name]
    paths = list(_paths(original))
    path = data.draw(st.sampled_from(paths))
    result = _load_mission_text(_dump(_replace(original, path, value)))
    assert isinstance(result, (MissionPlan, ConfigError))


@FUZZ
@given(st.text(max_size=300) | st.sampled_from([
    "steps: !!python/object/apply:os.system ['echo pwned']",
    "a: &x [*x]", "name: x\nsteps: *nothing", "\t- takeoff: {}", "%YAML 9.9\n---\nname: x",
    "steps:\n  - takeoff: {altitude_m: 1e400}", "steps:\n  - follow_ball: {duration_s: -0.0}",
    "name: x\n" * 3, "--- a\n--- b", "steps: [{takeoff: {altitude_m: .nan}}]",
    "steps: [{survey: {polygon_m: [[0, 0], [0, 0], [0, 0]]}}]",
    "steps: [{orbit: {center_m: [1e308, -1e308], radius_m: 1e308}}]",
    "steps: [{goto: {position_m: [0, 0, 3], frame: rover}}]"]))
def test_text_that_is_barely_yaml(text):
    result = _load_mission_text(text)
    assert isinstance(result, (MissionPlan, ConfigError))


_CONFIG = yaml.safe_load(default_config_path().read_text())


@FUZZ
@given(st.data(), documents)
def test_a_configuration_with_one_value_changed(data, value):
    paths = [p for p in _paths(_CONFIG) if p]
    path = data.draw(st.sampled_from(paths))
    with _written(_dump(_replace(_CONFIG, path, value))) as path_file:
        try:
            load_config(path_file)
        except ConfigError as exc:
            error = exc
        else:
            return
    assert error.problems


@FUZZ
@given(st.lists(st.one_of(
    st.text(max_size=40),
    st.builds(lambda k, v: f"{k}={v}",
              st.sampled_from(["sim.seed", "driver", "runtime.control_rate_hz",
                               "console.keys.forward", "steps.1.follow_ball.duration_s",
                               "scenario.ball.speed_mps", "vehicle.cameras.front.enabled",
                               "sim.wind.gust_mps", "steps.9.takeoff", "a.b.c", "", "."]),
              st.one_of(st.text(max_size=20), st.sampled_from(
                  ["[1,", "{x: 1}", "1e999", "nan", "-5", "true", "🚁", "null", "[[]]"])))),
    max_size=4))
def test_command_line_overrides(overrides):
    try:
        load_mission("follow_ball", overrides)
    except (ConfigError, InputError) as exc:
        error = exc
    else:
        return
    assert str(error)


_LAUGHS = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 9)}]\n"
    for i in range(8))  # 9^9 values once expanded


@pytest.mark.parametrize("text", ["", "null", "[]", "42", "steps: []", "steps: {}",
                                  "steps: [42]", "steps: [{}]", "steps: [{a: 1, b: 2}]",
                                  "a: &x [*x]", "? [a, b]\n: 1", "[" * 300 + "]" * 300,
                                  "a: " + "[" * 100 + "]" * 100, _LAUGHS,
                                  "when: 2024-13-45", "steps: !!binary 'not base64'"])
def test_degenerate_missions_are_refused_by_name(text):
    result = _load_mission_text(text)
    assert isinstance(result, ConfigError)
    assert not math.isnan(len(str(result)))


@FUZZ
@given(st.one_of(
    st.binary(max_size=200),
    st.builds(lambda name, junk, at: (_SHIPPED_BYTES[name][:at] + junk + _SHIPPED_BYTES[name][at:]),
              st.sampled_from(SHIPPED), st.binary(min_size=1, max_size=8),
              st.integers(min_value=0, max_value=400))))
def test_bytes_that_are_not_text_as_a_mission_file_or_with_validate(raw):
    """Any bytes at all (a shipped mission with binary spliced in, Latin-1, a UTF-16 BOM, …):
    a plan or a ConfigError naming the file and line, from the loader and from ``validate``."""
    with tempfile.TemporaryDirectory(prefix="fuzz-") as folder:
        path = Path(folder) / "mission.yaml"
        path.write_bytes(raw)
        _load_mission_text_at(path)
        from autopilot.cli import main

        assert main(["validate", str(path)]) in (0, 2)


_SHIPPED_BYTES = {name: find_mission(name).read_bytes() for name in SHIPPED}
