"""Fit results shared by every identification (mechanical, thermal): values, uncertainty, report.

:class:`FitResult` holds what a least-squares fit produced; :func:`linear_fit` solves a linear
problem ``y ≈ X p`` and :func:`result_from_jacobian` turns any nonlinear least-squares solution
(e.g. ``scipy.optimize.least_squares``: ``x``, ``fun``, ``jac``) into the same object, so that
thermal and mechanical fits print the same lmfit-style ``fit_report()``.

Standard errors are the classical ones, ``s² (JᵀJ)⁻¹`` with ``s²`` the residual variance; they
assume white residuals and are optimistic when the residual is autocorrelated (the report says so).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

import numpy as np
from scipy import stats

Z95 = float(stats.norm.ppf(0.975))


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Outcome of one least-squares fit.

    ``parameters`` holds every value of the model; ``stderr`` only those estimated by least
    squares (a parameter chosen by a grid search, e.g. a Stribeck velocity, has none).
    ``residuals`` are measured minus fitted, on the samples the fit used (``time_s``).
    """

    model: str
    parameters: Mapping[str, float]
    stderr: Mapping[str, float]
    residuals: np.ndarray
    fitted: np.ndarray
    success: bool
    status: str
    message: str
    time_s: np.ndarray | None = None
    units: Mapping[str, str] = dataclasses.field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def n_samples(self) -> int:
        return int(self.residuals.size)

    @property
    def n_parameters(self) -> int:
        return len(self.parameters)

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.residuals ** 2))) if self.residuals.size else 0.0

    @property
    def confidence(self) -> dict[str, tuple[float, float]]:
        """95 % normal-approximation intervals of the least-squares parameters."""
        return {k: (self.parameters[k] - Z95 * s, self.parameters[k] + Z95 * s) for k, s in self.stderr.items()}

    @property
    def aic(self) -> float:
        n = max(self.n_samples, 1)
        return n * math.log(max(self.rmse ** 2, 1e-300)) + 2 * self.n_parameters

    @property
    def bic(self) -> float:
        n = max(self.n_samples, 1)
        return n * math.log(max(self.rmse ** 2, 1e-300)) + math.log(n) * self.n_parameters

    def summary(self) -> dict:
        """The contract's ``{"model", "rmse", "parameters"}`` block of the diagnosis JSON."""
        return {"model": self.model, "rmse": self.rmse, "parameters": {k: float(v) for k, v in self.parameters.items()}}

    def fit_report(self) -> str:
        """A multi-line, lmfit-style report: statistics, then each parameter ± stderr and its 95 % CI."""
        lines = ["[[Model]]", f"    {self.model}", "[[Fit Statistics]]",
                 f"    status             = {self.status} ({'success' if self.success else 'FAILED'})",
                 f"    message            = {self.message}",
                 f"    # data points      = {self.n_samples}",
                 f"    # variables        = {self.n_parameters}",
                 f"    rmse               = {self.rmse:.6g}",
                 f"    Akaike info crit   = {self.aic:.2f}",
                 f"    Bayesian info crit = {self.bic:.2f}", "[[Variables]]"]
        width = max((len(k) for k in self.parameters), default=0)
        for key, value in self.parameters.items():
            unit = f" {self.units[key]}" if key in self.units else ""
            if key in self.stderr:
                err = self.stderr[key]
                rel = f" ({100 * err / abs(value):.2f}%)" if value else ""
                lo, hi = self.confidence[key]
                lines.append(f"    {key:<{width}}: {value:.6g} +/- {err:.3g}{rel}{unit}  95% CI [{lo:.6g}, {hi:.6g}]")
            else:
                lines.append(f"    {key:<{width}}: {value:.6g}{unit} (fixed by search, no stderr)")
        lines += [f"    note: {n}" for n in self.notes]
        lines.append("    note: standard errors assume white residuals (optimistic if the residual is autocorrelated)")
        return "\n".join(lines)

    report = fit_report


def failed_fit(model: str, y: np.ndarray, status: str, message: str, time_s: np.ndarray | None = None) -> FitResult:
    """A FitResult that says the fit failed (no parameters; residual = the data, never NaN)."""
    y = np.asarray(y, dtype=float)
    return FitResult(model=model, parameters={}, stderr={}, residuals=y.copy(), fitted=np.zeros_like(y),
                     success=False, status=status, message=message, time_s=time_s)


