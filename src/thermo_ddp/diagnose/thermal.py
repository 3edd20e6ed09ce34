"""Thermal diagnosis: fit the one-node baseline (seed report eq. 7 with R(T), eq. 5), locate where
and in which regime it misfits, name the missing physics from a candidate library, refit, validate
on held-out data, and write the improved contract parameter file.

Candidates (contract term names) and the parameter-file mapping of the final model:

==================  =========================================================  =========================
term                physics                                                     parameter file
==================  =========================================================  =========================
friction_heating    a fraction of the friction power tau_f(v) v heats the      ``friction_heating_fraction``
                    motor (sensor node of one_node, casing otherwise)
casing_node         winding and casing nodes, sensor on the casing (eq. 6)      ``model = "two_node"``
drive_heating       a drive node heated by idle + i^2 losses, coupled to the    ``model = "two_node_drive"``
                    casing and ambient: raises idle temperature, slows cooling
                    (implies the casing node: the drive heats the casing)
copper_resistance   free temperature coefficient of R(T) (eq. 3)                ``[motor] copper_alpha_per_k``
iron_losses         speed-dependent loss k v^2 in the winding                   ``[thermal] iron_loss_w`` (+ ref speed, exponent 2)
==================  =========================================================  =========================

Each candidate is refitted (output error, :mod:`thermo_ddp.identify.thermal`) and accepted only if
(a) it explains the located mismatch in its regime, (b) it lowers the blocked cross-validated RMSE
(contiguous held-out segments of every recording; the simulation runs through a held-out segment
from the state the training fit predicts) and (c) its parameters are physical (:data:`TERM_SPECS`).
Information criteria are not used: output-error residuals are strongly autocorrelated.

Iron losses and friction heating have nearly the same shape in one motion pattern (both grow with
speed); they are told apart physically: iron losses of this motor class are bounded by its no-load
losses (see :data:`IRON_MAX`), so a speed-dependent heat of several watts can only be friction.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm.auto import tqdm

from .._config import require
from ..errors import InputError
from ..identify.thermal import (IRON_KEY, THERMAL_TERMS, JointParameters, ThermalFit, ThermalModel,
                                default_fixed, fit_grids, load_joint_parameters, network_model, parameter_file,
                                start_values)
from ..identify.thermal_data import ThermalGrid, ThermalSettings, thermal_grid
from ..recordings import as_recordings, read_recordings
from ._thermal_localise import (ThermalLocaliseSettings, ThermalRegimeSettings, held_window_mean, locate_thermal,
                                thermal_regimes)
from .localise import Localisation, ResidualSeries
from .selection import (ModelFit, SelectedTerms, Selection, SelectionSettings, TermSpec, forward_select,
                        physical_violations)
from .._figures import new_figure

log = logging.getLogger(__name__)

CANDIDATE_TERMS = THERMAL_TERMS
# Iron-loss bound: at the no-load speed V_bus / (K_b N) (joint side) the iron losses are at most half
# the no-load power V_bus * I_0, with I_0 ~ 0.1 A for 48 V maxon EC-flat/EC-4pole motors of this class
# (datasheets list no-load currents of 0.05-0.3 A; the no-load power also covers bearing friction).
NO_LOAD_CURRENT_A = 0.1
IRON_SHARE_OF_NO_LOAD = 0.5
_POS = (0.0, math.inf)


def iron_max(params: JointParameters) -> float:
    """Largest physical iron-loss coefficient k [W s^2/rad^2] (joint-side speed), see module docstring."""
    m = params.motor
    no_load_speed = m.bus_voltage_v / (m.back_emf_v_s_per_rad * m.gear_ratio)
    return IRON_SHARE_OF_NO_LOAD * m.bus_voltage_v * NO_LOAD_CURRENT_A / no_load_speed ** 2


def term_specs(params: JointParameters) -> dict[str, TermSpec]:
    """Physical ranges of every term's parameters (inclusive).  Capacities: 0.1-20 kg of aluminium or
    copper (385-900 J/kg/K); resistances: maxon class data, winding-housing 0.5-5 K/W and
    housing-ambient 1-10 K/W, widened; copper alpha: 0.00393 /K (report eq. 3) +-10 %."""
    return {
        "one_node": TermSpec("one_node", {"capacity_j_per_k": (100.0, 2e4), "resistance_k_per_w": (0.1, 20.0)}),
        "casing_node": TermSpec("casing_node", {"winding_capacity_j_per_k": (1.0, 1000.0),
                                                "casing_capacity_j_per_k": (100.0, 2e4),
                                                "winding_casing_k_per_w": (0.05, 10.0),
                                                "casing_ambient_k_per_w": (0.1, 20.0)}),
        "drive_heating": TermSpec("drive_heating", {"winding_capacity_j_per_k": (1.0, 1000.0),
                                                    "casing_capacity_j_per_k": (100.0, 2e4),
                                                    "winding_casing_k_per_w": (0.05, 10.0),
                                                    "casing_ambient_k_per_w": (0.1, 20.0),
                                                    "drive_capacity_j_per_k": (10.0, 1e4),
                                                    "drive_casing_k_per_w": (0.02, 50.0),
                                                    "drive_idle_w": (0.5, 100.0)}),
        "friction_heating": TermSpec("friction_heating", {"friction_heating_fraction": (0.0, 1.0)}),
        "copper_resistance": TermSpec("copper_resistance", {"copper_alpha_per_k": (0.0035, 0.0045)}),
        "iron_losses": TermSpec("iron_losses", {IRON_KEY: (0.0, iron_max(params))}),
    }


_TERM_PARAMETERS = {
    "friction_heating": ("friction_heating_fraction",), "copper_resistance": ("copper_alpha_per_k",),
    "iron_losses": (IRON_KEY,),
    "casing_node": ("winding_capacity_j_per_k", "casing_capacity_j_per_k", "winding_casing_k_per_w",
                    "casing_ambient_k_per_w"),
    "drive_heating": ("drive_capacity_j_per_k", "drive_casing_k_per_w", "drive_ambient_k_per_w", "drive_idle_w",
                      "drive_loss_w_per_a2"),
}


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosisSettings:
    """``cv_blocks``: contiguous held-out segments per recording; ``fit``: grid/optimiser settings of
    every fit (10 s grid: thermal time constants are >= tens of seconds, the held losses are averaged
    exactly); ``progress``: tqdm bar over the candidate fits (None: only on a terminal)."""

    cv_blocks: int = 3
    fit: ThermalSettings = ThermalSettings(min_step_s=10.0, max_step_s=10.0)
    regimes: ThermalRegimeSettings = ThermalRegimeSettings()
    localise: ThermalLocaliseSettings = ThermalLocaliseSettings()
    selection: SelectionSettings = SelectionSettings(min_concentration=0.8)
    progress: bool | None = None

    def __post_init__(self) -> None:
        require(self.cv_blocks >= 2, "thermal diagnosis settings", "cv_blocks", self.cv_blocks, "must be >= 2")


def _blocks(grids: Sequence[ThermalGrid], n_blocks: int) -> list[np.ndarray]:
    """Contiguous time blocks per recording (ids r * n_blocks + b)."""
    out = []
    for r, g in enumerate(grids):
        frac = (g.time_s - g.time_s[0]) / max(g.time_s[-1] - g.time_s[0], 1e-9)
        out.append(r * n_blocks + np.minimum((frac * n_blocks).astype(int), n_blocks - 1))
    return out


class _Fitter:
    """Fits of term sets with blocked cross-validation, cached by network structure."""

    def __init__(self, params: JointParameters, grids: Sequence[ThermalGrid], settings: ThermalDiagnosisSettings,
                 specs: Sequence[TermSpec], bar):
        self.params, self.grids, self.settings, self.specs, self.bar = params, list(grids), settings, specs, bar
        self.blocks = _blocks(grids, settings.cv_blocks)
        self.cache: dict[tuple, ModelFit] = {}
        self.fits: dict[tuple, ThermalFit] = {}

    @staticmethod
    def key(terms: Sequence[str]) -> tuple:
        model = network_model(terms)
        return (model,) + tuple(sorted(t for t in terms if t not in ("casing_node", "drive_heating")))

    def thermal_fit(self, terms: Sequence[str]) -> ThermalFit:
        self(tuple(terms))
        return self.fits[self.key(terms)]

    def _parent(self, terms: Sequence[str]) -> ThermalFit | None:
        fits = [(len(k), f) for k, f in self.fits.items() if set(f.terms) <= set(terms) and f.success]
        return max(fits, key=lambda x: x[0])[1] if fits else None

    def _full_fit(self, model: ThermalModel) -> ThermalFit:
        """Best of two starts (the closest fitted parent, the parameter file), preferring
        converged fits, then physical ones (a network may fit as well with a node collapsed), then rmse."""
        parent = self._parent(model.terms)
        starts = [(start_values(self.params, model.terms), None)]
        if parent is not None:
            starts.insert(0, (start_values(self.params, model.terms, previous=parent.parameters),
                              [parent.initial_offset_c[g.name] for g in self.grids]))
        fits = []
        for start, offsets in starts:
            fits.append(fit_grids(model, self.grids, start=start, offsets=offsets, settings=self.settings.fit))
            self.bar.update(1)
        return min(fits, key=lambda f: (not f.success, bool(physical_violations(f.parameters, self.specs)), f.rmse))

    def __call__(self, terms: tuple[str, ...]) -> ModelFit:
        key = self.key(terms)
        if key in self.cache:
            return dataclasses.replace(self.cache[key], terms=tuple(terms))
        fixed_keys = default_fixed(terms)
        values = start_values(self.params, terms)
        model = ThermalModel(self.params, terms, {k: values[k] for k in fixed_keys})
        full = self._full_fit(model)
        self.fits[key] = full
        cv = np.array(full.residuals, float)
        if full.success:
            start = dict(full.parameters)
            offsets = [full.initial_offset_c[g.name] for g in self.grids]
            for b in np.unique(np.concatenate(self.blocks)):
                weights = [(blk != b).astype(float) for blk in self.blocks]
                held = fit_grids(model, self.grids, start=start, offsets=offsets, weights=weights,
                                 settings=self.settings.fit)
                self.bar.update(1)
                rows = np.concatenate(self.blocks) == b
                cv[rows] = held.residuals[rows]
        mf = ModelFit(tuple(terms), full, cv, np.concatenate(self.blocks),
                      np.concatenate([[g.name] * len(g) for g in self.grids]),
                      np.concatenate([g.time_s for g in self.grids]))
        self.cache[key] = mf
        return mf


@dataclasses.dataclass(frozen=True)
class RegimeGain:
    """How much of the located mismatch of one regime an accepted term removed."""

    regime: str
    gain: float    # 1 - mean-square residual after / before, inside that regime's mismatch intervals
    share: float   # share of the term's total squared-residual reduction inside mismatches

    def __str__(self) -> str:
        return f"{self.regime} -{100 * self.gain:.0f}% ({100 * self.share:.0f}% of the reduction)"


def regime_gains(current: ModelFit, candidate: ModelFit, localisation: Localisation) -> tuple[RegimeGain, ...]:
    """Per regime of the located mismatches: the candidate's local gain and share (largest share first)."""
    before, after = current.fit.residuals ** 2, candidate.fit.residuals ** 2
    masks: dict[str, np.ndarray] = {}
    for m in localisation.mismatches:
        mask = masks.setdefault(m.regime, np.zeros(before.size, dtype=bool))
        mask |= (current.recording == m.recording) & (current.time_s >= m.start_s) & (current.time_s <= m.end_s)
    total = sum(float((before - after)[mask].sum()) for mask in masks.values())
    out = [RegimeGain(r, float(1 - after[mask].mean() / before[mask].mean()) if before[mask].mean() > 0 else 0.0,
                      float((before - after)[mask].sum() / total) if total > 0 else 0.0)
           for r, mask in masks.items() if mask.any()]
    return tuple(sorted(out, key=lambda g: -g.share))


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosis(SelectedTerms):
    """Result of :func:`diagnose_thermal`; ``to_dict()`` is the contract's diagnosis JSON plus
    ``parameter_file`` (the improved parameter sections, loadable with ``parameters_from_dict``)."""

    recordings: tuple[str, ...]
    selection: Selection
    grids: tuple[ThermalGrid, ...]
    regimes: tuple[np.ndarray, ...]
    params: JointParameters
    baseline_fit: ThermalFit
    final_fit: ThermalFit
    cv_blocks: int
    explained: dict = dataclasses.field(default_factory=dict)  # accepted term -> tuple[RegimeGain]
    skipped: tuple[str, ...] = ()
    success: bool = True
    status: str = "ok"
    message: str = "diagnosis ran"

    def parameter_file(self) -> dict | None:
        if not self.final_fit.success:
            return None
        return parameter_file(self.params, self.final_fit, self.recordings)

    def to_dict(self) -> dict:
        sel = self.selection
        missing = []
        for a in sel.accepted:
            fit = a.candidate.fit
            keys = _TERM_PARAMETERS[a.term]
            if a.term == "drive_heating" and "casing_node" not in self.missing_physics:
                keys = _TERM_PARAMETERS["casing_node"] + keys
            where = "; ".join(str(g) for g in self.explained.get(a.term, ()) if g.gain > 0)
            missing.append({"term": a.term, "evidence": f"{a.evidence}; explained by regime: {where or 'none'}",
                            "parameters": {k: float(fit.parameters[k]) for k in keys if k in fit.parameters},
                            "rmse": fit.rmse})
        return {"physics": "thermal", "recordings": list(self.recordings),
                "baseline": sel.baseline.fit.summary(), "mismatches": sel.baseline_localisation.to_list(),
                "missing_physics": missing, "final": sel.final.fit.summary(),
                "validation": {"method": f"blocked cross-validation: {self.cv_blocks} contiguous segments per "
                                         "recording, each predicted (open-loop simulation) by a fit that did not "
                                         "see it (held-out RMSE)",
                               "rmse_before": sel.baseline.cv_rmse, "rmse_after": sel.final.cv_rmse},
                "unexplained": sel.final_localisation.to_list(),
                "parameter_file": self.parameter_file()}

    def report(self) -> str:
        sel = self.selection
        lines = [f"thermal diagnosis of {', '.join(self.recordings)}: {self.status} ({self.message})",
                 f"baseline {sel.baseline.fit.model}: rmse {sel.baseline.fit.rmse:.4g} K, "
                 f"{len(sel.baseline_localisation.mismatches)} mismatch intervals "
                 f"({', '.join(sorted({m.regime for m in sel.baseline_localisation.mismatches})) or 'none'})"]
        lines += [f"  {a.term}: {'ACCEPTED' if a.accepted else 'rejected'}: {a.evidence}" for a in sel.assessments]
        lines += [f"  {term} explains: " + "; ".join(map(str, gains)) for term, gains in self.explained.items()]
        lines += [f"  {term}: not tested ({why})" for term, why in (s.split(": ", 1) for s in self.skipped)]
        lines += [f"final {sel.final.fit.model}: rmse {sel.final.fit.rmse:.4g} K; held-out rmse "
                  f"{sel.baseline.cv_rmse:.4g} -> {sel.final.cv_rmse:.4g} K; "
                  f"{len(sel.final_localisation.mismatches)} unexplained intervals", self.final_fit.fit_report()]
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 3) -> Path:
        """Measured, baseline and final sensor temperature; residuals with mismatch intervals shaded;
        current and speed."""

        sel, path = self.selection, Path(path)
        grids = self.grids[:max_recordings]
        fig, axes = new_figure(3, len(grids), figsize=(9 * len(grids), 9), sharex="col", squeeze=False)
        for c, grid in enumerate(grids):
            rows, t, ax = self.baseline_fit.rows(grid.name), grid.time_s, axes[:, c]
            ax[0].plot(t, grid.measured_c, "k.", ms=1.5, label="recorded (casing sensor)")
            ax[0].plot(t, sel.baseline.fit.fitted[rows], lw=1.0, label=f"baseline {sel.baseline.fit.model}")
            ax[0].plot(t, sel.final.fit.fitted[rows], lw=1.0, label=f"final {sel.final.fit.model}")
            ax[1].plot(t, sel.baseline.fit.residuals[rows], lw=0.6, label=f"baseline, rmse {sel.baseline.fit.rmse:.3g} K")
            ax[1].plot(t, sel.final.fit.residuals[rows], lw=0.6, label=f"final, rmse {sel.final.fit.rmse:.3g} K")
            for loc, color in ((sel.baseline_localisation, "red"), (sel.final_localisation, "grey")):
                for m in loc.mismatches:
                    if m.recording == grid.name:
                        ax[1].axvspan(m.start_s, m.end_s, color=color, alpha=0.2, lw=0)
                        ax[1].text(0.5 * (m.start_s + m.end_s), 0, m.regime, fontsize=7, ha="center", color=color)
            ax[2].plot(t, np.sqrt(held_window_mean(grid, 1, 30.0)), lw=0.8, label="RMS current over 60 s [A]")
            ax[2].plot(t, np.sqrt(held_window_mean(grid, 3, 30.0)), lw=0.8, label="RMS speed over 60 s [rad/s]")
            ax[0].set(title=grid.name, ylabel="temperature [°C]")
            ax[1].set(ylabel="residual [K] (red: mismatch, grey: unexplained)")
            ax[2].set(xlabel="time [s]")
            for a in ax:
                a.legend(fontsize=8, loc="best")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        return path


