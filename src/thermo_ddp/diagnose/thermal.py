"""Thermal diagnosis: fit the one-node baseline (seed report eq. 7 with R(T), eq. 5) and every
combination of candidate terms, choose the smallest combination that no larger one beats by a
statistical test, name what the data cannot tell apart, and say so when nothing fits.

Candidates (contract term names) are free, physically bounded parts of the one thermal network
(:func:`thermo_ddp.model.thermal.network_from_parameters`, through :mod:`thermo_ddp.identify.thermal`):

==================  ==========================================================  =========================================
term                physics                                                     parameter file
==================  ==========================================================  =========================================
friction_heating    heat c1 abs(v) + c2 v^2 (free, >= 0; winding of a one-node  ``friction_heat_linear_w_s_per_rad``,
                    network, casing otherwise), not tied to [motor] friction    ``friction_heat_quadratic_w_s2_per_rad2``
drive_heating       idle W + W/A^2 i^2 on the sensor node (one node), or a      ``drive_idle_w``, ``drive_loss_w_per_a2``
                    drive node heating the casing (with the casing node)        (+ ``model = "two_node_drive"``)
casing_node         winding and casing nodes, sensor on the casing (eq. 6)      ``model = "two_node"``
copper_resistance   free temperature coefficient of R(T) (eq. 3)                ``[motor] copper_alpha_per_k``
iron_losses         speed-dependent loss P_ref (abs(v) / 1 rad/s)^2, winding    ``iron_loss_w`` (+ ref speed, exponent)
==================  ==========================================================  =========================================

Selection (:func:`thermo_ddp.diagnose.selection.subset_select`): every subset of the usable
candidates is fitted (output error, multi-start: the best nested fit and the parameter file);
nested likelihood-ratio tests with the effective sample size corrected for the residual
autocorrelation, p < ``alpha`` Bonferroni-corrected for the number of models compared, AND a
relative RMSE drop of at least ``min_rmse_drop``; the smallest adequate set whose every term passes
that test against the set without it wins.  Every fit searches inside the physical ranges of
:func:`term_specs` (iron losses, for instance, cannot exceed the motor class's no-load losses, so
they cannot pose as strong friction heat); parameters the data do not pin down (relative standard
error >= 50 %) and their collinear partners are reported, never used to reject a term.  A casing
node whose fitted winding time constant is shorter than the data's step is not named (it only hosts
the drive node of ``two_node_drive``) and is listed in ``not_determinable``.  With several segments
(recordings, or stretches between gaps) every term of the chosen set is also judged leaving one segment
out (:func:`~thermo_ddp.diagnose.selection.select_held_out`, ``HELD_OUT_RULE``), on the segments that can
judge it: the others hold more samples, reach its speeds and hold every operating regime it spends time in
(else the fold extrapolates), and, when a network has an unmeasured node, it starts at
thermal rest (a fold predicts from the network's equilibrium).  A term whose held-out RMSE there is higher
with it than without, beyond the noise of one reading, is withdrawn (``not_determinable`` says why) and
the selection repeated without it; a tie, or no segment able to judge, is no evidence against it: it
stands on the in-sample test, as with one recording, and ``not_determinable`` says so.  A chosen
running loss on data at one speed is listed in ``not_determinable`` with the experiment at several speeds.

Outcomes: ``ok``; ``model_does_not_fit`` (``success`` false) when even the chosen model's residual
is far above the noise (RMSE over ``max_noise_ratio`` times the high-pass residual noise with the
sensor quantisation), or no fit is admissible; ``insufficient_data`` when the recordings are too
short to fit and cross-validate.  Validation: blocked cross-validation of baseline and final.
"""
from __future__ import annotations

import dataclasses
import itertools
import logging
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from tqdm.auto import tqdm

from .._config import require
from .._figures import new_figure
from .figure import plot_thermal_diagnosis
from ..identify.fit_report import integrated_autocorrelation
from ..identify.thermal import (FRICTION_KEYS, IRON_KEY, SENSOR_DRIVE_KEYS, THERMAL_TERMS, JointParameters, ThermalFit,
                                ThermalModel, canonical_terms, default_fixed, fit_grids, load_joint_parameters,
                                parameter_file, start_values, structure_name)
from ..identify.thermal_data import ThermalGrid, ThermalSettings, split_at_gaps, thermal_grid
from ..model.parameters import HEAT_SOURCE_KINDS, THERMAL_KEYS
from ..recordings import as_recordings, read_recordings
from ._thermal_localise import (ThermalLocaliseSettings, ThermalRegimeSettings, held_window_mean, local_slope,
                                locate_thermal, noise_model, thermal_regimes)
from .localise import Localisation, ResidualSeries
from .selection import HeldOutCheck, SubsetFit, SubsetSelection, SubsetSettings, TermSpec, select_held_out

log = logging.getLogger(__name__)

