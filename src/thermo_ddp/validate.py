"""Validation of a parameter file on recordings: predict, do not refit (``thermo-ddp validate``).

Each recording (each segment of a split CSV) is simulated open loop with the file's thermal network
(``network_from_parameters``, heated through ``joint_heat_rhs``) from every measured node at its first
measurement (the others at the sensor's), with the recorded current, speed and ambient held over each
step of a ``grid_s`` grid (losses averaged exactly over the step, :func:`thermal_grid`; a speed power
the grid does not hold, such as an iron loss's fitted exponent, is taken of the step's mean speed),
integrated by the trapezoidal rule solved exactly for the network (affine in the temperatures over a
step).  The error is a predicted node minus its measurement at the grid's kept samples: the sensor
(``temperature_c``) and every further measured node (``node_<name>_c``) the network has (``per_sensor``).

The file's scope is reported too: the recordings against its ``[envelope]`` (:mod:`thermo_ddp.envelope`),
the prediction of each ``[[alternatives]]``, and ``band_k``, the widest spread of the sensor's prediction
that the ``[uncertainty]`` values and the alternatives allow.  The values enter to first order: at each
sample the prediction's sensitivity g to the uncertain values (CasADi derivatives through the whole
simulation; a share moved moves the first share of its split the other way, as in the fit).

- With the fit's ``[covariance]`` C (of log(value) or value, as the intervals): the spread over the values'
  joint 95 % confidence ellipsoid {d : d' C^-1 d <= chi2_{p,0.95}}, whose extremes along g are
  +-sqrt(chi2_{p,0.95}) sqrt(g' C g) (p values): a band that holds at every sample at once (Scheffe), and
  sees values that compensate each other (two resistances in series whose sum the data pin down).
- Without it (files written before): each value's interval moves the prediction by g (lo - x) and
  g (hi - x); the shifts are combined in quadrature, one side at a time (GUM, JCGM 100:2008 eq. 10: the
  95 % interval of the prediction when the values' errors are independent; the report says so).

The alternatives' predictions widen that band; ``band_k`` is its largest width over every sample.  Values
the data do not pin down (no interval) are not in it: where the recording lies outside the envelope the
error may be larger.  First order is exact only for small intervals (the network is nonlinear in its
capacities and resistances): the band is an estimate, not a guarantee.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ._figures import new_figure
from .envelope import TOLERANCE, EnvelopeCheck, check_envelope
from .errors import InputError
from .identify.network import values_of, with_values as with_network_values
from .identify.thermal import load_joint_parameters
from .identify.thermal_data import BOUNDARY_ROWS, INPUT_ROWS, ThermalGrid, ThermalSettings, thermal_grid
from .model.parameters import JointParameters
from .model.thermal import joint_heat_rhs, network_from_parameters
from .recordings import Recording, RecordingSet, as_recordings, read_recordings

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class ValidateSettings:
    """``grid_s``: step of the prediction grid (samples closer than this are merged, the losses held
    over a step are its exact means; thermal time constants are tens of seconds and more);
    ``envelope_tolerance``: how far beyond the identified range, as a share of its width, a quantity may
    reach before the recording counts as outside the envelope."""

    grid_s: float = 1.0
    envelope_tolerance: float = TOLERANCE

    def __post_init__(self) -> None:
        for name in ("grid_s", "envelope_tolerance"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError("validate settings", name, value, "must be a finite number > 0")


@dataclasses.dataclass(frozen=True)
class Prediction:
    """One recording: measured and predicted sensor temperature at the kept samples; ``nodes``: every
    measured node the network has, (measured, predicted); ``band_k``: the spread the file's uncertainty
    and alternatives allow here (0 without them)."""

    recording: str
    time_s: np.ndarray
    measured_c: np.ndarray
    predicted_c: np.ndarray
    nodes: Mapping[str, tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=dict)
    band_k: float = 0.0

    @property
    def error_c(self) -> np.ndarray:
        return self.predicted_c - self.measured_c

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.error_c ** 2)))

    @property
    def max_abs_error(self) -> float:
        return float(np.max(np.abs(self.error_c)))

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.predicted_c)))

    def to_dict(self) -> dict:
        return {"recording": self.recording, "rmse": self.rmse, "max_abs_error": self.max_abs_error,
                "samples": int(self.time_s.size)}


@dataclasses.dataclass(frozen=True)
class AlternativeScore:
    """The prediction of one of the file's ``[[alternatives]]``: its terms and sensor RMSE over every recording."""

    terms: tuple[str, ...]
    rmse: float

    def to_dict(self) -> dict:
        return {"terms": list(self.terms), "rmse": self.rmse}


