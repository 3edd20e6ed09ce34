"""Frozen, validated settings: the shared base for every options dataclass."""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, TypeVar

from .errors import InputError

T = TypeVar("T")


def settings_from_mapping(cls: type[T], values: Mapping[str, Any], source: str = "options") -> T:
    """Build the frozen dataclass ``cls`` from a mapping; unknown keys raise InputError."""
    known = {f.name for f in dataclasses.fields(cls)}
    for key, value in values.items():
        if key not in known:
            raise InputError(source, key, value, f"unknown option; known: {', '.join(sorted(known))}")
    return cls(**values)


def require(condition: bool, source: str, field: str, value: object, problem: str) -> None:
    """Raise InputError(source, field, value, problem) unless ``condition`` holds."""
    if not condition:
        raise InputError(source, field, value, problem)


def _interval(text: str) -> tuple[float, float, bool, bool]:
    """``"(0, 1]"`` -> (0.0, 1.0, open low, closed high); ``inf`` allowed."""
    lo, hi = (float(s) for s in text[1:-1].split(","))
    return lo, hi, text[0] == "(", text[-1] == ")"


def _interval_words(text: str) -> str:
    lo, hi, open_lo, _ = _interval(text)
    if hi == float("inf"):
        return f"must be {'>' if open_lo else '>='} {lo:g}"
    return f"must be in {text}"


def check_ranges(settings: object, source: str, ranges: Mapping[str, str]) -> None:
    """Each named field of ``settings`` is a number inside its interval, written as in mathematics
    (``"(0, 1]"``, ``"[2, inf)"``); the first one outside raises InputError(source, field, value)."""
    for name, text in ranges.items():
        value = getattr(settings, name)
        lo, hi, open_lo, open_hi = _interval(text)
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        inside = number and (lo < value if open_lo else lo <= value) and (value < hi if open_hi else value <= hi)
        require(inside, source, name, value, _interval_words(text))


def checked_settings(source: str, **ranges: str):
    """Class decorator: a frozen dataclass whose named fields are checked against their intervals
    (see :func:`check_ranges`) when an instance is made; a ``__post_init__`` of the class runs after."""
    def wrap(cls):
        extra = cls.__dict__.get("__post_init__")

        def __post_init__(self):
            check_ranges(self, source, ranges)
            if extra is not None:
                extra(self)

        cls.__post_init__ = __post_init__
        return dataclasses.dataclass(frozen=True)(cls)
    return wrap