CANDIDATE_TERMS = THERMAL_TERMS
# Iron-loss bound: at the no-load speed V_bus / (K_b N) (joint side) the iron losses are at most half
# the no-load power V_bus * I_0, with I_0 ~ 0.1 A for 48 V maxon EC-flat/EC-4pole motors of this class
# (datasheets list no-load currents of 0.05-0.3 A; the no-load power also covers bearing friction).
NO_LOAD_CURRENT_A = 0.1
IRON_SHARE_OF_NO_LOAD = 0.5
# Larger motors: a no-load current of 2 % of the rated current (the 0.1 A of a 5 A maxon; traction machines
# lose 1-3 % of their rated power unloaded at rated speed).
NO_LOAD_CURRENT_SHARE = 0.02
# A drive idles at up to 100 W in the Talos class (the elbow's 23 W, report), or at up to 5 times the motor's
# rated copper loss R I_nom^2 for larger drives.
DRIVE_IDLE_SHARE = 5.0
# Speeds: a joint turning slower than this is at rest; moving samples whose speeds lie within this factor
# (5th to 95th percentile) are one speed; a motor moving in this share of the samples never rests.
MOVING_RAD_S = 0.05
ONE_SPEED_SPREAD = 1.25
ALWAYS_MOVING = 0.9
SPEED_TERMS = ("friction_heating", "iron_losses")
# Ranges of capacities and resistances also hold the parameter file's own value within this factor.
FILE_VALUE_FACTOR = 10.0
# The experiment that separates each term from what it can be confused with.
EXPERIMENTS = {
    "friction_heating": "move at two speeds (e.g. 0.5 and 2 rad/s, 20 min each) with a light load, and hold the "
                        "same current still for 20 min next to it",
    "iron_losses": "spin unloaded at 2 rad/s for 10 min with the current near zero (gearbox disengaged if possible), "
                   "then at 1 rad/s: iron losses scale with the motor speed squared, gearbox friction does not",
    "drive_heating": "leave the robot powered and idle (current near zero) for 1 h, then switch the drive off and "
                     "record the cooling for 1 h",
    "casing_node": "current steps (e.g. 8 A for 30 s, 150 s apart) with the motor voltage logged: the winding "
                   "resistance shows the fast winding node the casing sensor smooths out",
    "copper_resistance": "hold two currents (e.g. 3 A and 6 A) until steady with the motor voltage logged",
}
# Without a room thermometer a steady heat on the sensor node and a room warmer than the file's ambient_c are
# one and the same (exactly so for one node): the drive heat is then fitted in every model as the room's
# stand-in, never tested, never named.
ROOM_NOTE = {"term": "drive_heating",
             "reason": "no recording logs the room (ambient_c): a steady heat on the sensor node reads the same as a "
                       "room warmer than the parameter file's ambient_c; fitted in every model as the room's stand-in, "
                       "not named",
             "experiment": "log the room temperature (ambient_c) beside the joint; " + EXPERIMENTS["drive_heating"]}
# How a term is judged leaving one segment out (diagnosis JSON and report).
HELD_OUT_RULE = ("each segment (recording or stretch between gaps) predicted from its first measurement by a fit of "
                 "the other segments; a chosen term is judged on the segments that can judge it: the others hold more "
                 "samples, reach its speeds and hold every operating regime it spends time in (at rest, loaded at "
                 "rest, moving), and, when either network has a node besides the sensor, it starts at thermal rest "
                 "(the prediction starts from the network's equilibrium); a term whose pooled held-out RMSE there is "
                 "higher with it than without, by more than the noise of one reading, is withdrawn; a tie, or no "
                 "segment able to judge, is no evidence against it: it stands on the in-sample test and "
                 "not_determinable says so; validation: the segments every chosen term was judged on")
_CASING_KEYS = ("winding_capacity_j_per_k", "casing_capacity_j_per_k", "winding_casing_k_per_w", "casing_ambient_k_per_w")


def iron_max(params: JointParameters) -> float:
    """Largest physical iron-loss coefficient k [W s^2/rad^2] (joint-side speed), see the constants above."""
    m = params.motor
    no_load_speed = m.bus_voltage_v / (m.back_emf_v_s_per_rad * m.gear_ratio)
    no_load_current = max(NO_LOAD_CURRENT_A, NO_LOAD_CURRENT_SHARE * m.current_nominal_a)
    return IRON_SHARE_OF_NO_LOAD * m.bus_voltage_v * no_load_current / no_load_speed ** 2


def _around_file(params: JointParameters, key: str, low: float, high: float) -> tuple[float, float]:
    """(low, high) widened to hold the parameter file's own value within ``FILE_VALUE_FACTOR`` both ways:
    the class ranges below are the Talos joints'; a file of another motor (a traction machine, a UR3 joint)
    brings its own scale."""
    value = params.thermal.values.get(key)
    if value is None or not value > 0:
        return low, high
    return min(low, value / FILE_VALUE_FACTOR), max(high, value * FILE_VALUE_FACTOR)


