"""YAML with source locations: every value's file and line, for errors that name them;
bounded depth and size (a "billion laughs" stops)."""

from __future__ import annotations

import copy
import functools
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from autopilot.config.base import (
    ConfigError,
    KeyPath,
    Problem,
)

# ------------------------------------------------------------------------------------------
# YAML with source locations
# ------------------------------------------------------------------------------------------


@dataclass
class Located:
    """Parsed YAML data plus where each key came from."""

    data: Any
    source: str
    lines: dict[KeyPath, tuple[str, int | None]]

    def locate(self, path: KeyPath) -> tuple[str, int | None]:
        """Source and line of the longest prefix of ``path`` that exists."""
        for n in range(len(path), -1, -1):
            if path[:n] in self.lines:
                return self.lines[path[:n]]
        return self.source, None


def load_yaml(path: str | Path) -> Located:
    path = Path(path)
    source = path.name
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError([Problem(str(path), None, "", f"cannot read file: {exc.strerror}")])\
            from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ConfigError([Problem(source, line, "", f"not UTF-8 text: byte 0x{raw[exc.start]:02x} "
                                   f"at offset {exc.start} (YAML files are UTF-8)")]) from None
    return parse_yaml(text, source)


MAX_YAML_DEPTH = 64  # nesting levels a configuration or mission may have
MAX_YAML_NODES = 100_000  # values in one file, aliases expanded (a "billion laughs" stops here)


def parse_yaml(text: str, source: str) -> Located:
    """``text`` parsed, with each key's line; a file read again (a mission loaded for every
    trial, the configuration under each ``--set``) is parsed once: the caller gets its own
    copy to change."""
    return copy.deepcopy(_parse_yaml(text, source))


@functools.lru_cache(maxsize=32)
def _parse_yaml(text: str, source: str) -> Located:
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError([Problem(source, line, "", f"invalid YAML: {problem}")]) from None
    except RecursionError:
        raise ConfigError([Problem(source, None, "", "invalid YAML: nested too deeply")]) \
            from None
    lines: dict[KeyPath, tuple[str, int | None]] = {(): (source, 1)}
    problems: list[Problem] = []
    if node is not None:
        # (before building the data: a recursive alias or an alias bomb is refused here)
        _walk(node, (), source, lines, problems, (), [MAX_YAML_NODES])
    if problems:
        raise ConfigError(problems)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:  # (composed above, so unlikely: a bad value, e.g. a date)
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError([Problem(source, line, "", f"invalid YAML: {problem}")]) from None
    except (ValueError, OverflowError) as exc:  # e.g. an impossible !!timestamp
        raise ConfigError([Problem(source, None, "", f"invalid YAML value: {exc}")]) from None
    return Located({} if data is None else data, source, lines)


def _walk(node: yaml.Node, path: KeyPath, source: str,
          lines: dict[KeyPath, tuple[str, int | None]], problems: list[Problem],
          stack: tuple[int, ...], budget: list[int]) -> None:
    line = node.start_mark.line + 1
    if id(node) in stack:
        problems.append(Problem(source, line, dotted_key(path), "an alias used inside its own "
                                "anchor (the value would contain itself)"))
        return
    if len(stack) >= MAX_YAML_DEPTH:
        problems.append(Problem(source, line, dotted_key(path),
                                f"nested more than {MAX_YAML_DEPTH} levels deep"))
        return
    budget[0] -= 1
    if budget[0] < 0:
        if budget[0] == -1:
            problems.append(Problem(source, line, dotted_key(path), f"more than {MAX_YAML_NODES} "
                                    "values (aliases expanding?)"))
        return
    inner = (*stack, id(node))
    if isinstance(node, yaml.MappingNode):
        seen: set[str] = set()
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                problems.append(Problem(source, key_node.start_mark.line + 1, dotted_key(path),
                                        "a key must be a plain name, not a list or mapping"))
                continue
            key = key_node.value
            child = (*path, key)
            key_line = key_node.start_mark.line + 1
            if key in seen:
                problems.append(Problem(source, key_line, dotted_key(child), "duplicate key"))
            seen.add(key)
            lines[child] = (source, key_line)
            _walk(value_node, child, source, lines, problems, inner, budget)
            if budget[0] < 0:
                return
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            child = (*path, i)
            lines[child] = (source, item.start_mark.line + 1)
            _walk(item, child, source, lines, problems, inner, budget)
            if budget[0] < 0:
                return


def dotted_key(path: Iterable[str | int]) -> str:
    """A key path as the messages write it: ``steps[1].follow_ball.duration_s``."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out
