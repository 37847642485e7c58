""""Did you mean": the closest of the names a user could have meant, for error messages."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def closest(word: str, choices: Iterable[str]) -> str | None:
    """The choice nearest to ``word`` (a typo, a wrong case, a missing letter), or None."""
    names = [str(c) for c in choices]
    lowered = {n.lower(): n for n in names}
    if str(word).lower() in lowered:
        return lowered[str(word).lower()]
    found = difflib.get_close_matches(str(word).lower(), list(lowered), n=1, cutoff=0.6)
    return lowered[found[0]] if found else None


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` for the choice nearest to ``word``, or ``""``."""
    found = closest(word, choices)
    return f" (did you mean {found!r}?)" if found is not None and found != word else ""