def term_specs(params: JointParameters) -> dict[str, TermSpec]:
    """Physical ranges of every term's parameters (inclusive).  Capacities: 0.1-20 kg of aluminium or
    copper (385-900 J/kg/K); resistances: maxon class data, winding-housing 0.5-5 K/W and
    housing-ambient 1-10 K/W, widened; both also hold the file's own values (another motor's scale);
    copper alpha: 0.00393 /K (report eq. 3) +-10 %; heat >= 0 (friction heat is free: no bound from the
    file's friction); drive idle heat and iron losses bounded by the motor's rating (constants above)."""
    def scaled(ranges: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        return {key: _around_file(params, key, *bounds) for key, bounds in ranges.items()}

    m = params.motor
    drive_idle_max_w = max(100.0, DRIVE_IDLE_SHARE * m.resistance_ohm * m.current_nominal_a ** 2)
    casing = scaled({"winding_capacity_j_per_k": (1.0, 1000.0), "casing_capacity_j_per_k": (100.0, 2e4),
                     "winding_casing_k_per_w": (0.05, 10.0), "casing_ambient_k_per_w": (0.1, 20.0)})
    return {
        "one_node": TermSpec("one_node", scaled({"capacity_j_per_k": (100.0, 2e4), "resistance_k_per_w": (0.1, 20.0)})),
        "casing_node": TermSpec("casing_node", casing),
        "drive_heating": TermSpec("drive_heating", {"drive_capacity_j_per_k": (10.0, 1e4),
                                                    "drive_casing_k_per_w": (0.02, 50.0),
                                                    "drive_idle_w": (0.0, drive_idle_max_w),
                                                    "drive_loss_w_per_a2": (0.0, 5.0)}),
        "friction_heating": TermSpec("friction_heating", {k: (0.0, math.inf) for k in FRICTION_KEYS}),
        "copper_resistance": TermSpec("copper_resistance", {"copper_alpha_per_k": (0.0035, 0.0045)}),
        "iron_losses": TermSpec("iron_losses", {IRON_KEY: (0.0, iron_max(params))}),
    }


def term_keys(term: str, terms: Sequence[str]) -> tuple[str, ...]:
    """The parameter-file keys ``term`` decides in the structure ``terms``."""
    if term == "drive_heating":
        return THERMAL_KEYS["two_node_drive"][4:] if "casing_node" in terms else SENSOR_DRIVE_KEYS
    return {"friction_heating": FRICTION_KEYS, "copper_resistance": ("copper_alpha_per_k",),
            "iron_losses": (IRON_KEY,), "casing_node": _CASING_KEYS}[term]


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosisSettings:
    """``cv_blocks``: contiguous held-out segments per recording (validation); ``fit``: grid/optimiser
    settings of every fit (10 s grid: thermal time constants are >= tens of seconds, the held losses
    are averaged exactly); ``selection``: level and effect size of the nested tests;
    ``max_noise_ratio``: the chosen model does not fit when its RMSE exceeds this many noise
    standard deviations; ``max_noise_c``: nor when that noise itself exceeds this (a motor's temperature does
    not jump kelvins between samples: larger "noise" is a wrong column or a broken sensor); ``min_samples`` / ``min_span_s``: less data per recording (on the grid) is
    ``insufficient_data``; ``progress``: tqdm bar over the fits (None: only on a terminal)."""

    cv_blocks: int = 3
    fit: ThermalSettings = ThermalSettings(min_step_s=10.0, max_step_s=10.0)
    regimes: ThermalRegimeSettings = ThermalRegimeSettings()
    localise: ThermalLocaliseSettings = ThermalLocaliseSettings()
    selection: SubsetSettings = SubsetSettings()
    max_noise_ratio: float = 3.0
    max_noise_c: float = 2.0
    min_samples: int = 30
    min_span_s: float = 900.0
    progress: bool | None = None

    def __post_init__(self) -> None:
        name = "thermal diagnosis settings"
        require(isinstance(self.cv_blocks, int) and self.cv_blocks >= 2, name, "cv_blocks", self.cv_blocks, "must be >= 2")
        require(self.max_noise_ratio > 1, name, "max_noise_ratio", self.max_noise_ratio, "must be > 1")
        require(self.max_noise_c > 0, name, "max_noise_c", self.max_noise_c, "must be > 0")
        require(self.min_samples >= 4 * self.cv_blocks, name, "min_samples", self.min_samples,
                f"must be >= 4 cv_blocks = {4 * self.cv_blocks}")
        require(self.min_span_s >= 0, name, "min_span_s", self.min_span_s, "must be >= 0")


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
                 specs: Mapping[str, TermSpec], bar):
        self.params, self.grids, self.settings, self.bar = params, list(grids), settings, bar
        self.bounds = {k: b for spec in specs.values() for k, b in spec.bounds.items()}
        self.fits: dict[frozenset, ThermalFit] = {}
        self._models: dict[frozenset, ThermalModel] = {}
        self._held_out: dict[frozenset, list[np.ndarray]] = {}

    def model(self, terms: frozenset) -> ThermalModel:
        if terms not in self._models:
            ordered = canonical_terms("one_node", terms)
            values = start_values(self.params, ordered)
            self._models[terms] = ThermalModel(self.params, ordered, {k: values[k] for k in default_fixed(ordered)})
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


