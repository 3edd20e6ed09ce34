"""Thermal regimes and mismatch localisation for slow (thermal) residuals.

Regimes (per kept sample, from the held inputs and the measured temperature):
``moving`` – RMS joint speed over ``window_s`` above ``moving_rad_s``; otherwise, under load
(RMS current over ``window_s`` above ``load_a``): ``heating`` when the temperature trend is above
``trend_k_per_h``, else ``static``; without load: ``cooling`` when the trend is below
``-trend_k_per_h``, else ``idle``.  The trend is the local least-squares slope of the *measured*
temperature over ``trend_window_s``: regimes must not depend on the model under test.

Localisation.  The general localiser (``localise.py``) estimates the residual's correlation time
from the residual itself; a thermal mismatch is a slow residual lasting as long as the recording,
so that estimate swallows the mismatch (one cluster per recording, nothing testable).  Here the
noise is measured where a mismatch cannot hide: the residual minus its moving mean over
``noise_window_s`` (high-pass) gives the noise scale ``sigma`` and its integrated autocorrelation
time ``tau`` (variance inflation of a mean of correlated samples).  Every regime occurrence is cut
into windows of about ``window_s``; a window is systematic when its mean residual ``m`` passes a
z-test against noise, ``|m| > z sigma sqrt(tau / n)`` (Bonferroni over all windows, family-wise
false-alarm rate ``alpha``), *and* ``|m| >= min_effect_c`` (default 0: no absolute gate; whether a
term is worth naming is the selection's nested test, not a window size).
Adjacent systematic windows of one occurrence with the same sign are merged into intervals.
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np
from scipy import stats

from .._config import checked_settings
from ..identify.fit_report import integrated_autocorrelation
from ..identify.thermal_data import ThermalGrid
from .localise import Localisation, Mismatch, RegimeTest, ResidualSeries, robust_scale

THERMAL_REGIMES = ("heating", "cooling", "idle", "moving", "static")


@checked_settings("thermal regime settings", window_s="(0, inf)", moving_rad_s="(0, inf)", load_a="(0, inf)",
                  trend_window_s="(0, inf)", trend_k_per_h="(0, inf)")
class ThermalRegimeSettings:
    """How samples are labelled moving / heating / static / cooling / idle (module docstring)."""

    window_s: float = 60.0
    moving_rad_s: float = 0.1
    load_a: float = 0.5
    trend_window_s: float = 600.0
    trend_k_per_h: float = 1.0


@checked_settings("thermal localise settings", window_s="(0, inf)", noise_window_s="(0, inf)",
                  min_effect_c="[0, inf)", alpha="(0, 1)", min_samples="[2, inf)")
class ThermalLocaliseSettings:
    """Windows of about ``window_s`` are tested against the noise of a ``noise_window_s`` high-pass at
    false-alarm rate ``alpha``; a systematic window must be at least ``min_effect_c`` in size (default 0) and hold
    ``min_samples`` samples (module docstring)."""

    window_s: float = 600.0
    noise_window_s: float = 120.0
    min_effect_c: float = 0.0
    alpha: float = 0.01
    min_samples: int = 3


def held_window_mean(grid: ThermalGrid, row: int, half_s: float) -> np.ndarray:
    """Time average of a held input (row of ``grid.inputs``) over [t - half, t + half] at kept samples."""
    h = grid.inputs[0]
    edges = grid.time_s[0] + np.concatenate(([0.0], np.cumsum(h)))
    integral = np.concatenate(([0.0], np.cumsum(h * grid.inputs[row])))
    lo = np.clip(grid.time_s - half_s, edges[0], edges[-1])
    hi = np.clip(grid.time_s + half_s, edges[0], edges[-1])
    span = np.maximum(hi - lo, 1e-9)
    return (np.interp(hi, edges, integral) - np.interp(lo, edges, integral)) / span


def local_slope(time_s: np.ndarray, values: np.ndarray, window_s: float) -> np.ndarray:
    """Least-squares slope of ``values`` over a centred window at every sample (irregular times)."""
    t = (time_s - time_s[0]) / window_s
    sums = [np.concatenate(([0.0], np.cumsum(x))) for x in (np.ones_like(t), t, values, t * t, t * values)]
    lo = np.searchsorted(t, t - 0.5, side="left")
    hi = np.searchsorted(t, t + 0.5, side="right")
    n, st, sy, stt, sty = ((s[hi] - s[lo]) for s in sums)
    den = n * stt - st * st
    slope = np.where(den > 1e-12, (n * sty - st * sy) / np.where(den > 1e-12, den, 1.0), 0.0)
    return slope / window_s


def thermal_regimes(grid: ThermalGrid, settings: ThermalRegimeSettings | None = None) -> np.ndarray:
    """Regime label of every kept sample of ``grid`` (see module docstring)."""
    s = settings or ThermalRegimeSettings()
    speed = np.sqrt(held_window_mean(grid, 3, 0.5 * s.window_s))
    current = np.sqrt(held_window_mean(grid, 1, 0.5 * s.window_s))
    trend = local_slope(grid.time_s, grid.measured_c, s.trend_window_s) * 3600.0
    labels = np.where(trend < -s.trend_k_per_h, "cooling", "idle").astype(object)
    loaded = current > s.load_a
    labels[loaded] = np.where(trend[loaded] > s.trend_k_per_h, "heating", "static")
    labels[speed > s.moving_rad_s] = "moving"
    return labels.astype(str)


def _moving_mean(time_s: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    csum = np.concatenate(([0.0], np.cumsum(x)))
    lo = np.searchsorted(time_s, time_s - 0.5 * window_s, side="left")
    hi = np.searchsorted(time_s, time_s + 0.5 * window_s, side="right")
    return (csum[hi] - csum[lo]) / (hi - lo)


@dataclasses.dataclass(frozen=True)
class NoiseModel:
    sigma_c: float
    tau: float  # integrated autocorrelation time, in samples

    def standard_error(self, n: int) -> float:
        return self.sigma_c * float(np.sqrt(self.tau / max(n, 1)))


def noise_model(s: ResidualSeries, window_s: float) -> NoiseModel:
    """Noise scale and correlation of the high-passed residual (a slow mismatch cannot hide there)."""
    high = s.residual - _moving_mean(s.time_s, s.residual, window_s)
    return NoiseModel(max(robust_scale(high), float(np.std(high)) * 0.5, 1e-6), integrated_autocorrelation(high))


def _windows(s: ResidualSeries, window_s: float, min_samples: int) -> list[tuple[int, int, str, int]]:
    """(start, stop, regime, occurrence) of windows of about ``window_s`` inside each regime run."""
    labels = np.asarray(s.regimes).astype(str)
    change = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    bounds = np.concatenate(([0], change, [labels.size]))
    out = []
    for occ, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        t = s.time_s[a:b]
        count = max(int(round((t[-1] - t[0]) / window_s)), 1)
        edges = np.searchsorted(t, np.linspace(t[0], t[-1], count + 1)[1:-1]) + a
        for lo, hi in zip(np.concatenate(([a], edges)), np.concatenate((edges, [b]))):
            if hi - lo >= min_samples:
                out.append((int(lo), int(hi), str(labels[a]), occ))
    return out


def locate_thermal(series: Sequence[ResidualSeries] | ResidualSeries,
                   settings: ThermalLocaliseSettings | None = None) -> Localisation:
    """Systematic residual intervals of thermal recordings (see module docstring)."""
    settings = settings or ThermalLocaliseSettings()
    series = [series] if isinstance(series, ResidualSeries) else list(series)
    noise = [noise_model(s, settings.noise_window_s) for s in series]
    windows = [(k, w) for k, s in enumerate(series) for w in _windows(s, settings.window_s, settings.min_samples)]
    z_crit = float(stats.norm.isf(settings.alpha / (2 * max(len(windows), 1))))
    per_regime: dict[str, list[tuple[float, float, bool]]] = {}
    flagged: list[tuple[int, int, int, str, int, float]] = []
    for k, (lo, hi, regime, occ) in windows:
        mean = float(np.mean(series[k].residual[lo:hi]))
        z = mean / noise[k].standard_error(hi - lo)
        hit = abs(z) > z_crit and abs(mean) >= settings.min_effect_c
        per_regime.setdefault(regime, []).append((mean, z, hit))
        if hit:
            flagged.append((k, lo, hi, regime, occ, np.sign(mean)))
    mismatches = _merge(series, flagged)
    scale = float(np.median([n.sigma_c for n in noise]))
    tests = tuple(_regime_test(regime, rows, scale, z_crit, len(windows)) for regime, rows in sorted(per_regime.items()))
    dt = float(np.median(np.concatenate([np.diff(s.time_s) for s in series if s.time_s.size > 1]))) if series else 0.0
    tau_s = float(max(n.tau for n in noise) * dt) if noise else 0.0
    return Localisation(tuple(sorted(mismatches, key=lambda m: (m.recording, m.start_s))), tests, scale, tau_s)


def _merge(series: Sequence[ResidualSeries], flagged) -> list[Mismatch]:
    out, current = [], None
    for k, lo, hi, regime, occ, sign in flagged:
        if current and current[0] == k and current[4] == occ and current[5] == sign and current[2] == lo:
            current = (k, current[1], hi, regime, occ, sign)
            continue
        if current:
            out.append(current)
        current = (k, lo, hi, regime, occ, sign)
    if current:
        out.append(current)
    return [Mismatch(series[k].recording, float(series[k].time_s[lo]), float(series[k].time_s[hi - 1]), regime,
                     float(np.mean(series[k].residual[lo:hi]))) for k, lo, hi, regime, _, _ in out]


def _regime_test(regime: str, rows, scale: float, z_crit: float, n_windows: int) -> RegimeTest:
    means = np.array([r[0] for r in rows])
    zs = np.array([r[1] for r in rows])
    worst = int(np.argmax(np.abs(zs)))
    p = float(min(1.0, 2 * stats.norm.sf(abs(zs[worst])) * n_windows))
    return RegimeTest(regime, len(rows), float(np.mean(means)), float(zs[worst]), p,
                      float(np.max(np.abs(means)) / scale) if scale > 0 else float("inf"),
                      bool(any(r[2] for r in rows)), True)
