"""Frozen, validated settings: the shared base for every options dataclass."""
from __future__ import annotations

import dataclasses
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