def _labels(fit: ThermalFit) -> np.ndarray:
    return np.concatenate([[name] * count for name, count in zip(fit.recordings, fit.sample_counts)])


@dataclasses.dataclass(frozen=True)
class RegimeGain:
    """How much of the located mismatch of one regime a term removed."""

    regime: str
    gain: float    # 1 - mean-square residual after / before, inside that regime's mismatch intervals
    share: float   # share of the term's total squared-residual reduction inside mismatches

    def __str__(self) -> str:
        return f"{self.regime} -{100 * self.gain:.0f}% ({100 * self.share:.0f}% of the reduction)"


def regime_gains(before: ThermalFit, after: ThermalFit, localisation: Localisation) -> tuple[RegimeGain, ...]:
    """Per regime of the located mismatches of ``before``: the local gain and share (largest share first)."""
    r0, r1 = before.residuals ** 2, after.residuals ** 2
    names, masks = _labels(before), {}
    for m in localisation.mismatches:
        mask = masks.setdefault(m.regime, np.zeros(r0.size, dtype=bool))
        mask |= (names == m.recording) & (before.time_s >= m.start_s) & (before.time_s <= m.end_s)
    total = sum(float((r0 - r1)[mask].sum()) for mask in masks.values())
    out = [RegimeGain(r, float(1 - r1[mask].mean() / r0[mask].mean()) if r0[mask].mean() > 0 else 0.0,
                      float((r0 - r1)[mask].sum() / total) if total > 0 else 0.0)
           for r, mask in masks.items() if mask.any()]
    return tuple(sorted(out, key=lambda g: -g.share))


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


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosis:
    """Result of :func:`diagnose_thermal`; ``to_dict()`` is the contract's diagnosis JSON plus
    ``parameter_file`` (the improved parameter sections, loadable with ``parameters_from_dict``),
    ``speed_source`` and ``noise``.  ``fits`` holds every fitted term set (empty without data)."""

    recordings: tuple[str, ...]
    params: JointParameters
    grids: tuple[ThermalGrid, ...]
    success: bool
    status: str
    message: str
    rows: Mapping[str, int] = dataclasses.field(default_factory=dict)  # the contract's rows: used, skipped, segments
    regimes: tuple[np.ndarray, ...] = ()
    selection: SubsetSelection | None = None
    fits: Mapping[frozenset, ThermalFit] = dataclasses.field(default_factory=dict)
    localisations: tuple[Localisation, Localisation] | None = None  # baseline, final
    cv_rmse: tuple[float, float] | None = None                      # baseline, final
    noise: Noise | None = None
    not_determinable: tuple[dict, ...] = ()
    cv_blocks: int = 3
    hosted: frozenset = frozenset()  # in the final structure, not evidenced by the data (not named)
    baseline_terms: frozenset = frozenset()  # in every fitted set, never tested (the room's stand-in, see ROOM_NOTE)
    held_out: Mapping[str, HeldOutCheck] = dataclasses.field(default_factory=dict)  # leave one segment out, per term
    segment_cv: tuple[float, float, tuple[str, ...]] | None = None  # leave one segment out: baseline, final, segments

    @property
    def final_terms(self) -> frozenset:
        return self.selection.chosen.terms if self.selection is not None else frozenset()

    @property
    def baseline_fit(self) -> ThermalFit | None:
        return self.fits.get(self.baseline_terms)

    @property
    def final_fit(self) -> ThermalFit | None:
        return self.fits.get(self.final_terms)

    @property
    def missing_physics(self) -> list[str]:
        """The named terms: the chosen set without the terms it only hosts (see :func:`_hosted`)."""
        return [t for t in THERMAL_TERMS if t in self.final_terms - self.baseline_terms and t not in self.hosted]

    @property
    def explained(self) -> dict[str, tuple[RegimeGain, ...]]:
        """Per named term: the baseline mismatch it removes (the final set against the final set without it)."""
        if self.localisations is None:
            return {}
        return {t: regime_gains(self.fits[self.final_terms - {t}], self.final_fit, self.localisations[0])
                for t in self.missing_physics if self.final_terms - {t} in self.fits}

    def parameter_file(self) -> dict | None:
        if self.final_fit is None or not self.final_fit.success:
            return None
        return parameter_file(self.params, self.final_fit, self.recordings)

    def term_report(self, term: str) -> dict:
        """The contract's ``missing_physics`` entry of a named term."""
        fit, test = self.final_fit, self.selection.term_tests[term]
        without = self.fits[self.final_terms - {term}]
        keys = [k for k in term_keys(term, canonical_terms("one_node", self.final_terms)) if k in fit.parameters]
        collinear = sorted({c for k in keys for c in fit.collinear(k)})
        where = "; ".join(str(g) for g in self.explained.get(term, ()) if g.gain > 0) or "no located mismatch"
        evidence = (f"{structure_name(canonical_terms('one_node', self.final_terms - {term}))} -> {fit.model}: "
                    f"RMSE {without.rmse:.3g} -> {fit.rmse:.3g} K (-{100 * test.rmse_drop:.0f}%), likelihood ratio "
                    f"{test.statistic:.1f} on {test.df} df, p = {test.p_value:.2g} ({self.selection.n_tests} models "
                    f"compared, effective samples n/tau = {test.large.n / test.large.tau:.0f}); explains {where}")
        if term in self.held_out:
            evidence += f"; leaving one segment out: {self.held_out[term]}"
        if term == "friction_heating":
            evidence += "; " + self._friction_ratio(fit)
        return {"term": term, "evidence": evidence,
                "parameters": {k: float(fit.parameters[k]) for k in keys}, "rmse": fit.rmse,
                "p_value": test.p_value, "effect_k": float(np.sqrt(np.mean((fit.fitted - without.fitted) ** 2))),
                "ci95": {k: [float(v) for v in fit.confidence[k]] for k in keys if k in fit.confidence},
                "collinear_with": collinear}

    def _friction_ratio(self, fit: ThermalFit) -> str:
        """Information only: the fitted friction heat against the file's friction power."""
        m = self.params.motor
        c1, c2 = (fit.parameters[k] for k in FRICTION_KEYS)

        def ratio(heat: float, friction: float) -> str:
            return f"{heat / friction:.2f}" if friction > 0 else "n/a (the file has none)"
        return (f"friction heat / the file's friction power: c1 / coulomb = {ratio(c1, m.coulomb_friction_nm)}, "
                f"c2 / viscous = {ratio(c2, m.viscous_friction_nm_s_per_rad)} (information, not a bound)")

    def to_dict(self) -> dict:
        base, final = self.baseline_fit, self.final_fit
        out = {"success": self.success, "status": self.status, "message": self.message, "physics": "thermal",
               "recordings": list(self.recordings),
               "rows": dict(self.rows),
               "speed_source": {g.name: g.speed_source for g in self.grids},
               "baseline": base.summary() if base is not None else None,
               "mismatches": self.localisations[0].to_list() if self.localisations else [],
               "missing_physics": [self.term_report(t) for t in self.missing_physics],
               "not_determinable": list(self.not_determinable),
               "final": final.summary() if final is not None else None,
               "validation": None, "unexplained": self.localisations[1].to_list() if self.localisations else [],
               "noise": dataclasses.asdict(self.noise) if self.noise is not None else None,
               "parameter_file": self.parameter_file()}
        if self.cv_rmse is not None:
            out["validation"] = {"method": f"blocked cross-validation: {self.cv_blocks} contiguous segments per "
                                           "recording, each predicted (open-loop simulation) by a fit that did not "
                                           "see it (held-out RMSE)",
                                 "rmse_before": self.cv_rmse[0], "rmse_after": self.cv_rmse[1]}
        if self.segment_cv is not None:
            out["validation"]["leave_one_segment_out"] = {
                "method": HELD_OUT_RULE,
                "segments": list(self.segment_cv[2]), "rmse_before": self.segment_cv[0], "rmse_after": self.segment_cv[1],
                "terms": {t: {"rmse_with": c.with_term, "rmse_without": c.without, "verdict": c.verdict,
                              "tie_c": c.tie_c, "named": t in self.missing_physics}
                          for t, c in self.held_out.items() if c.verdict != "undecided"},
                "undecided": {t: c.undecided for t, c in self.held_out.items() if c.verdict == "undecided"}}
        return out

    def report(self) -> str:
        lines = [f"thermal diagnosis of {', '.join(self.recordings)}: {self.status} ({self.message})"]
        if self.selection is None:
            return "\n".join(lines + [f"  not determinable: {d['term']}: {d['reason']}" for d in self.not_determinable])
        base, final = self.baseline_fit, self.final_fit
        lines.append(f"baseline {base.model}: rmse {base.rmse:.4g} K, {len(self.localisations[0].mismatches)} "
                     f"mismatch intervals ({', '.join(sorted({m.regime for m in self.localisations[0].mismatches})) or 'none'})")
        for f in sorted(self.selection.fits, key=lambda f: (len(f.terms), f.rss)):
            mark = "CHOSEN" if f is self.selection.chosen else ("" if f.admissible else f.reason)
            lines.append(f"  {self.fits[f.terms].model:<55s} rmse {f.rmse:.4g} K, tau {f.tau:.1f}  {mark}")
        lines += [f"  {t}: {self.term_report(t)['evidence']}" for t in self.missing_physics]
        lines += [f"  not determinable: {d['term']}: {d['reason']}" for d in self.not_determinable]
        lines += [f"final {final.model}: rmse {final.rmse:.4g} K = {self.noise.rmse_ratio:.2f} x noise "
                  f"({self.noise.total_c:.3g} K); held-out rmse {self.cv_rmse[0]:.4g} -> {self.cv_rmse[1]:.4g} K; "
                  f"{len(self.localisations[1].mismatches)} unexplained intervals"]
        if self.segment_cv is not None:
            lines.append(f"leave one segment out: held-out rmse {self.segment_cv[0]:.4g} -> {self.segment_cv[1]:.4g} K")
        if self.held_out:
            lines += [f"  held out, {t}: {c.verdict}, {c}" for t, c in sorted(self.held_out.items())]
            lines.append(f"  rule: {HELD_OUT_RULE}")
        lines.append(final.fit_report())
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 3) -> Path:
        """Measured, baseline and final sensor temperature; residuals with mismatch intervals shaded;
        current and speed."""
        path, base, final = Path(path), self.baseline_fit, self.final_fit
        grids = self.grids[:max_recordings]
        fig, axes = new_figure(3, len(grids), figsize=(9 * len(grids), 9), sharex="col", squeeze=False)
        for c, grid in enumerate(grids):
            t, ax = grid.time_s, axes[:, c]
            ax[0].plot(t, grid.measured_c, "k.", ms=1.5, label="recorded (sensor)")
            for fit, name in ((base, "baseline"), (final, "final")):
                if fit is not None:
                    rows = fit.rows(grid.name)
                    ax[0].plot(t, fit.fitted[rows], lw=1.0, label=f"{name} {fit.model}")
                    ax[1].plot(t, fit.residuals[rows], lw=0.6, label=f"{name}, rmse {fit.rmse:.3g} K")
            for loc, color in zip(self.localisations or (), ("red", "grey")):
                for m in loc.mismatches:
                    if m.recording == grid.name:
                        ax[1].axvspan(m.start_s, m.end_s, color=color, alpha=0.2, lw=0)
                        ax[1].text(0.5 * (m.start_s + m.end_s), 0, m.regime, fontsize=7, ha="center", color=color)
            ax[2].plot(t, np.sqrt(held_window_mean(grid, 1, 30.0)), lw=0.8, label="RMS current over 60 s [A]")
            ax[2].plot(t, np.sqrt(held_window_mean(grid, 3, 30.0)), lw=0.8,
                       label=f"RMS speed over 60 s [rad/s] (from {grid.speed_source})")
            ax[0].set(title=f"{grid.name}: {self.status}", ylabel="temperature [°C]")
            ax[1].set(ylabel="residual [K] (red: mismatch, grey: unexplained)")
            ax[2].set(xlabel="time [s]")
            for a in ax:
                a.legend(fontsize=8, loc="best")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        return path


