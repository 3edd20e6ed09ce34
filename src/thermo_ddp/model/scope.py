"""What a parameter file says beyond its values: what the motor can have (``[hardware]``), how well its
values are known (``[uncertainty]``, and jointly: ``[covariance]``), where they were identified (``[envelope]``)
and what else explains the same recordings (``[[alternatives]]``).  Read and checked here; written back unchanged.

::

    [hardware]
    heat_sources = ["copper", "iron_losses", "friction_heating"]   # default: every kind
    [uncertainty]                                                   # dotted path -> [lo, hi], lo <= value <= hi
    "thermal.capacity_j_per_k" = [1800.0, 2100.0]
    "thermal.resistance_k_per_w" = [1.1, 1.4]
    [covariance]                                                    # optional: the fit's joint uncertainty
    paths = ["thermal.capacity_j_per_k", "thermal.resistance_k_per_w"]   # exactly the [uncertainty] paths
    scale = ["log", "log"]                                          # each: log(value) or the value ("linear")
    matrix = [[0.0016, -0.0011], [-0.0011, 0.0039]]                 # covariance of those (1 sigma, symmetric, PSD)
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

import numpy as np
from scipy.stats import chi2

from ..errors import InputError
from .catalogue import ENVELOPE_QUANTITIES, HEAT_SOURCE_KINDS

SCALES = ("log", "linear")
# The sections identify and diagnose write (a file they start from had its own, describing its own values).
LEARNED_SECTIONS = ("uncertainty", "covariance", "envelope", "alternatives")


@dataclass(frozen=True)
class Alternative:
    """An explanation the recordings could not tell from the file's own: its ``terms`` and the values
    (dotted path -> value) that differ from the file's."""

    terms: tuple[str, ...]
    values: Mapping[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"terms": list(self.terms), **self.values}


@dataclass(frozen=True)
class Covariance:
    """The fit's covariance of the ``[uncertainty]`` values (``paths``) with the file's other values held as
    written, each in the parametrisation its interval uses (``scale``: ``log``, the value's logarithm, or
    ``linear``, the value): one standard deviation, symmetric positive semi-definite.  It says what the
    intervals alone cannot: which values compensate each other (two resistances in series whose sum the data
    pin down)."""

    paths: tuple[str, ...]
    scale: tuple[str, ...]
    matrix: tuple[tuple[float, ...], ...]

    @classmethod
    def of(cls, paths, scale, matrix) -> "Covariance":
        return cls(tuple(paths), tuple(scale), tuple(tuple(float(v) for v in row) for row in np.asarray(matrix)))

    @classmethod
    def of_errors(cls, paths, log, values, stderr, correlation) -> "Covariance | None":
        """From standard errors of the values and their correlation matrix (a log-scaled value's error relative to
        it); None unless every error is finite and > 0."""
        sigma = np.asarray(stderr, float) / np.where(log, np.asarray(values, float), 1.0)
        if not sigma.size or not np.all(np.isfinite(sigma) & (sigma > 0)):
            return None
        return cls.of(paths, ["log" if g else "linear" for g in log], np.asarray(correlation, float) * np.outer(sigma, sigma))

    @property
    def array(self) -> np.ndarray:
        return np.array(self.matrix, float).reshape(len(self.paths), len(self.paths))

    @property
    def radius_95(self) -> float:
        """The 95 % confidence ellipsoid's radius in standard deviations: sqrt(chi2_{p,0.95}), p values."""
        return math.sqrt(chi2.ppf(0.95, len(self.paths)))

    def value_jacobian(self, values) -> np.ndarray:
        """d value / d parameter of each path at ``values`` (value for log-scaled paths, 1 for linear)."""
        return np.array([v if s == "log" else 1.0 for v, s in zip(np.asarray(values, float), self.scale)])

    def restricted(self, paths) -> "Covariance | None":
        """The covariance of some of the values, the others now held as written (conditioned on them: the Schur
        complement); None for none."""
        keep = [i for i, p in enumerate(self.paths) if p in set(paths)]
        held = [i for i in range(len(self.paths)) if i not in keep]
        if not keep:
            return None
        a = self.array
        cov = a[np.ix_(keep, keep)]
        if held:
            cov = cov - a[np.ix_(keep, held)] @ np.linalg.pinv(a[np.ix_(held, held)]) @ a[np.ix_(held, keep)]
        cov = 0.5 * (cov + cov.T)
        np.fill_diagonal(cov, np.maximum(np.diag(cov), 1e-12 * np.diag(a)[keep]))  # a value fully set by the held
        return Covariance.of([self.paths[i] for i in keep], [self.scale[i] for i in keep], cov)

    def to_dict(self) -> dict[str, Any]:
        return {"paths": list(self.paths), "scale": list(self.scale), "matrix": [list(r) for r in self.matrix]}


@dataclass(frozen=True)
class Scope:
    """The five optional sections (``heat_sources`` None: the section is absent, every kind allowed)."""

    heat_sources: tuple[str, ...] | None = None
    uncertainty: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    envelope: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    alternatives: tuple[Alternative, ...] = ()
    covariance: Covariance | None = None

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
        if self.covariance is not None:
            out["covariance"] = self.covariance.to_dict()
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


def read_covariance(source: str, data: Mapping[str, Any], uncertainty: Mapping[str, tuple],
                    value_at: Callable[[str], Any]) -> Covariance | None:
    """``[covariance]`` (optional): ``paths`` (exactly the ``[uncertainty]`` paths), ``scale`` (``log`` needs a
    value > 0) and ``matrix``: finite, symmetric, positive semi-definite, a positive variance for each path."""
    sec = _table(source, data, "covariance")
    if not sec:
        return None
    for key in sec:
        if key not in ("paths", "scale", "matrix"):
            raise InputError(source, f"covariance.{key}", repr(sec[key]), "unknown key; known: paths, scale, matrix")
    paths, scale, matrix = (sec.get(k) for k in ("paths", "scale", "matrix"))
    if not isinstance(paths, list) or len(set(map(str, paths))) != len(paths) or set(paths) != set(uncertainty):
        raise InputError(source, "covariance.paths", repr(paths), "expected each [uncertainty] path once")
    if not isinstance(scale, list) or len(scale) != len(paths) or any(s not in SCALES for s in scale):
        raise InputError(source, "covariance.scale", repr(scale), f"expected one of {', '.join(SCALES)} per path")
    for path, s in zip(paths, scale):
        if s == "log" and not value_at(path) > 0:
            raise InputError(source, "covariance.scale", path, "log scale of a value that is not > 0")
    rows = matrix if isinstance(matrix, list) and all(isinstance(r, list) for r in matrix) else None
    if rows is None or len(rows) != len(paths) or any(len(r) != len(paths) for r in rows):
        raise InputError(source, "covariance.matrix", repr(matrix), f"expected {len(paths)} rows of {len(paths)} numbers")
    cov = np.array([[_finite(source, "covariance.matrix", v) for v in r] for r in rows])
    scale_of = max(float(np.max(np.abs(cov))), 1e-300)
    if not np.allclose(cov, cov.T, rtol=1e-6, atol=1e-9 * scale_of):
        raise InputError(source, "covariance.matrix", repr(matrix), "not symmetric")
    if np.any(np.diag(cov) <= 0) or np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() < -1e-9 * scale_of:
        raise InputError(source, "covariance.matrix", repr(matrix), "not a covariance (a variance <= 0 or a negative "
                         "eigenvalue)")
    return Covariance.of(paths, scale, cov)


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