@dataclasses.dataclass(frozen=True)
class Validation:
    """Result of :func:`validate_thermal` (``to_dict()``: the contract's Validate JSON plus ``rows``)."""

    model: str
    predictions: tuple[Prediction, ...]
    rows: dict = dataclasses.field(default_factory=dict)
    envelope: EnvelopeCheck = EnvelopeCheck((), False)
    alternatives: tuple[AlternativeScore, ...] = ()
    band_basis: str = "none"   # how the values' uncertainty entered band_k: covariance | independent | none

    @property
    def success(self) -> bool:
        return all(p.finite for p in self.predictions)

    @property
    def status(self) -> str:
        return "ok" if self.success else "not_finite"

    @property
    def message(self) -> str:
        if not self.success:
            bad = [p.recording for p in self.predictions if not p.finite]
            return f"the prediction diverged (thermal runaway?) on {', '.join(bad)}"
        return f"predicted {len(self.predictions)} recordings with the file as it is (no refit); {self.envelope.message}"

    @property
    def rmse(self) -> float:
        return _rmse([p.error_c for p in self.predictions])

    @property
    def max_abs_error(self) -> float:
        return max(p.max_abs_error for p in self.predictions)

    @property
    def per_sensor(self) -> dict[str, dict[str, float]]:
        """``{node: {"rmse": K}}`` over every recording, for each measured node the network has."""
        nodes = dict.fromkeys(n for p in self.predictions for n in p.nodes)
        return {n: {"rmse": _rmse([p.nodes[n][1] - p.nodes[n][0] for p in self.predictions if n in p.nodes])}
                for n in nodes}

    @property
    def band_k(self) -> float:
        return max((p.band_k for p in self.predictions), default=0.0)

    def to_dict(self) -> dict:
        common = {"model": self.model, "recordings": [p.recording for p in self.predictions], "rows": dict(self.rows),
                  "envelope": self.envelope.to_dict()}
        if not self.success:
            return {"success": False, "status": self.status, "message": self.message, **common, "rmse": None,
                    "max_abs_error": None, "per_recording": [], "per_sensor": {}, "alternatives": [], "band_k": None}
        return {"success": True, "status": self.status, "message": self.message, **common, "rmse": self.rmse,
                "max_abs_error": self.max_abs_error, "per_recording": [p.to_dict() for p in self.predictions],
                "per_sensor": self.per_sensor, "alternatives": [a.to_dict() for a in self.alternatives],
                "band_k": self.band_k, "band_basis": self.band_basis}

    def report(self) -> str:
        lines = [f"validate {self.model}: {self.status} ({self.message})"]
        if self.success:
            lines += [f"  {p.recording}: rmse {p.rmse:.3g} K, worst {p.max_abs_error:.3g} K, {p.time_s.size} samples"
                      for p in self.predictions]
            lines.append(f"all: rmse {self.rmse:.3g} K, worst {self.max_abs_error:.3g} K")
            if len(self.per_sensor) > 1:
                lines.append("per sensor: " + ", ".join(f"{n} {v['rmse']:.3g} K" for n, v in self.per_sensor.items()))
            lines += [f"alternative {'+'.join(a.terms)}: rmse {a.rmse:.3g} K" for a in self.alternatives]
            if self.band_k > 0:
                lines.append(f"band: the file's uncertainty and alternatives allow predictions {self.band_k:.3g} K apart"
                             + (" (the file has no [covariance]: the band assumes its values' errors independent)"
                                if self.band_basis == "independent" else "")
                             + (" (outside the envelope: the values the identification could not pin down are not in "
                                "it, the error may be larger)" if self.envelope.outside else ""))
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 4) -> Path:
        """Measured and predicted sensor temperature, and every further measured node (top), and the
        sensor's error (bottom), per recording."""
        shown = self.predictions[:max_recordings]
        fig, axes = new_figure(2, len(shown), figsize=(6 * len(shown), 6), sharex="col", squeeze=False)
        for c, p in enumerate(shown):
            axes[0, c].plot(p.time_s, p.measured_c, "k.", ms=1.5, label="recorded")
            axes[0, c].plot(p.time_s, p.predicted_c, lw=1.0, label=f"predicted ({Path(self.model).name})")
            for node, (measured, predicted) in p.nodes.items():
                if not np.array_equal(measured, p.measured_c):  # the further sensors, each in its colour
                    line, = axes[0, c].plot(p.time_s, predicted, lw=0.8, label=f"{node} predicted")
                    axes[0, c].plot(p.time_s, measured, ".", ms=1.0, color=line.get_color(), label=f"{node} recorded")
            axes[1, c].plot(p.time_s, p.error_c, lw=0.8, label=f"rmse {p.rmse:.3g} K, worst {p.max_abs_error:.3g} K")
            axes[0, c].set(title=p.recording, ylabel="sensor temperature [°C]")
            axes[1, c].set(xlabel="time [s]", ylabel="predicted - recorded [K]")
            for ax in axes[:, c]:
                ax.legend(fontsize=8, loc="best")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        return Path(path)


