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
drive_heating       idle W + W/A^2 i^2 on the sensor node (one node; the i^2    ``drive_idle_w``, ``drive_loss_w_per_a2``
                    loss held: the copper's twin), or a drive node heating the  (+ ``model = "two_node_drive"``)
                    casing (with the casing node)
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
running loss on data at one speed is listed in ``not_determinable`` with the experiment at several speeds; so are
the speed terms on data that carry current only while moving (seen in one regime: :func:`_one_regime`).

Outcomes: ``ok``; ``model_does_not_fit`` (``success`` false) when even the chosen model's residual
is far above the noise (RMSE over ``max_noise_ratio`` times the high-pass residual noise with the
sensor quantisation), or no fit is admissible; ``insufficient_data`` when the recordings are too
short to fit and cross-validate.  Validation: blocked cross-validation of baseline and final.
"""
from __future__ import annotations

import dataclasses
import itertools
import logging
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from tqdm import tqdm

from .._config import require
from ..envelope import envelope_of
from ..identify.thermal import THERMAL_TERMS, JointParameters, ThermalFit, canonical_terms, load_joint_parameters
from ..identify.thermal_data import ThermalGrid, ThermalSettings, split_at_gaps, thermal_grid
from ..model.parameters import HEAT_SOURCE_KINDS
from ..recordings import as_recordings, read_recordings
from ._thermal_fitter import _Fitter, _noise, _series
from ._thermal_localise import ThermalLocaliseSettings, ThermalRegimeSettings, locate_thermal, thermal_regimes
from ._thermal_result import ThermalDiagnosis
from ._thermal_terms import (ALWAYS_MOVING, CANDIDATE_TERMS, MOVING_RAD_S, ONE_SPEED_SPREAD, experiments, room_note,
                             SPEED_TERMS, iron_max, term_keys, term_specs)
from .growth import GrowthSettings
from .network_diagnosis import NetworkDiagnosis, diagnose_network
from .selection import HeldOutCheck, SubsetSelection, SubsetSettings, select_held_out

log = logging.getLogger(__name__)
PROPORTION_WINDOW_S = 300.0  # the thermal time scale over which heat and motion are compared (minutes)
ONE_PROPORTION = 0.1        # relative misfit of heat = a |v| below which they come in one proportion


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosisSettings:
    """``cv_blocks``: contiguous held-out segments per recording (validation); ``fit``: grid/optimiser
    settings of every fit (10 s grid: thermal time constants are >= tens of seconds, the held losses
    are averaged exactly); ``selection``: level and effect size of the nested tests;
    ``max_noise_ratio``: the chosen model does not fit when its RMSE exceeds this many noise
    standard deviations; ``max_noise_c``: nor when that noise itself exceeds this (a motor's temperature does
    not jump kelvins between samples: larger "noise" is a wrong column or a broken sensor); ``min_samples`` / ``min_span_s``: less data per recording (on the grid) is
    ``insufficient_data``; ``progress``: tqdm bar over the fits (None: only on a terminal); ``growth``: how a
    network grows on recordings with several sensors (:class:`~thermo_ddp.diagnose.growth.GrowthSettings`)."""

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
    growth: GrowthSettings = GrowthSettings()

    def __post_init__(self) -> None:
        name = "thermal diagnosis settings"
        require(isinstance(self.cv_blocks, int) and self.cv_blocks >= 2, name, "cv_blocks", self.cv_blocks, "must be >= 2")
        require(self.max_noise_ratio > 1, name, "max_noise_ratio", self.max_noise_ratio, "must be > 1")
        require(self.max_noise_c > 0, name, "max_noise_c", self.max_noise_c, "must be > 0")
        require(self.min_samples >= 4 * self.cv_blocks, name, "min_samples", self.min_samples,
                f"must be >= 4 cv_blocks = {4 * self.cv_blocks}")
        require(self.min_span_s >= 0, name, "min_span_s", self.min_span_s, "must be >= 0")


def _usable_candidates(candidates: Sequence[str], grids: Sequence[ThermalGrid], allowed: Sequence[str],
                       texts: Mapping[str, str]) -> tuple[list[str], list[dict]]:
    """The candidates these data can test; a heat source the motor cannot have ([hardware] heat_sources,
    ``allowed``) is never named (``texts``: each term's experiment)."""
    usable, skipped = [], []
    moving = any(g.has_velocity and np.any(np.abs(g.velocity) > MOVING_RAD_S) for g in grids)
    for term in candidates:
        require(term in THERMAL_TERMS, "diagnose", "term", term, f"unknown; known: {', '.join(THERMAL_TERMS)}")
        if term in HEAT_SOURCE_KINDS and term not in allowed:
            continue
        if term in SPEED_TERMS and not moving:
            skipped.append({"term": term, "reason": "no recording has a velocity (or position) showing motion",
                            "experiment": texts[term]})
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


def _undetermined(selection: SubsetSelection, fits: Mapping[frozenset, ThermalFit],
                  texts: Mapping[str, str]) -> list[dict]:
    """What these data cannot tell apart: equally good term sets, and named terms whose parameters
    are not identifiable."""
    out, chosen = [], selection.chosen
    for other in selection.equivalent:
        for term in sorted(other.terms ^ chosen.terms):
            out.append({"term": term, "reason": f"{fits[other.terms].model} fits as well as {fits[chosen.terms].model} "
                                                f"(RMSE {other.rmse:.3g} vs {chosen.rmse:.3g} K)",
                        "experiment": texts[term]})
    final = fits[chosen.terms]
    for term in sorted(chosen.terms):
        loose = [k for k in term_keys(term, canonical_terms("one_node", chosen.terms))
                 if k in final.stderr and not final.identifiable(k)]
        if loose:
            partners = sorted({c for k in loose for c in final.collinear(k)})
            out.append({"term": term, "reason": f"needed, but {', '.join(loose)} not identifiable from these data"
                                                + (f" (collinear with {', '.join(partners)})" if partners else ""),
                        "experiment": texts[term]})
    return out


def _held_out_notes(checks: Mapping[str, HeldOutCheck], named: frozenset, texts: Mapping[str, str]) -> list[dict]:
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
        out.append({"term": t, "reason": reason, "experiment": texts[t]})
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


def _window_mean(time_s: np.ndarray, values: np.ndarray, window_s: float) -> np.ndarray:
    """The mean of ``values`` over the samples in the ``window_s`` up to each sample (each sample counted once)."""
    total = np.concatenate([[0.0], np.cumsum(values)])
    start = np.searchsorted(time_s, time_s - window_s, side="left")
    stop = np.arange(1, len(values) + 1)
    return (total[stop] - total[start]) / (stop - start)


def _in_one_proportion(grids: Sequence[ThermalGrid]) -> bool:
    """Whether the copper heat (i^2) and the motion (|v|) come and go in one proportion on the thermal time scale:
    their means over :data:`PROPORTION_WINDOW_S` fit heat = a |v| within :data:`ONE_PROPORTION` (relative).  A
    motor that turns at one speed under two loads (Paderborn profile 24) does not: its running loss is separable."""
    heat = np.concatenate([_window_mean(g.time_s, g.current_a ** 2, PROPORTION_WINDOW_S) for g in grids])
    run = np.concatenate([_window_mean(g.time_s, np.abs(g.velocity), PROPORTION_WINDOW_S) for g in grids])
    if not run @ run > 0 or not heat @ heat > 0:
        return False
    return bool(np.linalg.norm(heat - (heat @ run) / (run @ run) * run) <= ONE_PROPORTION * np.linalg.norm(heat))


def _one_regime(grids: Sequence[ThermalGrid], regimes: Sequence[np.ndarray], usable: Sequence[str]) -> list[dict]:
    """Motion only ever under load and load only ever in motion (no stretch loaded at rest), in one proportion: a
    running loss then always comes with the copper heat and reads as a larger thermal resistance (every heat
    scales with it); the speed terms are listed, named or not (seed report 4.4: friction heat is the difference
    between a moving and a static phase at the same current)."""
    labels = np.concatenate(regimes) if regimes else np.zeros(0, str)
    if not np.any(labels == "moving") or np.any((labels == "static") | (labels == "heating")):
        return []
    if not _in_one_proportion(grids):
        return []
    reason = ("seen in one regime: the joint only carries current while it moves, so a running loss always comes "
              "with the copper heat and reads as a larger thermal resistance; its presence and values cannot be told")
    experiment = ("hold the moving phase's current still (e.g. 20 min) next to the motion, and move at a second "
                  "speed: the running loss is the difference between moving and static at the same current")
    return [{"term": t, "reason": reason, "experiment": experiment} for t in SPEED_TERMS if t in usable]


def _hosted(fit: ThermalFit, grids: Sequence[ThermalGrid], texts: Mapping[str, str]) -> tuple[frozenset, list[dict]]:
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
        "term": "casing_node", "experiment": texts["casing_node"],
        "reason": f"fitted winding time constant C_w R_wc = {tau_s:.1f} s, below the {step_s:.0f} s step of the "
                  "data: no casing node is evidenced (kept in the structure only to host the drive node)"}]