def _usable_candidates(candidates: Sequence[str], grids: Sequence[ThermalGrid],
                       allowed: Sequence[str]) -> tuple[list[str], list[dict]]:
    """The candidates these data can test; a heat source the motor cannot have ([hardware] heat_sources,
    ``allowed``) is never named."""
    usable, skipped = [], []
    moving = any(g.has_velocity and np.any(np.abs(g.velocity) > MOVING_RAD_S) for g in grids)
    for term in candidates:
        require(term in THERMAL_TERMS, "diagnose", "term", term, f"unknown; known: {', '.join(THERMAL_TERMS)}")
        if term in HEAT_SOURCE_KINDS and term not in allowed:
            continue
        if term in SPEED_TERMS and not moving:
            skipped.append({"term": term, "reason": "no recording has a velocity (or position) showing motion",
                            "experiment": EXPERIMENTS[term]})
        else:
            usable.append(term)
    return usable, skipped


def _too_short(grids: Sequence[ThermalGrid], settings: ThermalDiagnosisSettings) -> str:
    count, span = sum(len(g) for g in grids), max((float(g.time_s[-1] - g.time_s[0]) for g in grids), default=0.0)
    if count < settings.min_samples or span < settings.min_span_s:
        return (f"{', '.join(g.name for g in grids)}: {count} samples on the {settings.fit.min_step_s:g} s grid, "
                f"longest stretch {span:.0f} s; a diagnosis needs at least {settings.min_samples} samples and a "
                f"stretch of {settings.min_span_s:g} s (thermal time constants are minutes)")
    return ""


