"""Where is a residual systematic?  General mismatch localisation (any physics).

Input: per recording, the residual (measured - model), its time base and a regime label per
sample (``"moving"``, ``"heating"``, ...), optionally an *orientation* per sample (±1; e.g. the
sign of the velocity, so that an effect that flips with the motion direction adds up instead
of cancelling).  Output: mismatch intervals in the contract shape
``{"recording", "start_s", "end_s", "regime", "mean_residual"}``.

The test respects autocorrelation by never treating samples as independent.  The unit of
evidence is an *occurrence*: a maximal run of samples with the same regime and orientation.
Residual noise is coloured but forgets itself after its correlation time ``tau`` (first lag
where the residual's autocorrelation falls below 1/e, measured on the residual itself, which
over-estimates ``tau`` when a mismatch is present: the conservative side).  Occurrences of one
regime starting less than ``tau`` after the previous one are merged into one cluster; long
occurrences are cut into batches of at least ``batch_taus``·tau when there are too few
clusters (batch means).  Missing physics repeats every time its regime recurs, noise does not:
a regime is systematic when the oriented cluster means are consistently non-zero by a
Student-t test across clusters (effective sample size = number of clusters; Bonferroni over
regimes, family-wise false-alarm rate ``alpha``) *and* the effect is at least ``min_effect``
times the robust residual scale.  The reported intervals are that regime's occurrences whose
own oriented mean has the regime's sign and passes the effect threshold.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Sequence

import numpy as np
from scipy import stats

from .._config import checked_settings
from ..errors import InputError
from ..identify.fit_report import correlation_time

log = logging.getLogger(__name__)


@checked_settings("localise settings", alpha="(0, 1)", min_effect="[0, inf)", min_clusters="[3, inf)",
                  batch_taus="[1, inf)")
class LocaliseSettings:
    """``alpha``: family-wise false-alarm probability per call; ``min_effect``: smallest systematic
    mean worth reporting, in robust residual scales; ``min_clusters``: fewest independent clusters
    for a test; ``batch_taus``: batch length in correlation times when occurrences are too few."""

    alpha: float = 0.01
    min_effect: float = 0.25
    min_clusters: int = 5
    batch_taus: float = 5.0


@dataclasses.dataclass(frozen=True)
class ResidualSeries:
    """One recording's residual with per-sample regime labels (and optional ±1 orientation)."""

    recording: str
    time_s: np.ndarray
    residual: np.ndarray
    regimes: np.ndarray
    orientation: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.time_s)[0]
        for field in ("residual", "regimes", "orientation"):
            value = getattr(self, field)
            if value is not None and np.shape(value) != (n,):
                raise InputError(self.recording, field, f"shape {np.shape(value)}", f"expected ({n},) like time_s")
        if not np.all(np.isfinite(self.residual)):
            raise InputError(self.recording, "residual", "NaN/inf", "the residual must be finite")

    @property
    def signs(self) -> np.ndarray:
        return np.ones(len(self.time_s)) if self.orientation is None else np.where(np.asarray(self.orientation) < 0, -1.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Mismatch:
    """A systematic residual interval (contract shape via ``to_dict``)."""

    recording: str
    start_s: float
    end_s: float
    regime: str
    mean_residual: float

    def to_dict(self) -> dict:
        return {"recording": self.recording, "start_s": float(self.start_s), "end_s": float(self.end_s),
                "regime": self.regime, "mean_residual": float(self.mean_residual)}


@dataclasses.dataclass(frozen=True)
class RegimeTest:
    """The across-cluster test of one regime."""

    regime: str
    clusters: int
    mean: float          # oriented mean over clusters
    t_statistic: float
    p_value: float
    effect: float        # |mean| / robust residual scale
    systematic: bool
    tested: bool


@dataclasses.dataclass(frozen=True)
class Localisation:
    mismatches: tuple[Mismatch, ...]
    tests: tuple[RegimeTest, ...]
    scale: float         # robust residual scale (1.4826 MAD)
    tau_s: float         # residual correlation time used for clustering

    def mask(self, recording: str, time_s: np.ndarray) -> np.ndarray:
        """Samples of ``recording`` at ``time_s`` that lie inside a reported mismatch."""
        inside = np.zeros(len(time_s), dtype=bool)
        for m in self.mismatches:
            if m.recording == recording:
                inside |= (time_s >= m.start_s) & (time_s <= m.end_s)
        return inside

    def to_list(self) -> list[dict]:
        return [m.to_dict() for m in self.mismatches]


@dataclasses.dataclass(frozen=True)
class _Occurrence:
    series: int
    start: int
    stop: int        # exclusive
    regime: str
    sign: float


def robust_scale(residual: np.ndarray) -> float:
    """1.4826 × median absolute deviation (the standard deviation for Gaussian noise)."""
    r = np.asarray(residual, float)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def _occurrences(index: int, s: ResidualSeries) -> list[_Occurrence]:
    labels = np.asarray(s.regimes).astype(str)
    signs = s.signs
    change = np.flatnonzero((labels[1:] != labels[:-1]) | (signs[1:] != signs[:-1])) + 1
    bounds = np.concatenate(([0], change, [len(labels)]))
    return [_Occurrence(index, int(a), int(b), labels[a], float(signs[a])) for a, b in zip(bounds[:-1], bounds[1:])]


def _oriented_mean(series: Sequence[ResidualSeries], occ: _Occurrence) -> float:
    return float(occ.sign * np.mean(series[occ.series].residual[occ.start:occ.stop]))


def _clusters(series, occs: list[_Occurrence], tau_s: float, batch_s: float, min_clusters: int) -> list[float]:
    """Oriented cluster means: occurrences closer than tau merged; batched if too few clusters."""
    groups: list[list[_Occurrence]] = []
    for occ in occs:
        last = groups[-1][-1] if groups else None
        t = series[occ.series].time_s
        if last is not None and last.series == occ.series and t[occ.start] - t[last.stop - 1] < tau_s:
            groups[-1].append(occ)
        else:
            groups.append([occ])
    if len(groups) < min_clusters:
        groups = [[b] for g in groups for o in g for b in _batches(series, o, batch_s)]
    means = []
    for group in groups:
        weights = np.array([o.stop - o.start for o in group], float)
        means.append(float(np.average([_oriented_mean(series, o) for o in group], weights=weights)))
    return means


def _batches(series, occ: _Occurrence, batch_s: float) -> list[_Occurrence]:
    t = series[occ.series].time_s[occ.start:occ.stop]
    count = max(int((t[-1] - t[0]) // batch_s), 1) if batch_s > 0 else 1
    edges = np.linspace(occ.start, occ.stop, count + 1).astype(int)
    return [dataclasses.replace(occ, start=int(a), stop=int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def _test(regime: str, means: list[float], scale: float, threshold_p: float, settings: LocaliseSettings) -> RegimeTest:
    k = len(means)
    if k < settings.min_clusters:
        return RegimeTest(regime, k, float(np.mean(means)) if means else 0.0, 0.0, 1.0, 0.0, False, False)
    mean = float(np.mean(means))
    sd = float(np.std(means, ddof=1))
    t_stat = mean / (sd / np.sqrt(k)) if sd > 0 else (np.inf if mean else 0.0)
    p = float(2 * stats.t.sf(abs(t_stat), k - 1))
    effect = abs(mean) / scale if scale > 0 else np.inf
    return RegimeTest(regime, k, mean, float(t_stat), p, float(effect),
                      bool(p < threshold_p and effect >= settings.min_effect), True)


def localise(series: Sequence[ResidualSeries] | ResidualSeries, settings: LocaliseSettings | None = None) -> Localisation:
    """Find systematic residual intervals across ``series`` (regimes pooled over recordings)."""
    settings = settings or LocaliseSettings()
    series = [series] if isinstance(series, ResidualSeries) else list(series)
    scale = robust_scale(np.concatenate([s.residual for s in series]))
    tau_s = max(correlation_time(s.time_s, s.residual) for s in series)
    occs = [o for i, s in enumerate(series) for o in _occurrences(i, s)]
    regimes = sorted({o.regime for o in occs})
    threshold_p = settings.alpha / max(len(regimes), 1)
    tests, mismatches = [], []
    for regime in regimes:
        mine = [o for o in occs if o.regime == regime]
        test = _test(regime, _clusters(series, mine, tau_s, settings.batch_taus * tau_s, settings.min_clusters),
                     scale, threshold_p, settings)
        tests.append(dataclasses.replace(test, regime=str(regime)))
        log.debug("regime %s: %s", regime, test)
        if not test.systematic:
            continue
        for o in mine:
            m = _oriented_mean(series, o)
            if np.sign(m) == np.sign(test.mean) and abs(m) >= settings.min_effect * scale:
                s = series[o.series]
                mismatches.append(Mismatch(s.recording, float(s.time_s[o.start]), float(s.time_s[o.stop - 1]),
                                           str(regime), float(np.mean(s.residual[o.start:o.stop]))))
    mismatches.sort(key=lambda m: (m.recording, m.start_s))
    return Localisation(tuple(mismatches), tuple(tests), scale, tau_s)