def _segments(recs, params: JointParameters, settings: ThermalDiagnosisSettings) -> tuple[tuple[ThermalGrid, ...], dict]:
    """Every recording split at its gaps, on the diagnosis grid, with the contract's ``rows``."""
    split = [split_at_gaps(r) for r in recs]
    grids = tuple(thermal_grid(part, params, settings.fit) for parts, _ in split for part in parts)
    rows = {"used": sum(len(p) for parts, _ in split for p in parts), "skipped": sum(n for _, n in split),
            "segments": len(grids)}
    return grids, rows


def _select(params: JointParameters, grids, settings: ThermalDiagnosisSettings, usable: list[str], base: frozenset):
    """Fit every term set, select (nested tests, held out), validate: (fitter, selection, held_out, cv, segment_cv)."""
    hide = None if settings.progress is None else not settings.progress
    with tqdm(desc="thermal diagnosis fits", unit="fit", disable=hide) as bar:
        fitter = _Fitter(params, grids, settings, term_specs(params), bar, room_stand_in="drive_heating" in base)
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
    return fitter, selection, held_out, cv, segment_cv


def _verdict(final: ThermalFit, noise, settings: ThermalDiagnosisSettings, named: frozenset, cv) -> tuple[bool, str]:
    """(fits, message) of the chosen model against its residual noise."""
    fitting = noise.rmse_ratio <= settings.max_noise_ratio and noise.total_c <= settings.max_noise_c
    message = (f"{final.model}: rmse {final.rmse:.3g} K = {noise.rmse_ratio:.2f} x the residual noise "
               f"{noise.total_c:.3g} K")
    if noise.rmse_ratio > settings.max_noise_ratio:
        message += f" (> {settings.max_noise_ratio:g}): a systematic error that no candidate explains"
        if named:
            message += (f"; the terms named lower the held-out RMSE from {cv[0]:.3g} to {cv[1]:.3g} K, what is left "
                        "needs physics beyond the candidates (more thermal nodes, another heat source)")
    elif not fitting:
        message += (f", above {settings.max_noise_c:g} K: the temperature jumps between samples as no thermal "
                    "network does (a wrong column or a broken sensor?); nothing here can be diagnosed")
    return fitting, message