def _undetermined(selection: SubsetSelection, fits: Mapping[frozenset, ThermalFit]) -> list[dict]:
    """What these data cannot tell apart: equally good term sets, and named terms whose parameters
    are not identifiable."""
    out, chosen = [], selection.chosen
    for other in selection.equivalent:
        for term in sorted(other.terms ^ chosen.terms):
            out.append({"term": term, "reason": f"{fits[other.terms].model} fits as well as {fits[chosen.terms].model} "
                                                f"(RMSE {other.rmse:.3g} vs {chosen.rmse:.3g} K)",
                        "experiment": EXPERIMENTS[term]})
    final = fits[chosen.terms]
    for term in sorted(chosen.terms):
        loose = [k for k in term_keys(term, canonical_terms("one_node", chosen.terms))
                 if k in final.stderr and not final.identifiable(k)]
        if loose:
            partners = sorted({c for k in loose for c in final.collinear(k)})
            out.append({"term": term, "reason": f"needed, but {', '.join(loose)} not identifiable from these data"
                                                + (f" (collinear with {', '.join(partners)})" if partners else ""),
                        "experiment": EXPERIMENTS[term]})
    return out


def _held_out_notes(checks: Mapping[str, HeldOutCheck], named: frozenset) -> list[dict]:
    """Terms a held-out segment predicts worse with than without: withdrawn, not claimed.  Named terms the
    held-out segments could not judge (undecided, or a tie within the noise): claimed on the in-sample test
    alone, and said so."""
    out = []
    for t, c in sorted(checks.items()):
        if c.withdraws:
            reason = (f"lowers the residual of the data it is fitted on, not the error on unseen data (leave one "
                      f"segment out: {c}): not claimed, and not in the final model")
        elif t in named and not c.improves:
            reason = (f"named on the in-sample test alone: leaving one segment out cannot confirm it ({c}); "
                      "nothing held out speaks against it either")
        else:
            continue
        out.append({"term": t, "reason": reason, "experiment": EXPERIMENTS[t]})
    return out


