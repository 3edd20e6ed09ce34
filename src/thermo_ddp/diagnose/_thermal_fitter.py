"""Fits of the thermal diagnosis: term sets (multi-start), blocked and leave-one-segment-out
cross-validation, which segments can judge a term, and the residual noise."""
from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from ..identify.fit_report import integrated_autocorrelation
from ..identify.thermal import (JointParameters, ThermalFit, ThermalModel, canonical_terms, default_fixed, fit_grids,
                                start_values)
from ..identify.thermal_data import ThermalGrid
from ._thermal_localise import ThermalRegimeSettings, local_slope, noise_model
from .localise import ResidualSeries
from .selection import HeldOutCheck, SubsetFit, TermSpec

if TYPE_CHECKING:
    from .thermal import ThermalDiagnosisSettings


def _blocks(grids: Sequence[ThermalGrid], n_blocks: int) -> list[np.ndarray]:
    """Contiguous time blocks per recording (ids r * n_blocks + b)."""
    out = []
    for r, g in enumerate(grids):
        frac = (g.time_s - g.time_s[0]) / max(g.time_s[-1] - g.time_s[0], 1e-9)
        out.append(r * n_blocks + np.minimum((frac * n_blocks).astype(int), n_blocks - 1))
    return out


def _tau(fit: ThermalFit) -> float:
    """Pooled integrated autocorrelation time: n / sum over recordings of n_r / tau_r."""
    parts = [fit.residuals[fit.rows(name)] for name in fit.recordings]
    return fit.n_samples / sum(r.size / integrated_autocorrelation(r) for r in parts)


