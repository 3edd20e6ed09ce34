"""Which candidate physics to add?  General acceptance rule and greedy forward selection.

A candidate term is accepted only if all three hold (information criteria alone are not
trusted: with thousands of autocorrelated samples AIC/BIC accept almost anything):

(a) **it explains the located mismatch**: inside the mismatch intervals the mean-square residual
    falls by at least ``min_local_gain`` and the squared-residual reduction is concentrated there
    (share of the reduction inside / share of samples inside >= ``min_concentration``);
(b) **it predicts unseen data better**: blocked cross-validation (contiguous held-out blocks or
    whole recordings, so autocorrelated neighbours never leak into training) lowers the held-out
    RMSE by at least ``min_cv_gain`` (relative) and improves at least ``min_block_share`` of the
    held-out blocks that contain mismatch samples (a local effect cannot improve the other blocks);
(c) **its parameters are physical**: every parameter of the refitted model lies within the
    bounds given per term (:class:`TermSpec`), and the fit succeeded.

:func:`forward_select` adds, one at a time, the accepted candidate with the best held-out gain,
re-localises the mismatch after each addition, and stops when nothing is accepted or nothing
systematic is left.  It is model-agnostic: the caller supplies ``fit(terms) -> ModelFit`` (any
least-squares fit with its held-out residual) and ``locate(fit) -> Localisation``.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy import stats

from .._config import checked_settings
from ..identify.fit_report import FitResult
from .localise import Localisation

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class TermSpec:
    """A candidate (or baseline) term: physical ``bounds`` of its parameters (inclusive) and the
    terms it ``requires`` in the model first (e.g. Stribeck excess friction needs Coulomb)."""

    name: str
    bounds: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    requires: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class ModelFit:
    """A fit of one term set: the in-sample fit and its blocked cross-validation.

    ``cv_residual`` (same samples and order as ``fit.residuals``) is each sample's residual
    predicted by a fit that did not see its block; ``blocks`` is the block id of each sample.
    ``recording``/``time_s`` say where each sample comes from (to build mismatch masks).
    """

    terms: tuple[str, ...]
    fit: FitResult
    cv_residual: np.ndarray
    blocks: np.ndarray
    recording: np.ndarray
    time_s: np.ndarray

    @property
    def cv_rmse(self) -> float:
        return float(np.sqrt(np.mean(self.cv_residual ** 2)))

    def block_mse(self) -> dict[int, float]:
        return {int(b): float(np.mean(self.cv_residual[self.blocks == b] ** 2)) for b in np.unique(self.blocks)}


@checked_settings("selection settings", min_local_gain="[0, 1)", min_concentration="[0, inf)",
                  min_cv_gain="[0, 1)", min_block_share="(0, 1]")
class SelectionSettings:
    """The acceptance thresholds of a candidate term (module docstring: local gain, concentration,
    cross-validated gain, share of improved blocks)."""

    min_local_gain: float = 0.2
    min_concentration: float = 1.0
    min_cv_gain: float = 0.02
    min_block_share: float = 0.6


@dataclasses.dataclass(frozen=True)
class Assessment:
    """The verdict on one candidate term, with the numbers behind each check."""

    term: str
    candidate: ModelFit
    explains: bool
    predicts: bool
    physical: bool
    local_gain: float
    concentration: float
    cv_gain: float
    blocks_improved: str
    violations: tuple[str, ...]
    regimes: tuple[str, ...]

    @property
    def accepted(self) -> bool:
        return self.explains and self.predicts and self.physical

    @property
    def evidence(self) -> str:
        where = "/".join(self.regimes) or "no located mismatch"
        phys = "parameters physical" if self.physical else "unphysical: " + "; ".join(self.violations)
        return (f"mismatch in {where}: mean-square residual there -{100 * self.local_gain:.0f}% "
                f"(reduction concentration {self.concentration:.2f}); held-out RMSE -{100 * self.cv_gain:.1f}% "
                f"({self.blocks_improved} blocks with mismatch better, blocked CV); {phys}")


def mismatch_mask(fit: ModelFit, localisation: Localisation) -> np.ndarray:
    """Samples of ``fit`` lying inside a mismatch interval of ``localisation``."""
    mask = np.zeros(fit.time_s.size, dtype=bool)
    for name in np.unique(fit.recording):
        rows = fit.recording == name
        mask[rows] = localisation.mask(str(name), fit.time_s[rows])
    return mask


def physical_violations(parameters: Mapping[str, float], specs: Sequence[TermSpec]) -> tuple[str, ...]:
    """Parameters outside their bounds, as 'name=value outside [lo, hi]'."""
    bounds = {k: b for s in specs for k, b in s.bounds.items()}
    out = []
    for key, value in parameters.items():
        lo, hi = bounds.get(key, (-math.inf, math.inf))
        if not lo <= value <= hi:
            out.append(f"{key}={value:.4g} outside [{lo:g}, {hi:g}]")
    return tuple(out)


def assess(current: ModelFit, candidate: ModelFit, term: str, localisation: Localisation,
           specs: Sequence[TermSpec], settings: SelectionSettings | None = None) -> Assessment:
    """Apply checks (a), (b), (c) to adding ``term`` (``candidate``) to ``current``."""
    settings = settings or SelectionSettings()
    mask = mismatch_mask(current, localisation)
    before, after = current.fit.residuals ** 2, candidate.fit.residuals ** 2
    inside = mask.any()
    local_gain = 1 - after[mask].mean() / before[mask].mean() if inside and before[mask].mean() > 0 else 0.0
    reduction = before - after
    total = reduction.sum()
    concentration = (reduction[mask].sum() / total) / mask.mean() if inside and total > 0 else 0.0
    cv_gain = 1 - candidate.cv_rmse / current.cv_rmse if current.cv_rmse > 0 else 0.0
    old, new = current.block_mse(), candidate.block_mse()
    judged = [b for b in old if mask[current.blocks == b].any()] or list(old)
    better = sum(new[b] < old[b] for b in judged)
    violations = physical_violations(candidate.fit.parameters, specs)
    if not candidate.fit.success:
        violations += (f"fit failed: {candidate.fit.status}: {candidate.fit.message}",)
    regimes = tuple(sorted({m.regime for m in localisation.mismatches}))
    return Assessment(term, candidate,
                      explains=bool(inside and local_gain >= settings.min_local_gain
                                    and concentration >= settings.min_concentration),
                      predicts=bool(cv_gain >= settings.min_cv_gain and better >= settings.min_block_share * len(judged)),
                      physical=not violations, local_gain=float(local_gain), concentration=float(concentration),
                      cv_gain=float(cv_gain), blocks_improved=f"{better}/{len(judged)}", violations=violations,
                      regimes=regimes)


class SelectedTerms:
    """Mixin of a diagnosis holding a ``selection``: the terms it found missing, in order."""

    @property
    def missing_physics(self) -> list[str]:
        return [a.term for a in self.selection.accepted]


@dataclasses.dataclass(frozen=True)
class Selection:
    """Outcome of forward selection: fits, accepted terms (in order), all verdicts, mismatches."""

    baseline: ModelFit
    final: ModelFit
    accepted: tuple[Assessment, ...]
    assessments: tuple[Assessment, ...]
    baseline_localisation: Localisation
    final_localisation: Localisation


def forward_select(fit: Callable[[tuple[str, ...]], ModelFit], locate: Callable[[ModelFit], Localisation],
                   baseline: Sequence[str], library: Sequence[TermSpec], fixed: Sequence[TermSpec] = (),
                   settings: SelectionSettings | None = None) -> Selection:
    """Greedy forward selection over the candidate ``library`` starting from ``baseline`` (see
    module docstring); ``fixed`` gives bounds of baseline terms that are never candidates."""
    settings = settings or SelectionSettings()
    specs = tuple(library) + tuple(fixed)
    current = start = fit(tuple(baseline))
    found = first = locate(current)
    accepted, verdicts = [], []
    while found.mismatches:
        options = [s for s in library if s.name not in current.terms and set(s.requires) <= set(current.terms)]
        round_ = [assess(current, fit(current.terms + (s.name,)), s.name, found, specs, settings) for s in options]
        verdicts += round_
        for a in round_:
            log.info("candidate %s: %s -> %s", a.term, a.evidence, "accepted" if a.accepted else "rejected")
        good = [a for a in round_ if a.accepted]
        if not good:
            break
        best = max(good, key=lambda a: a.cv_gain)
        accepted.append(best)
        current = best.candidate
        found = locate(current)
    return Selection(start, current, tuple(accepted), tuple(verdicts), first, found)


# ----------------------------------------------------------------------------- joint search, nested tests
@dataclasses.dataclass(frozen=True)
class SubsetFit:
    """One fitted term set for :func:`subset_select`: residual sum of squares over ``n`` samples with
    ``n_parameters`` free parameters; ``tau`` is its residual's integrated autocorrelation time in
    samples (the variance inflation of a mean of correlated samples); ``admissible`` is False when the
    fit failed or an identifiable parameter left its physical range (``reason`` says which)."""

    terms: frozenset
    rss: float
    n: int
    n_parameters: int
    tau: float = 1.0
    admissible: bool = True
    reason: str = ""

    @property
    def rmse(self) -> float:
        return math.sqrt(self.rss / max(self.n, 1))


@dataclasses.dataclass(frozen=True)
class NestedTest:
    """Likelihood-ratio test of ``small`` against ``large``: Gaussian residuals, the effective sample
    size n / tau corrected for the residual autocorrelation of the larger model."""

    small: SubsetFit
    large: SubsetFit
    statistic: float
    df: int
    p_value: float
    rmse_drop: float  # 1 - rmse(large) / rmse(small)

    def significant(self, alpha: float, n_tests: int, min_rmse_drop: float) -> bool:
        """Bonferroni-corrected p below ``alpha`` AND a relative RMSE drop of at least ``min_rmse_drop``."""
        return self.p_value * max(n_tests, 1) < alpha and self.rmse_drop >= min_rmse_drop


def nested_test(small: SubsetFit, large: SubsetFit) -> NestedTest:
    """LR = (n / tau) ln(RSS_small / RSS_large) against chi^2 with the difference in parameter counts
    (at least 1: a non-nested pair of equal size is compared as if one parameter apart)."""
    n_eff = large.n / max(large.tau, 1.0)
    ratio = small.rss / large.rss if large.rss > 0 else math.inf
    statistic = float(n_eff * math.log(max(ratio, 1.0)))
    df = max(large.n_parameters - small.n_parameters, 1)
    drop = 1.0 - large.rmse / small.rmse if small.rmse > 0 else 0.0
    return NestedTest(small, large, statistic, df, float(stats.chi2.sf(statistic, df)), float(drop))


@checked_settings("subset selection settings", alpha="(0, 1)", min_rmse_drop="[0, 1)")
class SubsetSettings:
    """``alpha``: family-wise level of the nested tests (Bonferroni over the models compared);
    ``min_rmse_drop``: smallest relative RMSE drop that makes a term worth naming."""

    alpha: float = 0.001
    min_rmse_drop: float = 0.10


@dataclasses.dataclass(frozen=True)
class SubsetSelection:
    """Outcome of :func:`subset_select`: the chosen term set, the best-fitting admissible one, the
    equally good sets of the same size (what the data cannot tell apart), the per-term tests of the
    chosen set against itself without the term, and the number of tests the level is corrected for."""

    chosen: SubsetFit
    best: SubsetFit
    equivalent: tuple[SubsetFit, ...]
    term_tests: Mapping[str, NestedTest]
    n_tests: int
    fits: tuple[SubsetFit, ...]


def subset_select(fits: Sequence[SubsetFit], settings: SubsetSettings | None = None) -> SubsetSelection | None:
    """Joint search over fitted term sets (all subsets of a small candidate set).

    The reference is the admissible set with the smallest residual.  A set is adequate when the
    reference is not significantly better (:meth:`NestedTest.significant`, Bonferroni over the sets
    compared) and each of its terms is significant against the set without it (backward
    elimination).  The chosen set is the smallest adequate one (fewest terms, then parameters, then
    residual); other adequate sets of that size are its equivalents.  None if no fit is admissible."""
    settings = settings or SubsetSettings()
    admissible = [f for f in fits if f.admissible]
    if not admissible:
        return None
    best = min(admissible, key=lambda f: f.rss)
    n_tests = max(len(admissible) - 1, 1)

    by_terms = {f.terms: f for f in admissible}

    def significant(small: SubsetFit, large: SubsetFit) -> bool:
        return nested_test(small, large).significant(settings.alpha, n_tests, settings.min_rmse_drop)

    def needed(f: SubsetFit) -> bool:
        return all(significant(by_terms[f.terms - {t}], f) for t in f.terms if f.terms - {t} in by_terms)

    good = [f for f in admissible if f is best or not significant(f, best)]
    candidates = [f for f in good if needed(f)] or good
    chosen = min(candidates, key=lambda f: (len(f.terms), f.n_parameters, f.rss))
    equivalent = tuple(f for f in candidates if f is not chosen and len(f.terms) == len(chosen.terms))
    tests = {t: nested_test(by_terms[chosen.terms - {t}], chosen) for t in sorted(chosen.terms)
             if chosen.terms - {t} in by_terms}
    return SubsetSelection(chosen, best, equivalent, tests, n_tests, tuple(fits))


@dataclasses.dataclass(frozen=True)
class HeldOutCheck:
    """A term of a chosen set judged on data no fit saw: the pooled held-out RMSE of the set with the term and
    of the set without it over the ``segments`` that can judge it (e.g. leave one segment out: each segment
    predicted by a fit of the others).  Differences within ``tie_c`` (the noise of one reading) are ties;
    ``undecided`` says why no segment can judge the term (then the RMSEs are NaN).

    Verdicts: ``lowers`` (with < without - tie), ``raises`` (with > without + tie: the term is withdrawn),
    ``tie``, ``undecided``; only ``raises`` is evidence against the term."""

    term: str
    with_term: float = math.nan
    without: float = math.nan
    tie_c: float = 0.0
    segments: tuple[str, ...] = ()
    undecided: str = ""

    @property
    def verdict(self) -> str:
        if self.undecided:
            return "undecided"
        change = self.with_term - self.without
        return "lowers" if change < -self.tie_c else "raises" if change > self.tie_c else "tie"

    @property
    def improves(self) -> bool:
        return self.verdict == "lowers"

    @property
    def withdraws(self) -> bool:
        return self.verdict == "raises"

    def __str__(self) -> str:
        if self.undecided:
            return f"not judged: {self.undecided}"
        text = f"held-out RMSE {self.without:.3g} K without it, {self.with_term:.3g} K with it"
        return text + (f" (a tie: within the {self.tie_c:.2g} K noise of one reading)" if self.verdict == "tie" else "")


HeldOut = Callable[[str, frozenset, frozenset], HeldOutCheck]


def select_held_out(fits: Sequence[SubsetFit], held_out: HeldOut | None, fixed: frozenset = frozenset(),
                    settings: SubsetSettings | None = None) -> tuple[SubsetSelection | None, dict[str, HeldOutCheck]]:
    """:func:`subset_select`, then every term of the chosen set (but the ``fixed`` ones) judged on held-out
    data: ``held_out(term, chosen, chosen - {term})`` gives the :class:`HeldOutCheck`.  A term whose held-out
    RMSE is higher with it than without, beyond the tie, is withdrawn and the selection repeated among the sets
    without it, until no judged term of the chosen set raises the held-out error.  A tie or an undecided check
    (no segment can judge the term) is no evidence against it: the term stands on the in-sample test, as it
    does when there are no held-out data at all.  Returns the selection and the last check on every judged
    term (withdrawn ones included)."""
    withdrawn: set[str] = set()
    checks: dict[str, HeldOutCheck] = {}
    while True:
        selection = subset_select([f for f in fits if not f.terms & withdrawn], settings)
        if selection is None or held_out is None:
            return selection, checks
        chosen = selection.chosen.terms
        verdicts = {t: held_out(t, chosen, chosen - {t}) for t in sorted(chosen - fixed)}
        checks.update(verdicts)
        failed = {t for t, c in verdicts.items() if c.withdraws}
        for term in sorted(failed):
            log.info("%s withdrawn: %s", term, verdicts[term])
        if not failed:
            return selection, checks
        withdrawn |= failed