def result_from_jacobian(model: str, names: Sequence[str], values: Sequence[float], residuals: np.ndarray,
                         jacobian: np.ndarray, *, fitted: np.ndarray, extra: Mapping[str, float] | None = None,
                         time_s: np.ndarray | None = None, units: Mapping[str, str] | None = None,
                         status: str = "ok", message: str = "converged", notes: Sequence[str] = ()) -> FitResult:
    """Build a FitResult from a least-squares solution: ``values`` of ``names``, residuals and the
    Jacobian of the *model output* (or of the residual: the sign does not matter) w.r.t. ``names``.

    ``extra`` adds parameters fixed by a search (no standard error).  A rank-deficient Jacobian
    gives ``success=False`` and status ``"rank_deficient"``; the values are still returned.
    """
    residuals = np.asarray(residuals, dtype=float)
    jacobian = np.asarray(jacobian, dtype=float).reshape(residuals.size, len(names))
    n, p = jacobian.shape
    cov, rank = covariance(jacobian, residuals)
    parameters = {k: float(v) for k, v in zip(names, values)}
    parameters.update({k: float(v) for k, v in (extra or {}).items()})
    if rank < p or n <= p:
        why = f"rank {rank} < {p} parameters" if rank < p else f"{n} samples for {p} parameters"
        return FitResult(model, parameters, {}, residuals, np.asarray(fitted, float), False, "rank_deficient",
                         f"parameters not identifiable from these data ({why})", time_s, dict(units or {}), tuple(notes))
    stderr = {k: float(math.sqrt(max(cov[i, i], 0.0))) for i, k in enumerate(names)}
    return FitResult(model, parameters, stderr, residuals, np.asarray(fitted, float), True, status, message,
                     time_s, dict(units or {}), tuple(notes))


def covariance(jacobian: np.ndarray, residuals: np.ndarray, floor: float = 1e-9) -> tuple[np.ndarray, int]:
    """``s^2 (J^T J)^-1`` (columns scaled to unit norm) and the numerical rank of ``J``.  Singular values
    below ``floor`` times the largest are raised to it, so a rank-deficient Jacobian gives huge but finite
    variances along its null space (the correlations then name the collinear parameters)."""
    n, p = jacobian.shape
    scale = np.linalg.norm(jacobian, axis=0)
    scale[scale == 0] = 1.0
    _, sing, vt = np.linalg.svd(jacobian / scale, full_matrices=False)
    if not sing.size or sing.max() == 0:
        return np.zeros((p, p)), 0
    rank = int(np.sum(sing > sing.max() * max(n, p) * np.finfo(float).eps * 1e3))
    sing = np.maximum(sing, floor * sing.max())
    s2 = float(residuals @ residuals) / max(n - p, 1)
    return (vt.T / sing ** 2) @ vt / np.outer(scale, scale) * s2, rank


def correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance matrix."""
    sd = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return cov / np.outer(sd, sd)


def linear_fit(X: np.ndarray, y: np.ndarray, names: Sequence[str], *, model: str | None = None,
               extra: Mapping[str, float] | None = None, time_s: np.ndarray | None = None,
               units: Mapping[str, str] | None = None, notes: Sequence[str] = ()) -> FitResult:
    """Ordinary least squares ``y ≈ X p`` (columns of ``X`` named ``names``), as a FitResult."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    model = model or " + ".join(names)
    if X.ndim != 2 or X.shape[0] != y.size or X.shape[1] != len(names):
        return failed_fit(model, y, "bad_shape", f"regressor {X.shape} does not match {y.size} samples, {len(names)} names", time_s)
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
        return failed_fit(model, y, "non_finite", "regressor or data contain NaN or inf", time_s)
    values, *_ = np.linalg.lstsq(X, y, rcond=None)
    fitted = X @ values
    return result_from_jacobian(model, names, values, y - fitted, X, fitted=fitted, extra=extra,
                                time_s=time_s, units=units, message="linear least squares", notes=notes)


def autocorrelation(residual: np.ndarray) -> np.ndarray | None:
    """Normalised autocorrelation of a residual at lags 0..n-1 (FFT estimate); None if constant."""
    x = np.asarray(residual, float) - np.mean(residual)
    if not np.any(x):
        return None
    spectrum = np.fft.rfft(x, 2 * x.size)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:x.size]
    return acf / acf[0]


def correlation_time(time_s: np.ndarray, residual: np.ndarray) -> float:
    """First lag (seconds) where the residual's autocorrelation drops below 1/e."""
    acf = autocorrelation(residual) if np.size(residual) >= 3 else None
    if acf is None:
        return 0.0
    below = np.flatnonzero(acf < np.exp(-1.0))
    lag = below[0] if below.size else acf.size
    return float(lag * np.median(np.diff(time_s)))


def integrated_autocorrelation(residual: np.ndarray) -> float:
    """1 + 2 sum of autocorrelations (Geyer's initial positive sequence): variance inflation of a mean."""
    acf = autocorrelation(residual) if np.size(residual) >= 4 else None
    if acf is None:
        return 1.0
    n = acf.size
    m = n // 2
    gamma = acf[0:2 * m:2] + acf[1:2 * m:2]  # Gamma_k = rho_2k + rho_2k+1
    stop = np.flatnonzero(gamma <= 0)
    tau = -1.0 + 2.0 * gamma[: stop[0] if stop.size else m].sum()
    return float(min(max(tau, 1.0), n))