class _Fitter:
    """Fits of term sets (multi-start), their admissibility and blocked cross-validation."""

    def __init__(self, params: JointParameters, grids: Sequence[ThermalGrid], settings: ThermalDiagnosisSettings,
                 specs: Mapping[str, TermSpec], bar, room_stand_in: bool = False):
        self.params, self.grids, self.settings, self.bar = params, list(grids), settings, bar
        self.room_stand_in = room_stand_in  # the drive term stands in for an unlogged room (default_fixed)
        self.bounds = {k: b for spec in specs.values() for k, b in spec.bounds.items()}
        self.fits: dict[frozenset, ThermalFit] = {}
        self._models: dict[frozenset, ThermalModel] = {}
        self._held_out: dict[frozenset, list[np.ndarray]] = {}

    def model(self, terms: frozenset) -> ThermalModel:
        if terms not in self._models:
            ordered = canonical_terms("one_node", terms)
            values = start_values(self.params, ordered)
            self._models[terms] = ThermalModel(self.params, ordered, {k: values[k] for k in default_fixed(ordered, self.room_stand_in)})
        return self._models[terms]

    def fit(self, terms: frozenset) -> ThermalFit:
        """Best of the starts: the best fitted set with one term less, and the parameter file's when
        there is no such set or the network gains a node (a new node's split is not in the parent)."""
        model = self.model(terms)
        parents = [self.fits[terms - {t}] for t in terms if self.fits.get(terms - {t}) is not None]
        parents = [f for f in parents if self.usable(f)]
        starts = []
        if parents:
            parent = min(parents, key=lambda f: f.rmse)
            starts.append((start_values(self.params, model.terms, previous=parent.parameters),
                           [parent.initial_offset_c[g.name] for g in self.grids]))
        if not parents or all(f.nodes != model.nodes for f in parents):
            starts.append((start_values(self.params, model.terms), None))
        fits = []
        for start, offsets in starts:
            fits.append(fit_grids(model, self.grids, start=start, offsets=offsets, settings=self.settings.fit,
                                  bounds=self.bounds))
            self.bar.update(1)
        self.fits[terms] = min(fits, key=lambda f: (not self.usable(f), f.rmse))
        return self.fits[terms]

    @staticmethod
    def usable(fit: ThermalFit) -> bool:
        """Converged, or stopped by its evaluation budget: a real residual (an upper bound of the optimum's)."""
        return fit.success or (fit.status == "max_iterations" and bool(np.all(np.isfinite(fit.residuals))))

    def subset(self, terms: frozenset) -> SubsetFit:
        fit = self.fits[terms]
        reason = "" if self.usable(fit) else f"fit failed: {fit.status}: {fit.message}"
        return SubsetFit(terms, float(fit.residuals @ fit.residuals), fit.n_samples,
                         len(fit.stderr) + len(self.grids), _tau(fit), not reason, reason)

    def polish(self, terms: frozenset) -> ThermalFit:
        """The chosen set refitted from its values with four times the budget when its fit ran out of it."""
        fit = self.fits[terms]
        if fit.status == "max_iterations":
            more = dataclasses.replace(self.settings.fit, max_nfev=4 * self.settings.fit.max_nfev)
            again = fit_grids(self.model(terms), self.grids, start=dict(fit.parameters), settings=more,
                              offsets=[fit.initial_offset_c[g.name] for g in self.grids], bounds=self.bounds)
            self.bar.update(1)
            self.fits[terms] = min((fit, again), key=lambda f: (not f.success, f.rmse))
        return self.fits[terms]

    def cv_rmse(self, terms: frozenset) -> float:
        """Held-out RMSE: each contiguous block predicted (open-loop) by a fit that did not see it."""
        full = self.fits[terms]
        model = self.model(terms)
        blocks = _blocks(self.grids, self.settings.cv_blocks)
        every = np.concatenate(blocks)
        cv = np.array(full.residuals, float)
        offsets = [full.initial_offset_c[g.name] for g in self.grids]
        for b in np.unique(every):
            weights = [(blk != b).astype(float) for blk in blocks]
            held = fit_grids(model, self.grids, start=dict(full.parameters), offsets=offsets, weights=weights,
                             settings=self.settings.fit, bounds=self.bounds)
            self.bar.update(1)
            cv[every == b] = held.residuals[every == b]
        return float(np.sqrt(np.mean(cv ** 2)))

    def folds(self, terms: frozenset) -> list[np.ndarray]:
        """Leave one segment out: the residuals of each segment (a recording, or a stretch between gaps)
        predicted open-loop from its own first measurements by a fit of the other segments (inf when that
        fit is not usable)."""
        if terms not in self._held_out:
            full, model = self.fits[terms], self.model(terms)
            offsets = [full.initial_offset_c[g.name] for g in self.grids]
            ends, out = np.cumsum([0] + [len(g) for g in self.grids]), []
            for r in range(len(self.grids)):
                weights = [np.full(len(g), float(k != r)) for k, g in enumerate(self.grids)]
                held = fit_grids(model, self.grids, start=dict(full.parameters), offsets=offsets, weights=weights,
                                 settings=self.settings.fit, bounds=self.bounds)
                self.bar.update(1)
                out.append(held.residuals[ends[r]:ends[r + 1]] if self.usable(held) else np.array([np.inf]))
            self._held_out[terms] = out
        return self._held_out[terms]

    def segment_rmse(self, terms: frozenset, segments: Sequence[int] | None = None) -> float:
        """Pooled leave-one-segment-out RMSE over ``segments`` (all by default)."""
        folds = self.folds(terms)
        chosen = range(len(folds)) if segments is None else segments
        return float(np.sqrt(np.mean(np.concatenate([folds[r] for r in chosen]) ** 2)))

    def covered(self, r: int) -> str:
        """Why a fit of the other segments extrapolates to segment ``r`` ('' when it does not): they must hold at
        least as many samples, reach its speeds (95th percentile of |v|), and hold at least ``min_samples`` of
        every operating regime (at rest, loaded at rest, moving) it holds that many of."""
        grid, s, least = self.grids[r], self.settings.regimes, self.settings.min_samples
        others = [g for k, g in enumerate(self.grids) if k != r]
        if sum(len(g) for g in others) < len(grid):
            return f"the other segments hold fewer samples than {grid.name}"
        if _p95(grid.velocity) > max(_p95(g.velocity) for g in others):
            return f"the other segments do not reach the speeds of {grid.name}"
        mine, theirs = _operating(grid, s), np.sum([_operating(g, s) for g in others], axis=0)
        unseen = [name for name, n, m in zip(("at rest", "loaded at rest", "moving"), mine, theirs) if n >= least > m]
        return f"the other segments hold no {'/'.join(unseen)} stretch like {grid.name}'s" if unseen else ""

    def unsettled(self, r: int) -> str:
        """Why segment ``r`` does not start at thermal rest ('' when it does: its temperature trend at the start
        within the regimes' ``trend_k_per_h``).  A fold predicts it from the network's equilibrium under its
        first inputs: an unmeasured node then starts wherever that equilibrium puts it, not where it was."""
        grid, s = self.grids[r], self.settings.regimes
        trend = 3600.0 * abs(float(local_slope(grid.time_s, grid.measured_c, s.trend_window_s)[0]))
        return f"{grid.name} starts {trend:.2g} K/h away from rest" if trend > s.trend_k_per_h else ""

    def held_out(self, term: str, with_term: frozenset, without: frozenset) -> HeldOutCheck:
        """Leave-one-segment-out RMSE of both sets pooled over the segments that can judge: covered
        (:meth:`covered`) and, when either network has a node besides the sensor, settled at the start
        (:meth:`unsettled`); differences within the noise of one reading of the set with the term are ties."""
        hidden = any(len(self.model(terms).nodes) > 1 for terms in (with_term, without))
        why = {r: self.covered(r) or (self.unsettled(r) if hidden else "") for r in range(len(self.grids))}
        segments = [r for r, reason in why.items() if not reason]
        if not segments:
            return HeldOutCheck(term, undecided="; ".join(why.values()))
        scores = tuple(self.segment_rmse(terms, segments) for terms in (with_term, without))
        if not all(map(math.isfinite, scores)):
            return HeldOutCheck(term, undecided="a fit of the other segments did not converge")
        tie = _noise(self.fits[with_term], self.grids, self.settings.localise.noise_window_s).total_c
        return HeldOutCheck(term, *scores, tie, tuple(self.grids[r].name for r in segments))