def _one_speed(grids: Sequence[ThermalGrid], chosen: frozenset) -> list[dict]:
    """At one speed (``ONE_SPEED_SPREAD``) a loss that grows with the speed is a constant: each chosen
    speed-dependent term is listed, and the drive's constant heat too when the motor never rests
    (``ALWAYS_MOVING``: then nothing separates a running loss from a heat that is always on)."""
    speeds = np.abs(np.concatenate([g.velocity for g in grids if g.has_velocity] or [np.zeros(0)]))
    moving = speeds[speeds > MOVING_RAD_S]
    if moving.size < 2:
        return []
    low, mid, high = np.percentile(moving, [5, 50, 95])
    always = moving.size >= ALWAYS_MOVING * speeds.size
    named = [t for t in SPEED_TERMS if t in chosen]
    named += ["drive_heating"] if always and "drive_heating" in chosen else []
    if not named or high > ONE_SPEED_SPREAD * low:
        return []
    reason = (f"the motor turns at one speed ({mid:.4g} rad/s; 90 % of the moving samples within {low:.4g}-"
              f"{high:.4g} rad/s, {100 * moving.size / speeds.size:.0f} % of the samples moving): a loss that grows "
              "with the speed (friction heat c1 |w| + c2 w^2, iron losses k w^2) is a constant here, so how it grows "
              "cannot be told" + (", nor a running loss from a heat that is always on (a drive's idle loss)"
                                  if always else "") + "; the named {} is one reading of it")
    experiment = (f"the same currents at two or more speeds (e.g. {0.4 * mid:.3g} and {mid:.3g} rad/s, each until "
                  "the temperature settles): a speed-dependent loss changes with the speed, a constant one does not")
    return [{"term": t, "reason": reason.format(t), "experiment": experiment} for t in named]


def _hosted(fit: ThermalFit, grids: Sequence[ThermalGrid]) -> tuple[frozenset, list[dict]]:
    """A casing node whose winding time constant C_w R_wc is shorter than the grid's step is not
    evidenced: the data cannot resolve it.  It stays in the structure when the drive node needs it (the
    contract's drive node sits on the casing) but is not named."""
    p = fit.parameters
    if "casing_node" not in fit.terms:
        return frozenset(), []
    tau_s = p["winding_capacity_j_per_k"] * p["winding_casing_k_per_w"]
    step_s = float(np.median(np.concatenate([np.diff(g.time_s) for g in grids])))
    if tau_s >= step_s:
        return frozenset(), []
    return frozenset({"casing_node"}), [{
        "term": "casing_node", "experiment": EXPERIMENTS["casing_node"],
        "reason": f"fitted winding time constant C_w R_wc = {tau_s:.1f} s, below the {step_s:.0f} s step of the "
                  "data: no casing node is evidenced (kept in the structure only to host the drive node)"}]


