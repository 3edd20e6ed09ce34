"""The result of the one-sensor thermal diagnosis: the contract's diagnosis JSON, report and plot."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Mapping

import numpy as np

from ..identify.thermal import FRICTION_KEYS, THERMAL_TERMS, JointParameters, ThermalFit, canonical_terms, parameter_file, structure_name
from ..identify.thermal_data import ThermalGrid
from ._thermal_fitter import Noise
from ._thermal_terms import HELD_OUT_RULE, term_keys
from .localise import Localisation
from .selection import HeldOutCheck, SubsetSelection


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
class ThermalOutcome:
    """What every thermal diagnosis holds first: the recordings, the parameter file, their grids, the verdict."""

    recordings: tuple[str, ...]
    params: JointParameters
    grids: tuple[ThermalGrid, ...]
    success: bool
    status: str
    message: str


@dataclasses.dataclass(frozen=True)
class ThermalDiagnosis(ThermalOutcome):
    """Result of :func:`diagnose_thermal`; ``to_dict()`` is the contract's diagnosis JSON plus
    ``parameter_file`` (the improved parameter sections, loadable with ``parameters_from_dict``),
    ``speed_source`` and ``noise``.  ``fits`` holds every fitted term set (empty without data)."""

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
    baseline_terms: frozenset = frozenset()  # in every fitted set, never tested (the room's stand-in, see room_note)
    held_out: Mapping[str, HeldOutCheck] = dataclasses.field(default_factory=dict)  # leave one segment out, per term
    segment_cv: tuple[float, float, tuple[str, ...]] | None = None  # leave one segment out: baseline, final, segments
    envelope: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)  # what the recordings cover

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
        return parameter_file(self.params, self.final_fit, self.recordings, self.envelope)

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
                "collinear_with": collinear, "held": [k for k in keys if k not in fit.stderr]}

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

    def plot(self, path: str | Path) -> Path:
        """The diagnosis figure (:func:`thermo_ddp.diagnose.figure.plot_thermal_diagnosis`) written to ``path``."""
        from .figure import plot_thermal_diagnosis
        return plot_thermal_diagnosis(self, path)


