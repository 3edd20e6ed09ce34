"""What a parameter file says beyond its values: what the motor can have (``[hardware]``), how well its
values are known (``[uncertainty]``), where they were identified (``[envelope]``) and what else explains
the same recordings (``[[alternatives]]``).  Read and checked here; written back unchanged.

::

    [hardware]
    heat_sources = ["copper", "iron_losses", "friction_heating"]   # default: every kind
    [uncertainty]                                                   # dotted path -> [lo, hi], lo <= value <= hi
    "thermal.capacity_j_per_k" = [1800.0, 2100.0]
    [envelope]                                                      # the operating range identified on
    current_a = [0.0, 214.0]
    [[alternatives]]                                                # terms, and the values that differ
    terms = ["drive_heating"]
    "thermal.source.iron_losses.power_w" = 0.0
    "thermal.source.drive_heating.idle_w" = 365.0
    "thermal.source.drive_heating.split.winding" = 1.0

A path names a value of the file (``motor.resistance_ohm``, ``thermal.capacity_j_per_k``,
``thermal.node.winding.capacity_j_per_k``, ...; see :mod:`thermo_ddp.model.network_spec`).  An
alternative's values replace the file's at those paths (a source the file lacks is added; a power set
to 0 removes a term); the result must itself be a valid file of this motor.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from ..errors import InputError
from .catalogue import ENVELOPE_QUANTITIES, HEAT_SOURCE_KINDS


@dataclass(frozen=True)
class Alternative:
    """An explanation the recordings could not tell from the file's own: its ``terms`` and the values
    (dotted path -> value) that differ from the file's."""

    terms: tuple[str, ...]
    values: Mapping[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"terms": list(self.terms), **self.values}


@dataclass(frozen=True)
class Scope:
    """The four optional sections (``heat_sources`` None: the section is absent, every kind allowed)."""

    heat_sources: tuple[str, ...] | None = None
    uncertainty: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    envelope: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    alternatives: tuple[Alternative, ...] = ()

    @property
    def allowed_sources(self) -> tuple[str, ...]:
        return HEAT_SOURCE_KINDS if self.heat_sources is None else self.heat_sources

    def to_dict(self) -> dict[str, Any]:
        """The sections present, as written in the file."""
        out: dict[str, Any] = {}
        if self.heat_sources is not None:
            out["hardware"] = {"heat_sources": list(self.heat_sources)}
        if self.uncertainty:
            out["uncertainty"] = {k: list(v) for k, v in self.uncertainty.items()}
        if self.envelope:
            out["envelope"] = {k: list(v) for k, v in self.envelope.items()}
        if self.alternatives:
            out["alternatives"] = [a.to_dict() for a in self.alternatives]
        return out


def _table(source: str, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    sec = data.get(name, {})
    if not isinstance(sec, Mapping):
        raise InputError(source, f"[{name}]", repr(sec), "expected a table")
    return sec


def _finite(source: str, field: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise InputError(source, field, repr(value), "expected a finite number")
    return float(value)


def _interval(source: str, field: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise InputError(source, field, repr(value), "expected [lo, hi]")
    lo, hi = (_finite(source, field, v) for v in value)
    if lo > hi:
        raise InputError(source, field, repr(value), "lo > hi")
    return lo, hi


def read_hardware(source: str, data: Mapping[str, Any]) -> tuple[str, ...] | None:
    """``[hardware] heat_sources``: the kinds of heat this motor can have (None when absent)."""
    sec = _table(source, data, "hardware")
    for key in sec:
        if key != "heat_sources":
            raise InputError(source, f"hardware.{key}", sec[key], "unknown key; known: heat_sources")
    if "heat_sources" not in sec:
        return None
    kinds = sec["heat_sources"]
    if not isinstance(kinds, list):
        raise InputError(source, "hardware.heat_sources", repr(kinds), f"expected a list of {', '.join(HEAT_SOURCE_KINDS)}")
    for kind in kinds:
        if kind not in HEAT_SOURCE_KINDS:
            raise InputError(source, "hardware.heat_sources", repr(kind),
                             f"unknown heat source; known: {', '.join(HEAT_SOURCE_KINDS)}")
    return tuple(dict.fromkeys(kinds))


def read_uncertainty(source: str, data: Mapping[str, Any], value_at: Callable[[str], Any]) -> dict[str, tuple]:
    """``[uncertainty]``: dotted path -> [lo, hi]; each path names a value of the file, inside its interval."""
    out = {}
    for path, interval in _table(source, data, "uncertainty").items():
        lo, hi = _interval(source, f"uncertainty.{path}", interval)
        try:
            value = value_at(path)
        except KeyError:
            raise InputError(source, "uncertainty", path, "names no value of this file (a dotted path such as "
                             "motor.resistance_ohm or thermal.node.winding.capacity_j_per_k)") from None
        if not lo <= value <= hi:
            raise InputError(source, f"uncertainty.{path}", repr(list(interval)),
                             f"the file's value {value:g} lies outside the interval")
        out[path] = (lo, hi)
    return out


def read_envelope(source: str, data: Mapping[str, Any]) -> dict[str, tuple]:
    """``[envelope]``: quantity -> [lo, hi] for the quantities of :data:`ENVELOPE_QUANTITIES`."""
    out = {}
    for name, interval in _table(source, data, "envelope").items():
        if name not in ENVELOPE_QUANTITIES:
            raise InputError(source, f"envelope.{name}", repr(interval),
                             f"unknown quantity; known: {', '.join(ENVELOPE_QUANTITIES)}")
        out[name] = _interval(source, f"envelope.{name}", interval)
    return out


def read_alternatives(source: str, data: Mapping[str, Any], check: Callable[[str, Mapping[str, float]], None]
                      ) -> tuple[Alternative, ...]:
    """``[[alternatives]]``: each a ``terms`` list and dotted-path values; ``check(where, values)`` raises
    InputError when the file with those values is not a valid file of this motor."""
    items = data.get("alternatives", [])
    if not isinstance(items, list) or not all(isinstance(t, Mapping) for t in items):
        raise InputError(source, "[[alternatives]]", repr(items), "expected [[alternatives]] tables")
    out = []
    for k, table in enumerate(items, start=1):
        where = f"alternatives[{k}]"
        terms = table.get("terms")
        if not isinstance(terms, list) or not terms or not all(isinstance(t, str) and t for t in terms):
            raise InputError(source, f"{where}.terms", repr(terms), "expected a list of term names")
        values = {path: _finite(source, f"{where}.{path}", v) for path, v in table.items() if path != "terms"}
        check(where, values)
        out.append(Alternative(tuple(terms), values))
    return tuple(out)
