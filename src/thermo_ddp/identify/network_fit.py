"""Output-error identification of a general thermal network on every sensor at once.

The free values (:class:`Free`: a dotted path of :mod:`~thermo_ddp.identify.network`, physical bounds,
log or linear scale) are CasADi symbols in the package's one network (``joint_heat_rhs``); the
recordings' grids (:func:`~thermo_ddp.identify.thermal_data.thermal_grid`, held inputs, sub-steps) are
integrated with the trapezoidal rule solved exactly for the affine network, with forward sensitivities
(as :mod:`~thermo_ddp.identify.thermal`), and every measured node contributes its residual weighted by
its own noise: sigma_s from the second differences of its readings (white noise adds 6 sigma^2 to the
variance of a second difference; a smooth temperature adds almost nothing), floored by the sensor's
quantisation and ``min_noise_c``.

Initial state of each segment: every measured node at its first reading; every unmeasured node at the
equilibrium of its own equation with the measured nodes held there (the first inputs held).

95 % intervals: s^2 (J^T J)^-1 of the weighted problem, inflated by sqrt(integrated autocorrelation
time) of the residuals (output-error residuals are autocorrelated), log-normal for log-scaled values; that
covariance (inflated, of log(value) or value) of the values with an interval, the others held at their fitted
values (the inverse of the information matrix's block of those values), is the file's ``[covariance]``.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Mapping, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from ..model.parameters import JointParameters
from ..model.scope import Covariance
from ..model.thermal import joint_heat_rhs
from .fit_report import Z95, covariance, integrated_autocorrelation
from ..model.network_spec import NetworkSpec
from .network import identification_network, iron_features, values_of, with_values
from .thermal_data import BOUNDARY_ROWS, INPUT_ROWS, ThermalGrid

log = logging.getLogger(__name__)
MIN_NOISE_C = 0.02  # a sensor's reading is not trusted below 0.02 K (calibration and lag of a thermocouple)
# A value whose standard error exceeds half of it (of its log for log-scaled values) is not pinned down by the
# data (NetworkFit.pinned): no [uncertainty] interval, listed in the diagnosis' not_determinable instead.
MAX_RELATIVE_ERROR = 0.5


@dataclasses.dataclass(frozen=True)
class Free:
    """A free value: its dotted path, physical bounds (inclusive) and whether it is fitted as log(value)."""

    path: str
    low: float
    high: float
    log: bool = True

    def theta(self, value: float) -> float:
        value = min(max(value, self.low), self.high)
        return math.log(value) if self.log else value

    def bounds(self) -> tuple[float, float]:
        return (math.log(self.low), math.log(self.high)) if self.log else (self.low, self.high)

    def value(self, theta: float) -> tuple[float, float]:
        """(value, d value / d theta)."""
        return (math.exp(theta),) * 2 if self.log else (theta, 1.0)


def sensor_noise(grids: Sequence[ThermalGrid], node: str) -> float:
    """Noise standard deviation of ``node``'s readings (module docstring)."""
    diffs = [np.diff(g.sensors[node], 2) for g in grids if node in g.sensors and len(g) > 3]
    if not diffs:
        return MIN_NOISE_C
    d2 = np.concatenate(diffs)
    sigma = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    steps = np.abs(np.concatenate([np.diff(g.sensors[node]) for g in grids if node in g.sensors]))
    steps = steps[steps > 1e-9]
    quantum = float(steps.min()) if steps.size else 0.0
    return max(sigma, quantum / math.sqrt(12.0), MIN_NOISE_C)