def _usable_candidates(candidates: Sequence[str], grids: Sequence[ThermalGrid]) -> tuple[list[str], list[str]]:
    usable, skipped = [], []
    moving = any(g.has_velocity and np.any(np.abs(g.velocity) > 0.05) for g in grids)
    for term in candidates:
        require(term in THERMAL_TERMS, "diagnose", "term", term, f"unknown; known: {', '.join(THERMAL_TERMS)}")
        if term in ("friction_heating", "iron_losses") and not moving:
            skipped.append(f"{term}: no recording has a velocity (or position) showing motion")
        else:
            usable.append(term)
    return usable, skipped


def diagnose_thermal(recordings, *, parameters: JointParameters | str | Path | None = None,
                     candidates: Sequence[str] = CANDIDATE_TERMS,
                     settings: ThermalDiagnosisSettings | None = None) -> ThermalDiagnosis:
    """Diagnose recordings (``current_a`` + ``temperature_c``; ``velocity`` or ``position`` for the
    speed-dependent terms; ``ambient_c`` if logged) against the one-node baseline."""
    settings = settings or ThermalDiagnosisSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "thermal")
    grids = tuple(thermal_grid(r, params, settings.fit) for r in recs)
    for g in grids:
        if len(g) < 4 * settings.cv_blocks:
            raise InputError(g.name, "time_s", f"{len(g)} samples on the {settings.fit.min_step_s:g} s grid",
                             f"too short for {settings.cv_blocks}-block cross-validation")
    usable, skipped = _usable_candidates(candidates, grids)
    regimes = tuple(thermal_regimes(g, settings.regimes) for g in grids)
    specs = term_specs(params)
    hide = None if settings.progress is None else not settings.progress
    with tqdm(desc="thermal diagnosis fits", unit="fit", disable=hide) as bar:
        fitter = _Fitter(params, grids, settings, list(specs.values()), bar)

        def locate(mf: ModelFit) -> Localisation:
            series, start = [], 0
            for g, labels in zip(grids, regimes):
                series.append(ResidualSeries(g.name, g.time_s, mf.fit.residuals[start:start + len(g)], labels))
                start += len(g)
            return locate_thermal(series, settings.localise)

        selection = forward_select(fitter, locate, (), [specs[t] for t in usable], [specs["one_node"]],
                                   settings.selection)
    explained, current = {}, selection.baseline
    for a in selection.accepted:
        explained[a.term] = regime_gains(current, a.candidate, locate(current))
        current = a.candidate
    baseline_fit = fitter.thermal_fit(selection.baseline.terms)
    final_fit = fitter.thermal_fit(selection.final.terms)
    ok = baseline_fit.success and final_fit.success
    return ThermalDiagnosis(tuple(g.name for g in grids), selection, grids, regimes, params, baseline_fit, final_fit,
                            settings.cv_blocks, explained, tuple(skipped), ok, "ok" if ok else final_fit.status,
                            "diagnosis ran" if ok else f"final fit failed: {final_fit.message}")


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
           "diagnose_thermal_files", "iron_max", "term_specs"]