def several_sensors(params: JointParameters, grids: Sequence[ThermalGrid]) -> bool:
    """Whether the network diagnosis applies: a general network, or recordings with more than one sensor."""
    return params.thermal.model == "network" or any(len(g.sensors) > 1 for g in grids)


def diagnose_thermal(recordings, *, parameters: JointParameters | str | Path | None = None,
                     candidates: Sequence[str] = CANDIDATE_TERMS, settings: ThermalDiagnosisSettings | None = None
                     ) -> ThermalDiagnosis | NetworkDiagnosis:
    """Diagnose recordings (``current_a`` + ``temperature_c``; ``velocity`` or ``position`` for the
    speed-dependent terms; ``ambient_c`` if logged) against the one-node baseline (module docstring).
    Recordings with several sensors, or a general network file, grow the network instead
    (:func:`~thermo_ddp.diagnose.network_diagnosis.diagnose_network`)."""
    settings = settings or ThermalDiagnosisSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "thermal")
    for rec in recs:
        rec.require("current_a", "temperature_c")
    grids, rows = _segments(recs, params, settings)
    names = tuple(r.name for r in recs)
    short = _too_short(grids, settings)
    if short:
        return ThermalDiagnosis(names, params, grids, False, "insufficient_data", short, rows=rows,
                                cv_blocks=settings.cv_blocks)
    if several_sensors(params, grids):
        return diagnose_network(params, grids, settings=settings.growth, window_s=settings.localise.noise_window_s,
                                rows=rows, progress=settings.progress, envelope=envelope_of(recs))
    texts = experiments(grids, params)
    usable, skipped = _usable_candidates(candidates, grids, params.scope.allowed_sources, texts)
    base = frozenset()
    if "drive_heating" in usable and not any(g.has_ambient for g in grids):
        usable.remove("drive_heating")
        base = frozenset({"drive_heating"})
        skipped.append(room_note(texts))
    regimes = tuple(thermal_regimes(g, settings.regimes) for g in grids)
    fitter, selection, held_out, cv, segment_cv = _select(params, grids, settings, usable, base)
    fits = dict(fitter.fits)
    if selection is None:
        return ThermalDiagnosis(names, params, grids, False, "model_does_not_fit",
                                "no candidate model converged within physical bounds", rows, regimes, None, fits,
                                not_determinable=tuple(skipped), cv_blocks=settings.cv_blocks, baseline_terms=base)
    final = fits[selection.chosen.terms]
    locs = tuple(locate_thermal(_series(f, grids, regimes), settings.localise) for f in (fits[base], final))
    noise = _noise(final, grids, settings.localise.noise_window_s)
    hosted, unresolved = _hosted(final, grids, texts)
    named = selection.chosen.terms - base - hosted
    fitting, message = _verdict(final, noise, settings, named, cv)
    notes = (tuple(skipped) + tuple(unresolved) + tuple(_held_out_notes(held_out, named, texts))
             + tuple(_undetermined(selection, fits, texts)) + tuple(_one_speed(grids, selection.chosen.terms - base))
             + tuple(_one_regime(grids, regimes, usable)))
    return ThermalDiagnosis(names, params, grids, fitting, "ok" if fitting else "model_does_not_fit", message,
                            rows, regimes, selection, fits, locs, cv, noise, notes, settings.cv_blocks, hosted, base,
                            held_out, segment_cv, envelope_of(recs))


def diagnose_thermal_files(paths: Sequence[str | Path], plot: str | Path | None = None, columns=None,
                           **options) -> dict:
    """CLI entry: CSV recording paths (any columns through the column map ``columns``; ``parameters``:
    the parameter file) -> the diagnosis dict with ``rows`` (optionally a plot file)."""
    if options.get("parameters") is not None:
        options["parameters"] = load_joint_parameters(options["parameters"])  # refused before reading data
    recordings = read_recordings(paths, columns)
    diagnosis = diagnose_thermal(list(recordings.recordings), **options)
    if plot is not None:
        diagnosis.plot(plot)
    return diagnosis.to_dict() | {"rows": recordings.rows}


__all__ = ["CANDIDATE_TERMS", "ThermalDiagnosis", "ThermalDiagnosisSettings", "diagnose_thermal",
           "diagnose_thermal_files", "iron_max", "term_keys", "term_specs"]

