"""A small bounded in-process cache of values that are costly to build and never change once built
(CasADi functions of a model's structure)."""
from __future__ import annotations

from typing import Callable, Hashable, TypeVar

T = TypeVar("T")


class Memo:
    """``get(key, build)``: the value built once per key; past ``size`` keys the oldest is dropped."""

    def __init__(self, size: int = 16):
        self.size = size
        self._values: dict[Hashable, object] = {}

    def get(self, key: Hashable, build: Callable[[], T]) -> T:
        if key not in self._values:
            if len(self._values) >= self.size:
                self._values.pop(next(iter(self._values)))
            self._values[key] = build()
        return self._values[key]
