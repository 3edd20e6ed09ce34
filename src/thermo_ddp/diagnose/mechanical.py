"""Mechanical diagnosis: fit a baseline inverse-dynamics model, locate where it misfits, name the
missing friction physics, refit, and validate on held-out data.

Regimes (per sample, from the filtered velocity ``v`` and ``v_ref`` = 99th percentile of ``|v|``):
``"reversal"`` – a run with ``|v| < reversal_fraction·v_ref`` in which the velocity changes sign;
``"static"`` – otherwise ``|v| < static_fraction·v_ref``; ``"slow"`` – other samples with
``|v| < slow_fraction·v_ref``; ``"moving"`` – the rest.  The speed bands matter: friction
effects change sign with speed (a Stribeck hump is positive below ``vs`` and, once Coulomb and
viscous friction absorb its average, negative above), so one wide band would average them away.  The
orientation passed to the localiser is ``sign(v)`` (friction flips with the direction of motion),
``+1`` when static.  Candidate terms (contract names): ``coulomb_friction``, ``viscous_friction``,
``effort_offset``, ``stribeck_friction`` (needs Coulomb; excess static friction
``(Fs - Fc)·exp(-(v/vs)²)·sign(v)``, parameters ``stribeck_friction`` = Fs - Fc and
``stribeck_velocity`` = vs).  Physical bounds: inertia > 0, every friction amplitude >= 0.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from .._config import checked_settings, require
from ..errors import InputError
from ..identify.mechanical import (BASELINE_TERMS, STRIBECK_VELOCITY, JointKinematics, MechanicalSettings,
                                   fit_kinematics, joint_kinematics, predict_effort)
from ..recordings import Recording, as_recordings, read_recordings
from .localise import Localisation, LocaliseSettings, ResidualSeries, localise
from ..identify.fit_report import Z95, integrated_autocorrelation
from .selection import (Assessment, ModelFit, SelectedTerms, Selection, SelectionSettings, SubsetFit, TermSpec,
                        forward_select, nested_test)
from .._figures import new_figure

log = logging.getLogger(__name__)

CANDIDATE_TERMS = ("coulomb_friction", "viscous_friction", "effort_offset", "stribeck_friction")
_POSITIVE = (0.0, math.inf)
TERM_SPECS = {
    "inertia": TermSpec("inertia", {"inertia": (1e-12, math.inf)}),
    "viscous_friction": TermSpec("viscous_friction", {"viscous_friction": _POSITIVE}),
    "coulomb_friction": TermSpec("coulomb_friction", {"coulomb_friction": _POSITIVE}),
    "effort_offset": TermSpec("effort_offset"),
    "stribeck_friction": TermSpec("stribeck_friction", {"stribeck_friction": _POSITIVE, STRIBECK_VELOCITY: _POSITIVE},
                                  requires=("coulomb_friction",)),
}


@checked_settings("mechanical diagnosis settings", cv_blocks="[2, inf)")
class MechanicalDiagnosisSettings:
    """Regime thresholds (fractions of the 99th-percentile speed) and the number of CV blocks per recording."""

    static_fraction: float = 0.02
    reversal_fraction: float = 0.1
    slow_fraction: float = 0.4
    cv_blocks: int = 5

    def __post_init__(self) -> None:
        src = "mechanical diagnosis settings"
        fractions = (self.static_fraction, self.reversal_fraction, self.slow_fraction)
        require(0 < fractions[0] < fractions[1] < fractions[2] < 1, src, "static/reversal/slow_fraction",
                fractions, "need 0 < static < reversal < slow < 1")


def motion_regimes(velocity: np.ndarray, settings: MechanicalDiagnosisSettings | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample regime labels and ±1 orientation from a (filtered) velocity; see module docstring."""
    settings = settings or MechanicalDiagnosisSettings()
    v = np.asarray(velocity, float)
    v_ref = float(np.percentile(np.abs(v), 99)) or 1.0
    labels = np.full(v.size, "moving", dtype=object)
    labels[np.abs(v) < settings.slow_fraction * v_ref] = "slow"
    labels[np.abs(v) < settings.static_fraction * v_ref] = "static"
    low = np.abs(v) < settings.reversal_fraction * v_ref
    edges = np.flatnonzero(np.diff(np.concatenate(([0], low.astype(int), [0]))))
    for start, stop in zip(edges[::2], edges[1::2]):
        if np.any(v[start:stop] > 0) and np.any(v[start:stop] < 0) and np.sign(v[start]) != np.sign(v[stop - 1]):
            labels[start:stop] = "reversal"
    orientation = np.where(labels == "static", 1.0, np.where(v < 0, -1.0, 1.0))
    return labels.astype(str), orientation


def _subset(kin: JointKinematics, keep: np.ndarray) -> JointKinematics:
    return JointKinematics(kin.recording, kin.time_s[keep], kin.position[keep], kin.velocity[keep],
                           kin.acceleration[keep], kin.effort[keep])


