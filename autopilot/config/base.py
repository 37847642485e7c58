"""The configuration's building blocks: the model every section derives from, the number
types, and the problems loading reports (file, line, key, what was expected)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
)

from autopilot.perception.colors import COLORS

KeyPath = tuple[str | int, ...]
Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
ColorName = Literal[tuple(COLORS)]  # type: ignore[valid-type]
HsvTriple = tuple[Annotated[int, Field(ge=0, le=180)], Annotated[int, Field(ge=0, le=255)],
                  Annotated[int, Field(ge=0, le=255)]]


class ConfigModel(BaseModel):
    """A section of the configuration: unknown keys refused, immutable, numbers finite."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)



@dataclass(frozen=True, slots=True)
class Problem:
    source: str  # a file name, or "--set"
    line: int | None
    key_path: str
    message: str

    def __str__(self) -> str:
        where = f"{self.source}:{self.line}" if self.line is not None else self.source
        return f"{where}: {self.key_path or '(top level)'}: {self.message}"


class InputError(Exception):
    """A run folder, log or file that cannot be used as given; the message names it and what
    was expected (the CLI prints it and exits with 2)."""


class ConfigError(Exception):
    """One or more problems in a configuration or mission file."""

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))
