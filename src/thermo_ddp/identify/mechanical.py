"""Inverse-dynamics identification of one joint (or axis), linear in the parameters.

    effort = inertia·ddq + viscous_friction·dq + coulomb_friction·sign(dq) + effort_offset
             [+ stribeck_friction·exp(-(dq/stribeck_velocity)²)·sign(dq)]

Any subset of the terms can be fitted (the diagnosis baseline is inertia + viscous + offset).
``dq`` and ``ddq`` come from the position through a zero-phase Butterworth low-pass
(``scipy.signal.filtfilt``) and central differences, as in the EMPS benchmark reference model
(Janot, Gautier, Brunot, "Data Set and Reference Models of EMPS", 2019 Workshop on Nonlinear
System Identification Benchmarks).  The Stribeck term is the excess of static over Coulomb
friction, ``(Fs - Fc)·exp(-(v/vs)²)·sign(v)``; its shape velocity ``vs`` is found by a 1-D
search, its amplitude by least squares.  Units are the joint's SI units (m or rad; N or N·m).

:func:`identify_torque_current` fits the torque-vs-current line of the seed report (eq. 9:
effort = effort_per_current·current + effort_offset).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
from scipy import optimize, signal

from .._config import checked_settings, require
from ..errors import InputError
from ..recordings import Recording, resample
from .fit_report import FitResult, failed_fit, linear_fit

log = logging.getLogger(__name__)

MECHANICAL_TERMS = ("inertia", "viscous_friction", "coulomb_friction", "effort_offset", "stribeck_friction")
BASELINE_TERMS = ("inertia", "viscous_friction", "effort_offset")
REFERENCE_TERMS = ("inertia", "viscous_friction", "coulomb_friction", "effort_offset")
STRIBECK_VELOCITY = "stribeck_velocity"


@checked_settings("mechanical settings", cutoff_hz="(0, inf)", filter_order="[1, 8]", decimate="[1, inf)",
                  stribeck_grid="[4, inf)")
class MechanicalSettings:
    """How derivatives are estimated and how the Stribeck velocity is searched.

    ``cutoff_hz``: zero-phase Butterworth cut-off on the position (clipped to 0.8 × Nyquist);
    30 Hz, 4th order reproduces the published EMPS parameters within 1.5 %.  ``trim_s``: time
    dropped at each end of a recording (filter transients; default 3 / cutoff).  ``decimate``:
    keep every k-th sample; the effort is then low-passed by the same filter (parallel filtering).
    ``stribeck_range``: searched ``vs`` as fractions of the 99th percentile of ``|dq|``.
    """

    cutoff_hz: float = 30.0
    filter_order: int = 4
    decimate: int = 1
    trim_s: float | None = None
    stribeck_range: tuple[float, float] = (0.01, 0.5)
    stribeck_grid: int = 24

    def __post_init__(self) -> None:
        src = "mechanical settings"
        require(self.trim_s is None or self.trim_s >= 0, src, "trim_s", self.trim_s, "must be >= 0")
        lo, hi = self.stribeck_range
        require(0 < lo < hi, src, "stribeck_range", self.stribeck_range, "need 0 < low < high")


@dataclasses.dataclass(frozen=True)
class JointKinematics:
    """Filtered position and its derivatives with the effort, on a uniform (decimated) time base."""

    recording: str
    time_s: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    effort: np.ndarray


def _uniform(recording: Recording) -> Recording:
    step = np.diff(recording.time_s)
    dt = float(np.median(step))
    if np.max(np.abs(step - dt)) <= 0.05 * dt:
        return recording
    n = int(np.floor((recording.time_s[-1] - recording.time_s[0]) / dt)) + 1
    log.info("%s: resampled onto a uniform %.4g s grid for filtering", recording.name, dt)
    return resample(recording, recording.time_s[0] + dt * np.arange(n))


def joint_kinematics(recording: Recording, settings: MechanicalSettings | None = None) -> JointKinematics:
    """Zero-phase low-pass of ``position``, central-difference ``velocity``/``acceleration``, trimmed ends."""
    settings = settings or MechanicalSettings()
    recording.require("position", "effort")
    if len(recording) < 3:  # no sample period to filter with
        raise InputError(recording.source or recording.name, "time_s", f"{len(recording)} samples",
                         "too short to filter and differentiate")
    rec = _uniform(recording)
    dt = float(np.median(np.diff(rec.time_s)))
    nyquist = 0.5 / dt
    cutoff = min(settings.cutoff_hz, 0.8 * nyquist)
    b, a = signal.butter(settings.filter_order, cutoff / nyquist)
    pad = 3 * max(len(a), len(b))
    trim = int(round((settings.trim_s if settings.trim_s is not None else 3.0 / cutoff) / dt))
    if len(rec) <= max(pad, 2 * trim + 10):
        raise InputError(rec.source or rec.name, "time_s", f"{len(rec)} samples",
                         f"too short to filter and differentiate (need > {max(pad, 2 * trim + 10)})")
    q = signal.filtfilt(b, a, rec.position)
    dq = np.gradient(q, dt)
    ddq = np.gradient(dq, dt)
    effort = signal.filtfilt(b, a, rec.effort) if settings.decimate > 1 else np.asarray(rec.effort)
    keep = slice(trim, len(rec) - trim, settings.decimate)
    return JointKinematics(rec.name, rec.time_s[keep], q[keep], dq[keep], ddq[keep], effort[keep])


def term_column(term: str, kin: JointKinematics, stribeck_velocity: float | None = None) -> np.ndarray:
    """The regressor column of ``term`` (effort per unit of the term's parameter)."""
    v = kin.velocity
    if term == "inertia":
        return kin.acceleration
    if term == "viscous_friction":
        return v
    if term == "coulomb_friction":
        return np.sign(v)
    if term == "effort_offset":
        return np.ones_like(v)
    if term == "stribeck_friction":
        if stribeck_velocity is None or stribeck_velocity <= 0:
            raise InputError("mechanical model", STRIBECK_VELOCITY, stribeck_velocity, "must be > 0")
        return np.exp(-(v / stribeck_velocity) ** 2) * np.sign(v)
    raise InputError("mechanical model", "term", term, f"unknown; known terms: {', '.join(MECHANICAL_TERMS)}")


def regressor(kins: Sequence[JointKinematics], terms: Sequence[str], stribeck_velocity: float | None = None) -> np.ndarray:
    """Stacked regressor (samples of all ``kins`` × ``terms``)."""
    return np.vstack([np.column_stack([term_column(t, k, stribeck_velocity) for t in terms]) for k in kins])


def predict_effort(parameters: dict, kin: JointKinematics) -> np.ndarray:
    """Effort of the model ``parameters`` (keys: term names, plus stribeck_velocity if needed)."""
    vs = parameters.get(STRIBECK_VELOCITY)
    return sum(parameters[t] * term_column(t, kin, vs) for t in MECHANICAL_TERMS if t in parameters)


def _check_terms(terms: Sequence[str]) -> tuple[str, ...]:
    for term in terms:
        if term not in MECHANICAL_TERMS:
            raise InputError("mechanical model", "term", term, f"unknown; known terms: {', '.join(MECHANICAL_TERMS)}")
    if not terms:
        raise InputError("mechanical model", "terms", "()", "at least one term is needed")
    return tuple(t for t in MECHANICAL_TERMS if t in terms)


def _stribeck_search(kins, terms, y, settings: MechanicalSettings) -> float:
    vmax = float(np.percentile(np.abs(np.concatenate([k.velocity for k in kins])), 99))
    lo, hi = (f * vmax for f in settings.stribeck_range)

    def sse(log_vs: float) -> float:
        X = regressor(kins, terms, float(np.exp(log_vs)))
        p, *_ = np.linalg.lstsq(X, y, rcond=None)
        return float(np.sum((y - X @ p) ** 2))

    grid = np.linspace(np.log(lo), np.log(hi), settings.stribeck_grid)
    costs = [sse(g) for g in grid]
    i = int(np.argmin(costs))
    step = grid[1] - grid[0]
    best = optimize.minimize_scalar(sse, bounds=(max(grid[i] - step, grid[0]), min(grid[i] + step, grid[-1])),
                                    method="bounded", options={"xatol": 1e-3})
    return float(np.exp(best.x if best.fun <= costs[i] else grid[i]))


def fit_kinematics(kins: Sequence[JointKinematics], terms: Sequence[str],
                   settings: MechanicalSettings | None = None, stribeck_velocity: float | None = None) -> FitResult:
    """Least-squares fit of ``terms`` on prepared kinematics (several recordings share the parameters).

    With ``stribeck_friction`` in ``terms`` and no ``stribeck_velocity``, the velocity is searched.
    """
    settings = settings or MechanicalSettings()
    terms = _check_terms(terms)
    y = np.concatenate([k.effort for k in kins])
    time_s = np.concatenate([k.time_s for k in kins])
    model = " + ".join(terms)
    extra = {}
    if "stribeck_friction" in terms:
        if stribeck_velocity is None:
            stribeck_velocity = _stribeck_search(kins, terms, y, settings)
        extra = {STRIBECK_VELOCITY: stribeck_velocity}
    X = regressor(kins, terms, stribeck_velocity)
    if y.size <= len(terms):
        return failed_fit(model, y, "too_few_samples", f"{y.size} samples for {len(terms)} parameters", time_s)
    return linear_fit(X, y, terms, model=model, extra=extra, time_s=time_s)


def identify_mechanical(recordings: Recording | Sequence[Recording], terms: Sequence[str] = REFERENCE_TERMS,
                        settings: MechanicalSettings | None = None) -> FitResult:
    """Identify ``terms`` from recordings with ``position`` and ``effort`` (shared parameters)."""
    recordings = [recordings] if isinstance(recordings, Recording) else list(recordings)
    settings = settings or MechanicalSettings()
    return fit_kinematics([joint_kinematics(r, settings) for r in recordings], terms, settings)


def identify_torque_current(recordings: Recording | Sequence[Recording]) -> FitResult:
    """Seed report eq. 9: ``effort = effort_per_current·current_a + effort_offset`` (needs effort, current_a)."""
    recordings = [recordings] if isinstance(recordings, Recording) else list(recordings)
    for r in recordings:
        r.require("current_a", "effort")
    current = np.concatenate([r.current_a for r in recordings])
    effort = np.concatenate([r.effort for r in recordings])
    X = np.column_stack([current, np.ones_like(current)])
    return linear_fit(X, effort, ("effort_per_current", "effort_offset"),
                      model="effort = effort_per_current * current_a + effort_offset",
                      time_s=np.concatenate([r.time_s for r in recordings]))


def identify_mechanical_files(paths: Sequence[str], terms: Sequence[str] = REFERENCE_TERMS,
                              settings: MechanicalSettings | None = None, columns=None) -> dict:
    """CLI entry (``thermo-ddp identify --physics mechanical``): CSV paths (any columns through the
    column map ``columns``) -> a JSON-ready dict."""
    from ..recordings import read_recordings

    read = read_recordings(paths, columns)
    recordings = list(read.recordings)
    fit = identify_mechanical(recordings, terms, settings)
    return {"physics": "mechanical", "recordings": [r.name for r in recordings], "rows": read.rows, **fit.summary(),
            "stderr": dict(fit.stderr), "n_samples": fit.n_samples,
            "success": fit.success, "status": fit.status, "message": fit.message}