def _p95(values: np.ndarray) -> float:
    return float(np.percentile(np.abs(values), 95))


def _operating(grid: ThermalGrid, settings: ThermalRegimeSettings) -> np.ndarray:
    """Samples at rest, loaded at rest and moving (the regimes' current and speed thresholds)."""
    moving = np.abs(grid.velocity) > settings.moving_rad_s
    loaded = ~moving & (np.abs(grid.current_a) > settings.load_a)
    return np.array([np.sum(~moving & ~loaded), np.sum(loaded), np.sum(moving)])



@dataclasses.dataclass(frozen=True)
class Noise:
    """Noise of the chosen model's residual: high-pass scale, sensor quantum, and the RMSE ratio."""

    sigma_c: float
    quantum_c: float
    rmse_ratio: float

    @property
    def total_c(self) -> float:
        return math.sqrt(self.sigma_c ** 2 + self.quantum_c ** 2 / 12)


def _quantum(grids: Sequence[ThermalGrid]) -> float:
    """The sensor's quantisation step: the smallest change between successive readings when the readings
    lie on a lattice of it (0 for continuous readings)."""
    steps = np.concatenate([np.abs(np.diff(g.measured_c)) for g in grids])
    steps = steps[steps > 1e-9]
    if not steps.size:
        return 0.0
    q = float(steps.min())
    return q if np.all(np.abs(steps / q - np.round(steps / q)) < 0.05) else 0.0


def _noise(fit: ThermalFit, grids: Sequence[ThermalGrid], window_s: float) -> Noise:
    sigma = math.sqrt(np.mean([noise_model(s, window_s).sigma_c ** 2 for s in _series(fit, grids)]))
    quantum = _quantum(grids)
    total = math.sqrt(sigma ** 2 + quantum ** 2 / 12)
    return Noise(sigma, quantum, fit.rmse / total if total > 0 else math.inf)


def _series(fit: ThermalFit, grids: Sequence[ThermalGrid], regimes: Sequence[np.ndarray] | None = None):
    return [ResidualSeries(g.name, g.time_s, fit.residuals[fit.rows(g.name)],
                           regimes[k] if regimes is not None else np.full(len(g), "any"))
            for k, g in enumerate(grids)]