class NetworkModel:
    """``spec`` (``sensor``: the node ``temperature_c`` measures) with ``free`` values as symbols: step,
    initial state and their sensitivities."""

    def __init__(self, params: JointParameters, spec: NetworkSpec, sensor: str, free: Sequence[Free]):
        self.params, self.spec, self.sensor, self.free = params, spec, sensor, tuple(free)
        self.nodes = spec.node_names
        self._p = ca.SX.sym("free", len(self.free))
        sym = with_values(spec, {f.path: self._p[i] for i, f in enumerate(self.free)})
        self._network = identification_network(sym, sensor)
        self._rhs, self._temps, self._u = self._rhs_expression(sym)
        n, q = len(self.nodes), len(self.free)
        h = self._u[0]
        a = ca.jacobian(self._rhs, self._temps)
        nxt = self._temps + h * ca.solve(ca.SX.eye(n) - 0.5 * h * a, self._rhs)
        sens = ca.SX.sym("sensitivities", n, q)
        d_nxt = ca.jacobian(nxt, self._temps) @ sens + ca.jacobian(nxt, self._p)
        self.step = ca.Function("network_step", [ca.vertcat(self._temps, ca.vec(sens)), self._u, self._p],
                                [ca.vertcat(nxt, ca.vec(d_nxt))])
        self._maps: dict[int, ca.Function] = {}
        self._initials: dict[tuple[bool, ...], ca.Function] = {}

    def _rhs_expression(self, sym: NetworkSpec):
        temps = ca.SX.sym("temperatures_c", len(self.nodes))
        u = ca.SX.sym("inputs", len(INPUT_ROWS))
        row = {name: u[k] for k, name in enumerate(INPUT_ROWS)}
        held = {key: row[key] for key in INPUT_ROWS[1:] if key not in BOUNDARY_ROWS}
        held |= iron_features(sym, held)
        rhs = joint_heat_rhs(self._network, self.params.motor, temps, ca.sqrt(row["current_sq_a2"]), 0.0,
                             row["ambient_c"], held, row["room_c"])
        return rhs, temps, u

    def _initial(self, measured: tuple[bool, ...]) -> ca.Function:
        """x0: measured nodes at their readings y0, the others at equilibrium given them (first inputs)."""
        if measured not in self._initials:
            y0 = ca.SX.sym("first_readings_c", len(self.nodes))
            a = ca.jacobian(self._rhs, self._temps)
            b = ca.substitute(self._rhs, self._temps, ca.SX.zeros(len(self.nodes)))
            m = [i for i, k in enumerate(measured) if k]
            u = [i for i, k in enumerate(measured) if not k]
            x0 = ca.SX(y0)
            if u:
                xu = -ca.solve(a[u, u], a[u, m] @ y0[m] + b[u])
                for j, i in enumerate(u):
                    x0[i] = xu[j]
            self._initials[measured] = ca.Function("network_initial", [self._u, self._p, y0],
                                                   [ca.vertcat(x0, ca.vec(ca.jacobian(x0, self._p)))])
        return self._initials[measured]

    def simulate(self, grid: ThermalGrid, values: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """(node temperatures at the kept samples (nodes x K), their sensitivities (nodes x K x free))."""
        n, q = len(self.nodes), len(self.free)
        measured = tuple(node in grid.sensors for node in self.nodes)
        y0 = np.array([grid.sensors[node][0] if node in grid.sensors else 0.0 for node in self.nodes])
        p = np.asarray(values, float)
        z0 = np.asarray(self._initial(measured)(grid.inputs[:, 0], p, y0)).ravel()
        steps = grid.inputs.shape[1]
        if steps not in self._maps:
            self._maps[steps] = self.step.mapaccum("network_simulation", steps)
        z = np.asarray(self._maps[steps](z0, grid.inputs, p))
        z = np.column_stack([z0, z[:, grid.output_index]])
        sens = z[n:].reshape(q, n, -1).transpose(1, 2, 0) if q else np.zeros((n, z.shape[1], 0))
        return z[:n], sens


@dataclasses.dataclass(frozen=True)
class NetworkFit:
    """A fitted network: values by path, 95 % intervals, residuals per grid and sensor, noise per sensor."""

    spec: NetworkSpec
    sensor: str
    free: tuple[Free, ...]
    stderr: Mapping[str, float]          # of theta (log value for log-scaled paths), inflated
    residuals: Mapping[tuple[str, str], np.ndarray]   # (grid, node) -> measured - model
    simulated: Mapping[str, np.ndarray]  # grid -> nodes x K
    noise_c: Mapping[str, float]
    tau: float
    success: bool
    status: str
    message: str = ""
    information: np.ndarray | None = None   # J^T J / (s^2 tau) of theta (the inverse of stderr^2's covariance)

    @property
    def values(self) -> dict[str, float]:
        every = values_of(self.spec)
        return {f.path: float(every[f.path]) for f in self.free}

    @property
    def n(self) -> int:
        return int(sum(r.size for r in self.residuals.values()))

    @property
    def rss(self) -> float:
        """Noise-weighted residual sum of squares (the fit's cost)."""
        return float(sum(np.sum((r / self.noise_c[node]) ** 2) for (_, node), r in self.residuals.items()))

    def rmse(self, node: str | None = None, grids: Sequence[str] | None = None) -> float:
        """RMSE of ``node`` (the spec's sensor by default) over ``grids`` (all by default)."""
        node = node or self.sensor
        parts = [r for (g, s), r in self.residuals.items() if s == node and (grids is None or g in grids)]
        return float(np.sqrt(np.mean(np.concatenate(parts) ** 2))) if parts else math.nan

    def per_sensor(self) -> dict[str, float]:
        return {node: self.rmse(node) for node in dict.fromkeys(s for _, s in self.residuals)}

    @property
    def noise_ratio(self) -> float:
        """The largest per-sensor RMSE in units of its noise."""
        return max(self.rmse(s) / self.noise_c[s] for s in self.per_sensor())

    def interval(self, path: str) -> tuple[float, float]:
        """95 % interval of ``path``'s value, within the physical range searched (log-normal for log-scaled)."""
        f = next(f for f in self.free if f.path == path)
        value, err = self.values[path], self.stderr.get(path, math.inf)
        if f.log:
            factor = math.exp(min(Z95 * err, 700.0))
            lo, hi = value / factor, value * factor
        else:
            lo, hi = value - Z95 * err, value + Z95 * err
        return max(lo, f.low), min(hi, f.high)

    def pinned(self, path: str) -> bool:
        """Whether the data pin ``path`` down: its relative standard error is at most :data:`MAX_RELATIVE_ERROR`
        (a share's is relative to the whole share, 1: a share near 0 may be pinned down)."""
        if ".split." in path:
            return self.stderr.get(path, math.inf) <= MAX_RELATIVE_ERROR
        return self.relative_error(path) <= MAX_RELATIVE_ERROR

    def uncertainty(self) -> dict[str, list[float]]:
        """95 % interval of every fitted value the data pin down (the file's ``[uncertainty]``).  A value they do
        not pin down has none: its interval would be the range searched, and any band drawn from it (validate's
        ``band_k``) the spread of that range, not of what was learned (:meth:`undetermined` lists them)."""
        return {f.path: list(self.interval(f.path)) for f in self.free if self.pinned(f.path)}

    def covariance(self) -> Covariance | None:
        """The covariance of the values :meth:`uncertainty` gives intervals to, the values it gives none held at
        the fitted ones (the file's ``[covariance]``: what validate and the planner vary, the others as written)."""
        keep = [i for i, f in enumerate(self.free) if self.pinned(f.path)]
        if self.information is None or not keep:
            return None
        block = self.information[np.ix_(keep, keep)]
        d = np.sqrt(np.diag(block))
        cov = np.linalg.pinv(block / np.outer(d, d), hermitian=True) / np.outer(d, d)
        return Covariance.of([self.free[i].path for i in keep], ["log" if self.free[i].log else "linear" for i in keep],
                             0.5 * (cov + cov.T))

    def undetermined(self) -> dict[str, tuple[float, float]]:
        """The fitted values the data do not pin down, with their 95 % intervals within the range searched."""
        return {f.path: self.interval(f.path) for f in self.free if not self.pinned(f.path)}

    def relative_error(self, path: str) -> float:
        """Standard error relative to the value (log-scaled: the standard error of log(value))."""
        f = next(f for f in self.free if f.path == path)
        err = self.stderr.get(path, math.inf)
        return err if f.log else err / max(abs(self.values[path]), 1e-12)


def fit_network(params: JointParameters, spec: NetworkSpec, sensor: str, free: Sequence[Free],
                grids: Sequence[ThermalGrid], *, weights: Sequence[float] | None = None,
                noise: Mapping[str, float] | None = None, max_nfev: int = 100) -> NetworkFit:
    """Fit ``free`` values of ``spec`` (their start: the spec's) to every sensor of ``grids``.  ``weights``
    (per grid, 0 or 1) selects the grids the cost sees; residuals are returned for all."""
    model = NetworkModel(params, spec, sensor, free)
    weights = [1.0] * len(grids) if weights is None else list(weights)
    sensors = [n for n in model.nodes if any(n in g.sensors for g in grids)]
    noise = dict(noise or {n: sensor_noise(grids, n) for n in sensors})
    start = values_of(spec)
    theta0 = np.array([f.theta(float(start[f.path])) for f in free])
    lo, hi = (np.array(b) for b in zip(*(f.bounds() for f in free))) if free else (np.zeros(0), np.zeros(0))
    cache: dict[bytes, tuple] = {}

    def evaluate(theta):
        key = theta.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = _residuals(model, grids, theta, weights, noise, sensors)
        return cache[key]

    if free:
        try:
            sol = optimize.least_squares(lambda t: evaluate(t)[0], np.clip(theta0, lo, hi), lambda t: evaluate(t)[1],
                                         bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=max_nfev,
                                         ftol=1e-6, xtol=1e-8, gtol=1e-8)
        except ValueError as err:
            return NetworkFit(spec, sensor, tuple(free), {}, {}, {}, noise, 1.0, False, "not_finite",
                              f"not finite at the start ({err})")
        theta, ok, status, message = sol.x, sol.status > 0 or sol.status == 0, _status(sol.status), sol.message
    else:
        theta, ok, status, message = theta0, True, "converged", "nothing free"
    return _result(model, grids, theta, weights, noise, sensors, ok, status, message)


def _status(code: int) -> str:
    return "max_iterations" if code == 0 else "converged" if code > 0 else "failed"


def _residuals(model: NetworkModel, grids, theta, weights, noise, sensors):
    """Stacked weighted residuals (model - reading) / sigma and their Jacobian by theta."""
    vals, dval = (np.array(v) for v in zip(*(f.value(t) for f, t in zip(model.free, theta)))) \
        if model.free else (np.zeros(0), np.zeros(0))
    rows, jacs = [], []
    for grid, w in zip(grids, weights):
        if not w:
            continue
        temps, sens = model.simulate(grid, vals)
        for node in sensors:
            if node in grid.sensors:
                i = model.nodes.index(node)
                rows.append((temps[i] - grid.sensors[node]) / noise[node])
                jacs.append(sens[i] * dval / noise[node])
    r, j = np.concatenate(rows), np.vstack(jacs)
    if not np.all(np.abs(r) < 1e8):
        r = np.full_like(r, np.inf)
    return r, j


def _result(model: NetworkModel, grids, theta, weights, noise, sensors, ok, status, message) -> NetworkFit:
    vals = np.array([f.value(t)[0] for f, t in zip(model.free, theta)])
    spec = with_values(model.spec, {f.path: float(v) for f, v in zip(model.free, vals)})
    residuals, simulated = {}, {}
    for grid in grids:
        temps, _ = model.simulate(grid, vals)
        simulated[grid.name] = temps
        for node in sensors:
            if node in grid.sensors:
                residuals[(grid.name, node)] = grid.sensors[node] - temps[model.nodes.index(node)]
    seen = [r / noise[node] for (g, node), r in residuals.items()
            if weights[[x.name for x in grids].index(g)]]
    tau = sum(r.size for r in seen) / sum(r.size / integrated_autocorrelation(r) for r in seen)
    stderr, info = {}, None
    if model.free:
        _, jac = _residuals(model, grids, theta, weights, noise, sensors)
        r = np.concatenate(seen)
        cov, _ = covariance(jac, r)
        stderr = {f.path: math.sqrt(tau * max(cov[i, i], 0.0)) for i, f in enumerate(model.free)}
        info = jac.T @ jac / (tau * float(r @ r) / max(r.size - len(model.free), 1))
    finite = all(np.all(np.isfinite(r)) for r in residuals.values())
    return NetworkFit(spec, model.sensor, model.free, stderr, residuals, simulated, noise, tau, bool(ok and finite), status,
                      str(message), info)