def _block_ids(kins: Sequence[JointKinematics], n_blocks: int) -> list[np.ndarray]:
    return [i * n_blocks + np.minimum((np.arange(len(k.time_s)) * n_blocks) // len(k.time_s), n_blocks - 1)
            for i, k in enumerate(kins)]


def model_fit(kins: Sequence[JointKinematics], terms: Sequence[str], settings: MechanicalSettings,
              n_blocks: int = 5) -> ModelFit:
    """In-sample fit of ``terms`` plus blocked cross-validation (contiguous blocks per recording)."""
    fit = fit_kinematics(kins, terms, settings)
    blocks = _block_ids(kins, n_blocks)
    cv = []
    for i, kin in enumerate(kins):
        out = np.empty(len(kin.time_s))
        for b in np.unique(blocks[i]):
            train = [_subset(k, blocks[j] != b) for j, k in enumerate(kins)]
            held = fit_kinematics(train, terms, settings)
            rows = blocks[i] == b
            out[rows] = kin.effort[rows] - predict_effort(dict(held.parameters), _subset(kin, rows)) \
                if held.success else kin.effort[rows]
        cv.append(out)
    return ModelFit(tuple(terms), fit,
                    np.concatenate(cv), np.concatenate(blocks),
                    np.concatenate([[k.recording] * len(k.time_s) for k in kins]),
                    np.concatenate([k.time_s for k in kins]))


def _residual_series(kins: Sequence[JointKinematics], mf: ModelFit, settings: MechanicalDiagnosisSettings):
    out, start = [], 0
    for kin in kins:
        n = len(kin.time_s)
        labels, orientation = motion_regimes(kin.velocity, settings)
        out.append(ResidualSeries(kin.recording, kin.time_s, mf.fit.residuals[start:start + n], labels, orientation))
        start += n
    return out


def _as_subset_fit(mf: ModelFit) -> SubsetFit:
    res = np.asarray(mf.fit.residuals, float)
    return SubsetFit(frozenset(mf.terms), float(res @ res), int(res.size), len(mf.fit.stderr) or mf.fit.n_parameters,
                     integrated_autocorrelation(res))


def _term_entry(a: Assessment, parent: ModelFit) -> dict:
    """The contract's entry of an accepted term: its parameters, the nested likelihood-ratio test against the
    model it was added to (sample size corrected for residual autocorrelation), the RMS change of the fitted
    effort it makes (``effect_k``, in the effort's units: N m or N) and 95 % intervals. ``collinear_with``
    stays empty: the linear fit refuses a rank-deficient regressor set instead."""
    fit = a.candidate.fit
    keys = [k for k in fit.parameters if k == a.term or (a.term == "stribeck_friction" and k == STRIBECK_VELOCITY)]
    return {"term": a.term, "evidence": a.evidence, "parameters": {k: float(fit.parameters[k]) for k in keys},
            "rmse": fit.rmse, "p_value": nested_test(_as_subset_fit(parent), _as_subset_fit(a.candidate)).p_value,
            "effect_k": float(np.sqrt(np.mean((np.asarray(fit.fitted) - np.asarray(parent.fit.fitted)) ** 2))),
            "ci95": {k: [float(fit.parameters[k] - Z95 * fit.stderr[k]), float(fit.parameters[k] + Z95 * fit.stderr[k])]
                     for k in keys if k in fit.stderr},
            "collinear_with": []}


@dataclasses.dataclass(frozen=True)
class Diagnosis(SelectedTerms):
    """Result of :func:`diagnose_mechanical`; ``to_dict()`` is the contract's diagnosis JSON."""

    physics: str
    recordings: tuple[str, ...]
    selection: Selection
    kinematics: tuple[JointKinematics, ...]
    cv_blocks: int
    success: bool = True
    status: str = "ok"
    message: str = "diagnosis ran"

    def to_dict(self) -> dict:
        sel = self.selection
        parents = (sel.baseline, *(a.candidate for a in sel.accepted[:-1]))
        missing = [_term_entry(a, parent) for a, parent in zip(sel.accepted, parents)]
        return {"success": self.success, "status": self.status, "message": self.message,
                "physics": self.physics, "recordings": list(self.recordings), "not_determinable": [],
                "baseline": sel.baseline.fit.summary(), "mismatches": sel.baseline_localisation.to_list(),
                "missing_physics": missing, "final": sel.final.fit.summary(),
                "validation": {"method": f"blocked cross-validation: {self.cv_blocks} contiguous blocks per recording, "
                                         "each predicted by a fit on the others (held-out RMSE)",
                               "rmse_before": sel.baseline.cv_rmse, "rmse_after": sel.final.cv_rmse},
                "unexplained": sel.final_localisation.to_list()}

    def report(self) -> str:
        sel = self.selection
        lines = [f"mechanical diagnosis of {', '.join(self.recordings)}: {self.status}",
                 f"baseline {sel.baseline.fit.model}: rmse {sel.baseline.fit.rmse:.4g}, "
                 f"{len(sel.baseline_localisation.mismatches)} mismatch intervals"]
        lines += [f"  {a.term}: {'ACCEPTED' if a.accepted else 'rejected'}: {a.evidence}" for a in sel.assessments]
        lines += [f"final {sel.final.fit.model}: rmse {sel.final.fit.rmse:.4g}; held-out rmse "
                  f"{sel.baseline.cv_rmse:.4g} -> {sel.final.cv_rmse:.4g}; "
                  f"{len(sel.final_localisation.mismatches)} unexplained intervals", sel.final.fit.fit_report()]
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 3) -> Path:
        """Effort with baseline and final fits, residuals with mismatch intervals shaded, velocity."""

        sel, path = self.selection, Path(path)
        kins = self.kinematics[:max_recordings]
        fig, axes = new_figure(3, len(kins), figsize=(12 * len(kins), 8), sharex="col", squeeze=False)
        start = 0
        for c, kin in enumerate(kins):
            rows = slice(start, start + len(kin.time_s))
            start += len(kin.time_s)
            t = kin.time_s
            ax = axes[:, c]
            ax[0].plot(t, kin.effort, "k", lw=0.6, label="recorded")
            ax[0].plot(t, sel.baseline.fit.fitted[rows], lw=0.8, label=f"baseline ({sel.baseline.fit.model})")
            ax[0].plot(t, sel.final.fit.fitted[rows], lw=0.8, label=f"final ({sel.final.fit.model})")
            ax[1].plot(t, sel.baseline.fit.residuals[rows], lw=0.5, label=f"baseline, rmse {sel.baseline.fit.rmse:.3g}")
            ax[1].plot(t, sel.final.fit.residuals[rows], lw=0.5, label=f"final, rmse {sel.final.fit.rmse:.3g}")
            for loc, color, meaning in ((sel.baseline_localisation, "red", "mismatch of the baseline"),
                                        (sel.final_localisation, "grey", "left unexplained by the final model")):
                spans = [m for m in loc.mismatches if m.recording == kin.recording]
                for k, m in enumerate(spans):
                    ax[1].axvspan(m.start_s, m.end_s, color=color, alpha=0.25, lw=0, label=None if k else meaning)
            ax[2].plot(t, kin.velocity, lw=0.8)
            ax[0].set(title=kin.recording, ylabel="effort [N·m or N, the joint's SI unit]")
            ax[1].set(ylabel="effort residual [N·m or N]")
            ax[2].set(ylabel="velocity [rad/s or m/s]", xlabel="time [s]")
            ax[0].legend(fontsize=8)
            ax[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        return path


def diagnose_mechanical(recordings: Sequence[Recording | str | Path] | Recording, *,
                        baseline: Sequence[str] = BASELINE_TERMS, candidates: Sequence[str] = CANDIDATE_TERMS,
                        settings: MechanicalSettings | None = None,
                        regime_settings: MechanicalDiagnosisSettings | None = None,
                        localise_settings: LocaliseSettings | None = None,
                        selection_settings: SelectionSettings | None = None) -> Diagnosis:
    """Diagnose recordings (``position`` + ``effort``; Recording objects or CSV paths) against ``baseline``."""
    recordings = as_recordings(recordings, "diagnose")
    for term in list(baseline) + list(candidates):
        if term not in TERM_SPECS:
            raise InputError("diagnose", "term", term, f"unknown; known: {', '.join(TERM_SPECS)}")
    settings = settings or MechanicalSettings()
    regime_settings = regime_settings or MechanicalDiagnosisSettings()
    kins = tuple(joint_kinematics(r, settings) for r in recordings)

    def fit(terms):
        return model_fit(kins, terms, settings, regime_settings.cv_blocks)

    def locate(mf: ModelFit) -> Localisation:
        return localise(_residual_series(kins, mf, regime_settings), localise_settings)

    library = [TERM_SPECS[t] for t in candidates if t not in baseline]
    fixed = [TERM_SPECS[t] for t in baseline]
    selection = forward_select(fit, locate, tuple(baseline), library, fixed, selection_settings)
    ok = selection.baseline.fit.success and selection.final.fit.success
    return Diagnosis("mechanical", tuple(r.name for r in recordings), selection, kins, regime_settings.cv_blocks, success=ok,
                     status="ok" if ok else selection.final.fit.status,
                     message="diagnosis ran" if ok else selection.final.fit.message)


def diagnose_mechanical_files(paths: Sequence[str | Path], plot: str | Path | None = None, columns=None,
                              **options) -> dict:
    """CLI entry: CSV recording paths (any columns through the column map ``columns``) -> the
    contract's diagnosis dict with ``rows`` (optionally a plot file)."""
    recordings = read_recordings(paths, columns)
    diagnosis = diagnose_mechanical(list(recordings.recordings), **options)
    if plot is not None:
        diagnosis.plot(plot)
    return diagnosis.to_dict() | {"rows": recordings.rows}