def _rmse(errors: Sequence[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))


@dataclasses.dataclass(frozen=True)
class _Simulator:
    """One held-input step of every node of a file's network, ``step(temps, inputs, p)``, where ``p`` are
    the values at ``paths`` (empty: the file as it is)."""

    step: ca.Function
    nodes: tuple[str, ...]
    sensor: str
    paths: tuple[str, ...]


def _with_rest_shares(params: JointParameters, values: Mapping[str, object]) -> dict[str, object]:
    """``values`` and, for a network whose split shares they move, each split's first share (unless moved
    itself) as the rest (the fit's parametrisation: shares sum to 1, :func:`~thermo_ddp.identify.network.with_values`)."""
    shares = {k: v for k, v in values.items() if ".split." in k}
    if params.thermal.network is None or not shares:
        return dict(values)
    full = values_of(with_network_values(params.thermal.general, shares))
    return dict(values) | {k: v for k, v in full.items() if ".split." in k and k not in values}


def _simulator(params: JointParameters, paths: Sequence[str] = ()) -> _Simulator:
    p = ca.SX.sym("p", len(paths))
    sym = params.with_values(_with_rest_shares(params, dict(zip(paths, ca.vertsplit(p))))) if paths else params
    network = network_from_parameters(sym.thermal)
    temps = ca.SX.sym("temperatures_c", len(network.nodes))
    u = ca.SX.sym("inputs", len(INPUT_ROWS))
    row = dict(zip(INPUT_ROWS, ca.vertsplit(u)))
    held = {k: row[k] for k in INPUT_ROWS[1:] if k not in BOUNDARY_ROWS}
    rhs = joint_heat_rhs(network, sym.motor, temps, ca.sqrt(row["current_sq_a2"]), 0.0, row["ambient_c"], held,
                         row["room_c"])
    h = row["step_s"]
    trapezoid = temps + h * ca.solve(ca.SX.eye(temps.numel()) - 0.5 * h * ca.jacobian(rhs, temps), rhs)
    step = ca.Function("validate_step", [temps, u, p], [trapezoid])
    return _Simulator(step, network.nodes, network.sensor_node, tuple(paths))


def _measured(rec: Recording, grid: ThermalGrid, sim: _Simulator) -> dict[str, np.ndarray]:
    """Every measured node of the network at the grid's kept samples."""
    kept = np.searchsorted(rec.time_s, grid.time_s)
    by_node = rec.temperatures_by_node(sim.sensor)
    return {n: np.asarray(by_node[n], float)[kept] for n in sim.nodes if n in by_node}


def _states(sim: _Simulator, grid: ThermalGrid, measured: Mapping[str, np.ndarray], p) -> np.ndarray:
    """Every node at the kept samples (nodes x samples); ``p``: numbers, or an MX symbol."""
    x0 = np.array([measured[n][0] if n in measured else grid.measured_c[0] for n in sim.nodes])
    after = sim.step.mapaccum(grid.inputs.shape[1])(x0, grid.inputs, p)
    return ca.horzcat(ca.DM(x0), after[:, [int(k) for k in grid.output_index]])


def _predict(sim: _Simulator, grid: ThermalGrid, measured: Mapping[str, np.ndarray]) -> np.ndarray:
    return np.asarray(_states(sim, grid, measured, []), float)


def _band(params: JointParameters, sim: _Simulator, grid, measured, nominal: np.ndarray,
          others: Sequence[np.ndarray]) -> float:
    """The widest spread of the sensor's prediction over this recording: first-order in the uncertain
    values (:func:`_spread`), widened by the alternatives' predictions ``others`` (module docstring)."""
    lower, upper = nominal.copy(), nominal.copy()
    if sim.paths:
        p = ca.MX.sym("p", len(sim.paths))
        y = _states(sim, grid, measured, p)[sim.nodes.index(sim.sensor), :]
        x = np.array([params.value(k) for k in sim.paths])
        jac = np.asarray(ca.Function("sensitivity", [p], [ca.jacobian(y, p)])(x), float)
        down, up = _spread(params, sim.paths, x, jac)
        lower, upper = lower - down, upper + up
    for other in others:
        lower, upper = np.minimum(lower, other), np.maximum(upper, other)
    return float(np.max(upper - lower))