def diagnose_thermal(recordings, *, parameters: JointParameters | str | Path | None = None,
                     candidates: Sequence[str] = CANDIDATE_TERMS,
                     settings: ThermalDiagnosisSettings | None = None) -> ThermalDiagnosis:
    """Diagnose recordings (``current_a`` + ``temperature_c``; ``velocity`` or ``position`` for the
    speed-dependent terms; ``ambient_c`` if logged) against the one-node baseline (module docstring)."""
    settings = settings or ThermalDiagnosisSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "thermal")
    for rec in recs:
        rec.require("current_a", "temperature_c")
    split = [split_at_gaps(r) for r in recs]
    grids = tuple(thermal_grid(part, params, settings.fit) for parts, _ in split for part in parts)
    names = tuple(r.name for r in recs)
    rows = {"used": sum(len(p) for parts, _ in split for p in parts), "skipped": sum(n for _, n in split),
            "segments": len(grids)}
    short = _too_short(grids, settings)
    if short:
        return ThermalDiagnosis(names, params, grids, False, "insufficient_data", short, rows=rows,
                                cv_blocks=settings.cv_blocks)
    usable, skipped = _usable_candidates(candidates, grids, params.scope.allowed_sources)
    base = frozenset()
    if "drive_heating" in usable and not any(g.has_ambient for g in grids):
        usable.remove("drive_heating")
        base = frozenset({"drive_heating"})
        skipped.append(ROOM_NOTE)
    regimes = tuple(thermal_regimes(g, settings.regimes) for g in grids)
    specs = term_specs(params)
    hide = None if settings.progress is None else not settings.progress
    with tqdm(desc="thermal diagnosis fits", unit="fit", disable=hide) as bar:
        fitter = _Fitter(params, grids, settings, specs, bar)
        sets = [frozenset(c) | base for k in range(len(usable) + 1) for c in itertools.combinations(usable, k)]
        if base:  # the plain one-node fit starts the baseline's (from the file's values alone it can stall far off)
            fitter.fit(frozenset())
        for terms in sets:
            fitter.fit(terms)
        several = len(grids) > 1
        selection, held_out = select_held_out([fitter.subset(t) for t in sets], fitter.held_out if several else None,
                                              base, settings.selection)
        cv = segment_cv = None
        if selection is not None:
            fitter.polish(selection.chosen.terms)
            cv = (fitter.cv_rmse(base), fitter.cv_rmse(selection.chosen.terms))
            judged = [r for r, g in enumerate(grids) if all(g.name in c.segments for c in held_out.values()
                                                              if c.term in selection.chosen.terms)]
            if several and judged:  # the segments every chosen term was judged on (all when none was)
                segment_cv = (fitter.segment_rmse(base, judged), fitter.segment_rmse(selection.chosen.terms, judged),
                              tuple(grids[r].name for r in judged))
    fits = dict(fitter.fits)
    if selection is None:
        return ThermalDiagnosis(names, params, grids, False, "model_does_not_fit",
                                "no candidate model converged within physical bounds", rows, regimes, None, fits,
                                not_determinable=tuple(skipped), cv_blocks=settings.cv_blocks, baseline_terms=base)
    final = fits[selection.chosen.terms]
    locs = tuple(locate_thermal(_series(f, grids, regimes), settings.localise) for f in (fits[base], final))
    noise = _noise(final, grids, settings.localise.noise_window_s)
    fitting = noise.rmse_ratio <= settings.max_noise_ratio and noise.total_c <= settings.max_noise_c
    message = (f"{final.model}: rmse {final.rmse:.3g} K = {noise.rmse_ratio:.2f} x the residual noise "
               f"{noise.total_c:.3g} K")
    hosted, unresolved = _hosted(final, grids)
    if noise.rmse_ratio > settings.max_noise_ratio:
        message += f" (> {settings.max_noise_ratio:g}): a systematic error that no candidate explains"
        if selection.chosen.terms - base - hosted:
            message += (f"; the terms named lower the held-out RMSE from {cv[0]:.3g} to {cv[1]:.3g} K, what is left "
                        "needs physics beyond the candidates (more thermal nodes, another heat source)")
    elif not fitting:
        message += (f", above {settings.max_noise_c:g} K: the temperature jumps between samples as no thermal "
                    "network does (a wrong column or a broken sensor?); nothing here can be diagnosed")
    return ThermalDiagnosis(names, params, grids, fitting, "ok" if fitting else "model_does_not_fit", message,
                            rows, regimes, selection, fits, locs, cv, noise,
                            tuple(skipped) + tuple(unresolved)
                            + tuple(_held_out_notes(held_out, selection.chosen.terms - base - hosted))
                            + tuple(_undetermined(selection, fits)) + tuple(_one_speed(grids, selection.chosen.terms - base)),
                            settings.cv_blocks, hosted, base, held_out, segment_cv)


def diagnose_thermal_files(paths: Sequence[str | Path], plot: str | Path | None = None, columns=None,
                           **options) -> dict:
    """CLI entry: CSV recording paths (any columns through the column map ``columns``; ``parameters``:
    the parameter file) -> the diagnosis dict with ``rows`` (optionally a plot file)."""
    if options.get("parameters") is not None:
        options["parameters"] = load_joint_parameters(options["parameters"])  # refused before reading data
    recordings = read_recordings(paths, columns)
    diagnosis = diagnose_thermal(list(recordings.recordings), **options)
    if plot is not None:
        plot_thermal_diagnosis(diagnosis, plot)
    return diagnosis.to_dict() | {"rows": recordings.rows}


__all__ = ["CANDIDATE_TERMS", "EXPERIMENTS", "ThermalDiagnosis", "ThermalDiagnosisSettings", "diagnose_thermal",
           "diagnose_thermal_files", "iron_max", "term_keys", "term_specs"]