def _spread(params: JointParameters, paths: Sequence[str], x: np.ndarray, jac: np.ndarray):
    """(downward, upward) first-order spread per sample of a prediction with sensitivity ``jac`` (samples x
    values at ``paths``, at the file's values ``x``): over the [covariance]'s 95 % ellipsoid, or the
    [uncertainty] intervals in quadrature (module docstring)."""
    cov = params.scope.covariance
    if cov is not None:  # the simulator's paths are the covariance's, in its order
        g = jac * cov.value_jacobian(x)
        half = cov.radius_95 * np.sqrt(np.maximum(np.einsum("ti,ij,tj->t", g, cov.array, g), 0))
        return half, half
    lo, hi = (np.array([params.scope.uncertainty[k][j] for k in paths]) - x for j in (0, 1))
    down, up = np.minimum(jac * lo, jac * hi), np.maximum(jac * lo, jac * hi)  # each value's one-sided shifts
    return np.sqrt(np.sum(np.minimum(down, 0.0) ** 2, axis=1)), np.sqrt(np.sum(np.maximum(up, 0.0) ** 2, axis=1))


def _prediction(params: JointParameters, rec: Recording, grid: ThermalGrid, sims: Sequence[_Simulator],
                alternatives: Sequence[_Simulator]) -> tuple[Prediction, list[np.ndarray]]:
    """The file's prediction of one recording (``sims``: nominal, and with the uncertain values as
    parameters), and each alternative's sensor prediction."""
    nominal, uncertain = sims
    measured = _measured(rec, grid, nominal)
    states = _predict(nominal, grid, measured)
    sensor = states[nominal.nodes.index(nominal.sensor)]
    others = [_predict(a, grid, measured)[a.nodes.index(a.sensor)] for a in alternatives]
    band = _band(params, uncertain, grid, measured, sensor, others) if np.all(np.isfinite(sensor)) else math.nan
    nodes = {n: (m, states[nominal.nodes.index(n)]) for n, m in measured.items()}
    return Prediction(grid.name, grid.time_s, grid.measured_c, sensor, nodes, band), others


def validate_thermal(recordings, parameters: JointParameters | str | Path,
                     settings: ValidateSettings | None = None, rows: dict | None = None) -> Validation:
    """Predict ``recordings`` (``current_a``, ``temperature_c``; ``velocity``, ``ambient_c`` and
    ``node_<name>_c`` when logged) with the parameter file ``parameters`` as it is; report the error per
    recording and per sensor, the envelope check, the alternatives and the band (module docstring)."""
    settings = settings or ValidateSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "validate")
    grid_settings = ThermalSettings(min_step_s=settings.grid_s, max_step_s=settings.grid_s, voltage_thermometry=False)
    grids = [thermal_grid(r, params, grid_settings) for r in recs]
    cov = params.scope.covariance
    sims = (_simulator(params), _simulator(params, cov.paths if cov else tuple(params.scope.uncertainty)))
    alts = [_simulator(params.alternative(k)) for k in range(len(params.scope.alternatives))]
    results = [_prediction(params, r, g, sims, alts) for r, g in zip(recs, grids)]
    scores = tuple(AlternativeScore(a.terms, _rmse([others[k] - g.measured_c for (_, others), g in zip(results, grids)]))
                   for k, a in enumerate(params.scope.alternatives))
    name = parameters if isinstance(parameters, (str, Path)) else params.path
    result = Validation(str(name), tuple(p for p, _ in results),
                        rows or {"used": sum(len(r) for r in recs), "skipped": 0, "segments": len(recs)},
                        check_envelope(params.scope.envelope, recs, settings.envelope_tolerance), scores,
                        "covariance" if cov else "independent" if params.scope.uncertainty else "none")
    if not result.success:
        log.warning("%s: %s", result.model, result.message)
    return result


def validate_files(paths: Sequence[str | Path], parameters: str | Path, columns=None,
                   settings: ValidateSettings | None = None) -> Validation:
    """CLI entry (``thermo-ddp validate``): CSV paths (and a column map) -> :class:`Validation`."""
    params = load_joint_parameters(parameters)  # bad file: refused before the recordings are read
    recordings: RecordingSet = read_recordings(paths, columns)
    result = validate_thermal(list(recordings.recordings), params, settings, recordings.rows)
    return dataclasses.replace(result, model=str(parameters))
