"""Thermal identification: output-error nonlinear least squares on the simulated sensor temperature.

The model is the package's lumped network (``thermo_ddp.model.thermal``) fed by the motor's losses
(``thermo_ddp.model.motor``), built with the free parameters as CasADi symbols, so the fit differentiates the same
expressions the planner integrates.  Structures (``terms``):

- ``one_node`` (seed report eq. 7 with R(T), eq. 5): free ``capacity_j_per_k``, ``resistance_k_per_w``;
- ``casing_node`` -> ``two_node`` (eq. 6; the sensor is on the casing): winding and casing capacities,
  ``winding_casing_k_per_w``, ``casing_ambient_k_per_w``;
- ``drive_heating``: the drive's ``drive_idle_w + drive_loss_w_per_a2 i^2`` (idle free, >= 0; i^2 loss held by
  default, :func:`default_fixed`) on the sensor node of a one-node network (no drive node); with the casing node, a
  drive node (``two_node_drive``) coupled to the casing and to ambient, heated by the idle loss;
- ``friction_heating``: free heat ``c1 |v| + c2 v^2`` (``friction_heat_linear_w_s_per_rad``,
  ``friction_heat_quadratic_w_s2_per_rad2``, joint-side v, both >= 0), in the winding of a one-node network and in
  the casing otherwise (gearbox and bearings sit on the housing); not tied to the friction of [motor] (gearbox heat
  may be several times the identified joint friction);
- ``copper_resistance``: ``copper_alpha_per_k`` free (eq. 3);
- ``iron_losses``: ``iron_loss_w_s2_per_rad2`` k, a speed-dependent loss k v^2 (joint-side v) in the winding node:
  the contract's iron loss with ``iron_loss_w`` = k at 1 rad/s and exponent 2.

The file's other optional [thermal] keys (``sensor``, the contract's friction heat, drive losses without a drive
node) are held at their values in every structure: the network is the planner's (``network_from_parameters``, heated
through ``joint_heat_rhs``).

Simulation: each recording on its own (possibly irregular) time grid, inputs held between samples (zero-order hold).
Samples closer than ``min_step_s`` are merged (the held losses are averaged exactly over the merged interval;
residuals only at the kept samples), intervals longer than ``max_step_s`` (gaps) are cut into sub-steps.  The network
is affine in the temperatures for held inputs; each (sub-)step is the trapezoidal rule (A-stable, 2nd order) solved
exactly for that affine system.  Sensitivities d(temperature)/d(parameters) are propagated with the states (forward
sensitivities of the step, CasADi AD, one ``mapaccum`` per recording), not by finite differences.

A second measurement when the recording logs ``voltage_v``: resistance thermometry of the winding (R(T) = (V - K_b N
v) / i at standstill, report eqs. 2-4), weighed by its noise at each sample's current (see :class:`ThermalSettings`).
It informs the winding node, which a casing sensor barely sees; a one-node model has no winding apart from its sensor
and ignores it.

Initial state per recording: the network's equilibrium under the first held inputs, plus a fitted offset common to
all nodes (``initial_offset_c``): the sensor's initial temperature is fitted, the unmeasured nodes start in the same
relation to it as at equilibrium.

Confidence intervals: the classical s^2 (J^T J)^-1 assumes white residuals; output-error residuals are
autocorrelated, so the standard errors are inflated by sqrt(integrated autocorrelation time) of the residual (an
effective-sample-size correction, Geyer's initial positive sequence).  They remain local, linearised intervals.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Mapping, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from .._config import require
from ..model.parameters import (THERMAL_KEYS, THERMAL_MODELS, JointParameters, ThermalParameters, load_parameters,
                                packaged_parameter_file, parameters_from_dict, unit)
from ..model.scope import LEARNED_SECTIONS, Covariance
from ..recordings import as_recordings
from ..model.thermal import joint_heat_rhs, network_from_parameters
from .fit_report import Z95, FitResult, correlation, covariance, integrated_autocorrelation
from .thermal_data import BOUNDARY_ROWS, INPUT_ROWS, ThermalGrid, ThermalSettings, thermal_grid

log = logging.getLogger(__name__)

MODELS = THERMAL_MODELS
THERMAL_TERMS = ("friction_heating", "drive_heating", "casing_node", "copper_resistance", "iron_losses")
IRON_KEY = "iron_loss_w_s2_per_rad2"
# The iron_losses term k v^2 is the contract's iron loss at 1 rad/s with exponent 2: iron_loss_w = k.
_IRON_CONTRACT = {"iron_loss_ref_speed_rad_s": 1.0, "iron_loss_speed_exponent": 2.0}
_PATHS = {"copper_alpha_per_k": "motor.copper_alpha_per_k", IRON_KEY: "thermal.iron_loss_w"}  # fitted key -> file path

FRICTION_KEYS = ("friction_heat_linear_w_s_per_rad", "friction_heat_quadratic_w_s2_per_rad2")
SENSOR_DRIVE_KEYS = ("drive_idle_w", "drive_loss_w_per_a2")
_TERM_KEYS = {"friction_heating": FRICTION_KEYS, "copper_resistance": ("copper_alpha_per_k",),
              "iron_losses": (IRON_KEY,)}
# Optional [thermal] keys a term decides (absent term: default); the file's other optional keys are kept.
_TERM_OWNED = ("friction_heating_fraction", "iron_loss_w", *_IRON_CONTRACT)
UNITS = {k: unit(k) for k in {*(k for keys in THERMAL_KEYS.values() for k in keys), *FRICTION_KEYS,
                              "copper_alpha_per_k"}} | {IRON_KEY: "W s^2/rad^2"}
# Search bounds of the optimiser (wide, technical; the diagnosis checks narrower physical ranges).
# "log": fitted as log(value); "lin": fitted as value / scale.
_SEARCH = {
    "capacity_j_per_k": ("log", 1.0, 1e6), "winding_capacity_j_per_k": ("log", 0.1, 1e6),
    "casing_capacity_j_per_k": ("log", 1.0, 1e6), "drive_capacity_j_per_k": ("log", 1.0, 1e6),
    "resistance_k_per_w": ("log", 1e-3, 100.0), "winding_casing_k_per_w": ("log", 1e-3, 100.0),
    "casing_ambient_k_per_w": ("log", 1e-3, 100.0), "drive_casing_k_per_w": ("log", 1e-3, 100.0),
    "drive_ambient_k_per_w": ("log", 1e-3, 1000.0), "drive_idle_w": ("log", 1e-3, 1e5),
    "drive_loss_w_per_a2": ("lin", 0.0, 5.0, 0.1),
    "friction_heat_linear_w_s_per_rad": ("lin", 0.0, 200.0, 1.0),
    "friction_heat_quadratic_w_s2_per_rad2": ("lin", 0.0, 200.0, 1.0),
    "copper_alpha_per_k": ("lin", 0.0, 0.02, 0.004), IRON_KEY: ("lin", 0.0, 10.0, 0.1),
}
_OFFSET_SCALE_C = 1.0
DRIVE_FIXED = ("drive_ambient_k_per_w", "drive_loss_w_per_a2")
# Start values used when the parameter file lacks a key: the elbow file's class values
# (models/arm_left_4_joint.toml, maxon flat-motor class, see its [sources]).
_FALLBACK = {"winding_capacity_j_per_k": 40.0, "casing_capacity_j_per_k": 1200.0, "winding_casing_k_per_w": 0.9,
             "casing_ambient_k_per_w": 1.3, "drive_capacity_j_per_k": 300.0, "drive_casing_k_per_w": 0.6,
             "drive_ambient_k_per_w": 2.5, "drive_idle_w": 23.0, "drive_loss_w_per_a2": 0.1,
             IRON_KEY: 0.02}
_STATUS = {-1: "improper_input", 0: "max_iterations", 1: "converged_gtol", 2: "converged_ftol",
           3: "converged_xtol", 4: "converged_ftol_xtol"}


# ----------------------------------------------------------------------------- structure
def canonical_terms(model: str = "one_node", terms: Sequence[str] = ()) -> tuple[str, ...]:
    """The term set of ``model`` plus ``terms``, in library order (InputError on unknown names)."""
    require(model in MODELS, "thermal model", "model", model, f"expected one of {', '.join(MODELS)}")
    for term in terms:
        require(term in THERMAL_TERMS, "thermal model", "term", term, f"unknown; known: {', '.join(THERMAL_TERMS)}")
    implied = {"one_node": (), "two_node": ("casing_node",), "two_node_drive": ("casing_node", "drive_heating")}[model]
    chosen = set(terms) | set(implied)
    return tuple(t for t in THERMAL_TERMS if t in chosen)


def network_model(terms: Sequence[str]) -> str:
    """Contract thermal model of a term set: the casing node makes two nodes, the drive then a third."""
    if "casing_node" not in terms:
        return "one_node"
    return "two_node_drive" if "drive_heating" in terms else "two_node"


def structure_name(terms: Sequence[str]) -> str:
    """E.g. ``two_node_drive + friction_heating`` or ``one_node + drive_heating``."""
    model = network_model(terms)
    implied = {"one_node": (), "two_node": ("casing_node",), "two_node_drive": ("casing_node", "drive_heating")}[model]
    return " + ".join([model] + [t for t in terms if t not in implied])


def free_keys(terms: Sequence[str]) -> tuple[str, ...]:
    model = network_model(terms)
    keys = THERMAL_KEYS[model]
    if model == "one_node" and "drive_heating" in terms:
        keys += SENSOR_DRIVE_KEYS
    for term in THERMAL_TERMS:
        if term in terms:
            keys += _TERM_KEYS.get(term, ())
    return keys


def lumped(th: ThermalParameters) -> tuple[float, float]:
    """(total capacity, total resistance to ambient along the winding path) of any contract network."""
    if th.model == "one_node":
        return th["capacity_j_per_k"], th["resistance_k_per_w"]
    return (th["winding_capacity_j_per_k"] + th["casing_capacity_j_per_k"],
            th["winding_casing_k_per_w"] + th["casing_ambient_k_per_w"])


def structure_parameters(th: ThermalParameters, model: str, values: Mapping[str, object]) -> ThermalParameters:
    """The thermal parameters of a structure: ``model`` with ``values`` (free symbols or fixed numbers,
    contract or term keys) and the file's optional keys that no term decides (``sensor``, ...)."""
    kept = {k: v for k, v in th.values.items()
            if k not in THERMAL_KEYS[th.model] and k not in _TERM_OWNED and k not in THERMAL_KEYS[model]}
    own = {k: values[k] for k in THERMAL_KEYS[model]}
    own |= {k: values[k] for k in SENSOR_DRIVE_KEYS if model == "one_node" and k in values}
    own["friction_heating_fraction"] = 0.0
    own |= {k: values[k] for k in FRICTION_KEYS if k in values}
    if IRON_KEY in values:
        own |= {"iron_loss_w": values[IRON_KEY], **_IRON_CONTRACT}
    if model == "one_node":  # a one-node network has only the winding
        return dataclasses.replace(th, model=model, values=kept | own, sensor=None, friction_heat_node=None)
    friction_node = "casing" if FRICTION_KEYS[0] in values else th.friction_heat_node
    return dataclasses.replace(th, model=model, values=kept | own, friction_heat_node=friction_node)


def start_values(params: JointParameters, terms: Sequence[str],
                 previous: Mapping[str, float] | None = None) -> dict[str, float]:
    """Start values of the free parameters: a previous fit's where it has them (a one-node fit is
    split in the file's winding/casing proportions), else the parameter file's, else class values."""
    th = params.thermal
    m = params.motor
    # friction heat starts at the file's friction power (c1 = Coulomb, c2 = viscous), drive heat at class values
    file_values = ({"friction_heat_linear_w_s_per_rad": m.coulomb_friction_nm,
                    "friction_heat_quadratic_w_s2_per_rad2": m.viscous_friction_nm_s_per_rad}
                   | {k: v for k, v in th.values.items() if v} | {"copper_alpha_per_k": m.copper_alpha_per_k})
    cap, res = lumped(th)
    file_values.setdefault("capacity_j_per_k", cap)
    file_values.setdefault("resistance_k_per_w", res)
    if previous:
        file_values |= {k: v for k, v in previous.items() if k in _SEARCH}
        if "capacity_j_per_k" in previous and "casing_capacity_j_per_k" not in previous:
            cw = file_values.get("winding_capacity_j_per_k", _FALLBACK["winding_capacity_j_per_k"])
            rw = file_values.get("winding_casing_k_per_w", _FALLBACK["winding_casing_k_per_w"])
            share_c, share_r = cw / cap, rw / res
            file_values |= {"winding_capacity_j_per_k": share_c * previous["capacity_j_per_k"],
                            "casing_capacity_j_per_k": (1 - share_c) * previous["capacity_j_per_k"],
                            "winding_casing_k_per_w": share_r * previous["resistance_k_per_w"],
                            "casing_ambient_k_per_w": (1 - share_r) * previous["resistance_k_per_w"]}
    out = {}
    for key in free_keys(terms):
        value = file_values.get(key, _FALLBACK.get(key))
        kind, lo, hi = _SEARCH[key][:3]
        span = hi - lo
        out[key] = float(np.clip(value, lo + 1e-6 * span if kind == "lin" else lo * 1.001, hi - 1e-6 * span))
    return out


class ThermalModel:
    """One structure (``terms``) of the thermal model with the parameter file's fixed values, as
    named CasADi functions of the free parameters (contract key names, :func:`free_keys`)."""

    def __init__(self, params: JointParameters, terms: Sequence[str] = (), fixed: Mapping[str, float] | None = None):
        self.params = params
        self.terms = canonical_terms("one_node", terms)
        self.model = network_model(self.terms)
        self.name = structure_name(self.terms)
        self.fixed = {k: float(v) for k, v in (fixed or {}).items() if k in free_keys(self.terms)}
        self.keys = tuple(k for k in free_keys(self.terms) if k not in self.fixed)
        symbols = ca.SX.sym("parameters", len(self.keys))
        sym = {k: symbols[i] for i, k in enumerate(self.keys)} | self.fixed
        self.network = network_from_parameters(structure_parameters(params.thermal, self.model, sym))
        self.nodes = self.network.nodes
        self.sensor = self.network.index(self.network.sensor_node)
        self.winding = self.network.index("winding")
        m = SimpleNamespace(**dataclasses.asdict(params.motor))
        if "copper_alpha_per_k" in sym:
            m.copper_alpha_per_k = sym["copper_alpha_per_k"]
        self._build(symbols, m)
        self._maps: dict[int, ca.Function] = {}

    def _build(self, p: ca.SX, m: SimpleNamespace) -> None:
        n, q = len(self.nodes), len(self.keys) + 1  # + the initial offset
        temps = ca.SX.sym("temperatures_c", n)
        u = ca.SX.sym("inputs", len(INPUT_ROWS))
        row = {name: u[k] for k, name in enumerate(INPUT_ROWS)}
        held = {key: row[key] for key in INPUT_ROWS[2:] if key not in BOUNDARY_ROWS}  # the held loss drivers
        rhs = joint_heat_rhs(self.network, m, temps, ca.sqrt(row["current_sq_a2"]), 0.0, row["ambient_c"], held,
                             row["room_c"])
        h = row["step_s"]
        a = ca.jacobian(rhs, temps)
        b = ca.substitute(rhs, temps, ca.SX.zeros(n))
        nxt = temps + h * ca.solve(ca.SX.eye(n) - 0.5 * h * a, rhs)
        sens = ca.SX.sym("sensitivities", n, q)
        d_nxt = ca.jacobian(nxt, temps) @ sens + ca.horzcat(ca.jacobian(nxt, p), ca.SX.zeros(n, 1))
        z = ca.vertcat(temps, ca.vec(sens))
        self.step = ca.Function("thermal_step_sensitivities", [z, u, p], [ca.vertcat(nxt, ca.vec(d_nxt))],
                                ["state_and_sensitivities", "inputs", "parameters"], ["next"])
        eq = -ca.solve(a, b)
        offset = ca.SX.sym("initial_offset_c")
        x0 = eq + offset
        s0 = ca.jacobian(x0, ca.vertcat(p, offset))
        self.initial = ca.Function("thermal_initial_state", [u, p, offset], [ca.vertcat(x0, ca.vec(s0))],
                                   ["inputs", "parameters", "initial_offset_c"], ["state_and_sensitivities"])
        self.equilibrium = ca.Function("thermal_equilibrium", [u, p], [eq], ["inputs", "parameters"], ["temperatures_c"])

    def _mapped(self, steps: int) -> ca.Function:
        if steps not in self._maps:
            self._maps[steps] = self.step.mapaccum("thermal_simulation", steps)
        return self._maps[steps]

    @property
    def thermometry(self) -> bool:
        """Whether resistance thermometry can inform this structure (a winding node apart from the sensor)."""
        return self.winding != self.sensor

    def simulate(self, grid: "ThermalGrid", values: Sequence[float],
                 offset_c: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(node temperatures at the grid's kept samples (nodes x K), sensor output (K,),
        d sensor / d[parameters, offset] and d winding / d[parameters, offset] (K x (p + 1)))."""
        n, q = len(self.nodes), len(self.keys) + 1
        p = np.asarray(values, float)
        z0 = np.asarray(self.initial(grid.inputs[:, 0], p, offset_c)).ravel()
        z = np.asarray(self._mapped(grid.inputs.shape[1])(z0, grid.inputs, p))
        z = np.column_stack([z0, z[:, grid.output_index]])
        temps = z[:n]
        return temps, temps[self.sensor], z[n + self.sensor::n][:q].T, z[n + self.winding::n][:q].T

    def equilibrium_sensor(self, grid: "ThermalGrid", values: Sequence[float]) -> float:
        return float(self.equilibrium(grid.inputs[:, 0], np.asarray(values, float))[self.sensor])


# ----------------------------------------------------------------------------- result
@dataclasses.dataclass(frozen=True)
class ThermalFit(FitResult):
    """A thermal fit: a :class:`FitResult` (parameters with contract key names, inflated standard
    errors, residuals and fitted sensor temperatures of all recordings, concatenated) plus the
    structure, per-recording initial states and the samples each recording contributed."""

    terms: tuple[str, ...] = ()
    recordings: tuple[str, ...] = ()
    sample_counts: tuple[int, ...] = ()
    initial_offset_c: Mapping[str, float] = dataclasses.field(default_factory=dict)
    stderr_inflation: float = 1.0
    nodes: tuple[str, ...] = ()
    node_temperatures_c: tuple[np.ndarray, ...] = ()  # per recording, nodes x samples
    nfev: int = 0
    correlation: Mapping[str, Mapping[str, float]] = dataclasses.field(default_factory=dict)
    rank_deficient: bool = False  # some parameter combination is not identifiable (see ``correlation``)

    def collinear(self, key: str, threshold: float = 0.95) -> tuple[str, ...]:
        """Other free parameters whose estimate is correlated with ``key``'s beyond ``threshold``."""
        row = self.correlation.get(key, {})
        return tuple(k for k, r in row.items() if k != key and abs(r) >= threshold)

    def identifiable(self, key: str, max_relative_error: float = 0.5) -> bool:
        """Whether the data pin ``key`` down: a finite standard error below ``max_relative_error`` of its value."""
        err, value = self.stderr.get(key), self.parameters.get(key, 0.0)
        return err is not None and value != 0 and err < max_relative_error * abs(value)

    @property
    def network_model(self) -> str:
        return network_model(self.terms)

    def rows(self, recording: str) -> slice:
        """Samples of ``recording`` in the concatenated arrays."""
        start = 0
        for name, count in zip(self.recordings, self.sample_counts):
            if name == recording:
                return slice(start, start + count)
            start += count
        raise KeyError(recording)

    @property
    def confidence(self) -> dict[str, tuple[float, float]]:
        """95 % intervals; log-normal for the parameters fitted in log-space (always positive)."""
        out = {}
        for key, err in self.stderr.items():
            value = self.parameters[key]
            if _SEARCH[key][0] == "log" and value > 0:
                factor = math.exp(min(Z95 * err / value, 700.0))  # no OverflowError: ~1e304, beyond any bound
                out[key] = (value / factor, value * factor)
            else:
                out[key] = (value - Z95 * err, value + Z95 * err)
        return out


def _to_theta(keys: Sequence[str], values: Mapping[str, float]) -> np.ndarray:
    out = []
    for k in keys:
        spec = _SEARCH[k]
        out.append(math.log(values[k]) if spec[0] == "log" else values[k] / spec[3])
    return np.array(out)


def _from_theta(keys: Sequence[str], theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical values and d value / d theta."""
    values, deriv = np.empty(len(keys)), np.empty(len(keys))
    for i, k in enumerate(keys):
        spec = _SEARCH[k]
        if spec[0] == "log":
            values[i] = deriv[i] = math.exp(theta[i])
        else:
            values[i], deriv[i] = theta[i] * spec[3], spec[3]
    return values, deriv


def _theta_bounds(keys: Sequence[str], bounds: Mapping[str, tuple[float, float]] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Optimiser bounds of theta: the technical search range, narrowed to ``bounds`` (physical ranges)."""
    lo, hi = [], []
    for k in keys:
        kind, a, b = _SEARCH[k][:3]
        narrow = (bounds or {}).get(k, (a, b))
        a, b = max(a, narrow[0]), min(b, narrow[1])
        lo.append(math.log(a) if kind == "log" else a / _SEARCH[k][3])
        hi.append(math.log(b) if kind == "log" else b / _SEARCH[k][3])
    return np.array(lo), np.array(hi)


class _Problem:
    """Stacked residual and Jacobian of several recordings for the optimiser (memoised per theta)."""

    def __init__(self, model: ThermalModel, grids: Sequence[ThermalGrid], weights: Sequence[np.ndarray]):
        self.model, self.grids, self.weights = model, grids, weights
        self.p = len(model.keys)
        self._last: tuple[bytes, tuple] | None = None
        self.nfev = 0

    def evaluate(self, theta: np.ndarray):
        key = theta.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        values, dvalue = _from_theta(self.model.keys, theta[:self.p])
        offsets = theta[self.p:] * _OFFSET_SCALE_C
        res, jacs = [], []
        for r, (grid, w) in enumerate(zip(self.grids, self.weights)):
            rows, j = _weighted_rows(self.model, grid, self.model.simulate(grid, values, offsets[r]), w)
            res.append(rows)
            block = np.zeros((rows.size, theta.size))
            block[:, :self.p], block[:, self.p + r] = j[:, :self.p] * dvalue, j[:, self.p] * _OFFSET_SCALE_C
            jacs.append(block)
        r_all, jac = np.concatenate(res), np.vstack(jacs)
        if not np.all(np.abs(r_all) < 1e6):  # runaway or overflow: tell the optimiser the step failed
            r_all = np.full_like(r_all, np.inf)
        self.nfev += 1
        self._last = (key, (r_all, jac))
        return r_all, jac

    def fun(self, theta):
        return self.evaluate(theta)[0]

    def jac(self, theta):
        return self.evaluate(theta)[1]


def _weighted_rows(model: ThermalModel, grid: ThermalGrid, sim: tuple, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residual rows (model - measurement) of one recording and their Jacobian by
    [parameters, offset]: the sensor's, then the winding thermometry's (when usable)."""
    _, y, j_sensor, j_winding = sim
    res, jac = [w * (y - grid.measured_c)], [w[:, None] * j_sensor]
    if model.thermometry and grid.thermometry_samples:
        use = (grid.winding_weight > 0) & (w > 0)
        ww = w[use] * grid.winding_weight[use]
        res.append(ww * (sim[0][model.winding][use] - grid.winding_c[use]))
        jac.append(ww[:, None] * j_winding[use])
    return np.concatenate(res), np.vstack(jac)


def head_offset(model: ThermalModel, grid: ThermalGrid, values: Sequence[float], head_s: float) -> float:
    """Initial offset set from the first measurements (median over ``head_s``) of ``grid``."""
    head = grid.measured_c[grid.time_s <= grid.time_s[0] + head_s]
    return float(np.median(head) - model.equilibrium_sensor(grid, values))


def fit_grids(model: ThermalModel, grids: Sequence[ThermalGrid], *, start: Mapping[str, float] | None = None,
              offsets: Sequence[float] | None = None, weights: Sequence[np.ndarray] | None = None,
              settings: ThermalSettings | None = None, bounds: Mapping[str, tuple[float, float]] | None = None
              ) -> ThermalFit:
    """Output-error fit of ``model`` to ``grids`` (shared parameters, one initial offset per grid).

    ``weights`` (per grid, per kept sample; 0 = unseen) select the samples the cost sees; residuals
    and fitted values are returned for every sample.  A grid whose weights are all 0 gets its
    initial offset from its first measurements (:func:`head_offset`), not from the fit.  ``bounds``
    narrows the search range of named parameters (physical ranges; the start is clipped into them).
    """
    settings = settings or ThermalSettings()
    start = dict(start or start_values(model.params, model.terms))
    weights = [np.ones(len(g)) for g in grids] if weights is None else [np.asarray(w, float) for w in weights]
    keys, p = model.keys, len(model.keys)
    vals0 = [start[k] for k in keys]
    if offsets is None:
        offsets = [head_offset(model, g, vals0, settings.head_s) for g in grids]
    theta0 = np.concatenate([_to_theta(keys, start), np.asarray(offsets, float) / _OFFSET_SCALE_C])
    lo, hi = _theta_bounds(keys, bounds)
    unseen = [r for r, w in enumerate(weights) if not np.any(w)]
    lo = np.concatenate([lo, np.full(len(grids), -np.inf)])
    hi = np.concatenate([hi, np.full(len(grids), np.inf)])
    problem = _Problem(model, grids, weights)
    theta0 = np.clip(theta0, lo, hi)
    seen = np.array([True] * p + [r not in unseen for r in range(len(grids))])
    n_used = int(sum(np.count_nonzero(w) for w in weights))
    try:
        sol = optimize.least_squares(lambda th: problem.fun(_merge(th, theta0, seen)),
                                     theta0[seen], lambda th: problem.jac(_merge(th, theta0, seen))[:, seen],
                                     bounds=(lo[seen], hi[seen]), method="trf", tr_solver="lsmr",
                                     max_nfev=settings.max_nfev, ftol=settings.chi2_tolerance / max(n_used, 1), xtol=1e-10, gtol=1e-10)
    except ValueError as err:  # non-finite residual at the start (e.g. thermal runaway)
        return _failed(model, grids, start, "not_finite", f"simulation not finite at the start values ({err})")
    theta = _merge(sol.x, theta0, seen)
    if unseen:
        values, _ = _from_theta(keys, theta[:p])
        for r in unseen:
            theta[p + r] = head_offset(model, grids[r], values, settings.head_s) / _OFFSET_SCALE_C
    status = _STATUS.get(sol.status, str(sol.status))
    return _result(model, grids, theta, weights, status, sol.success, sol.message, problem.nfev)


def _merge(part: np.ndarray, full: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = full.copy()
    out[mask] = part
    return out


def _failed(model: ThermalModel, grids, start, status: str, message: str) -> ThermalFit:
    measured = np.concatenate([g.measured_c for g in grids])
    return ThermalFit(model.name, dict(start), {}, measured.copy(), np.zeros_like(measured), False, status, message,
                      np.concatenate([g.time_s for g in grids]), terms=model.terms,
                      recordings=tuple(g.name for g in grids), sample_counts=tuple(len(g) for g in grids),
                      nodes=model.nodes)


def _result(model: ThermalModel, grids, theta, weights, status, success, message, nfev) -> ThermalFit:
    keys, p = model.keys, len(model.keys)
    values, _ = _from_theta(keys, theta[:p])
    offsets = theta[p:] * _OFFSET_SCALE_C
    sims = [model.simulate(g, values, offsets[r]) for r, g in enumerate(grids)]
    fitted = np.concatenate([s[1] for s in sims])
    measured = np.concatenate([g.measured_c for g in grids])
    residuals = measured - fitted
    rows, jacs = [], []
    for r, (g, s, w_r) in enumerate(zip(grids, sims, weights)):
        res_r, j_r = _weighted_rows(model, g, s, w_r)
        keep = np.concatenate([w_r > 0, np.ones(res_r.size - len(g), bool)])
        block = np.zeros((int(keep.sum()), p + len(grids)))
        block[:, :p], block[:, p + r] = j_r[keep, :p], j_r[keep, p]
        rows.append(res_r[keep])
        jacs.append(block)
    names = list(keys) + [f"initial_offset_c[{g.name}]" for g in grids]
    seen_cols = [True] * p + [bool(np.any(w_r)) for w_r in weights]
    names = [n for n, s in zip(names, seen_cols) if s]
    cov, rank = covariance(np.vstack(jacs)[:, seen_cols], np.concatenate(rows))
    parameters = {k: float(v) for k, v in zip(keys, values)} | model.fixed
    inflation = math.sqrt(max(integrated_autocorrelation(r_g[w_g > 0]) for r_g, w_g in
                              zip(np.split(residuals, np.cumsum([len(g) for g in grids])[:-1]), weights)
                              if np.any(w_g > 0)))
    stderr = {k: inflation * math.sqrt(max(cov[i, i], 0.0)) for i, k in enumerate(keys)}
    corr = correlation(cov[:p, :p])
    ok = bool(success) and bool(np.all(np.isfinite(residuals)))
    notes = (f"standard errors inflated x{inflation:.2f} = sqrt(integrated autocorrelation time of the residual) "
             "for autocorrelated output-error residuals; still linearised, local intervals",
             "initial offsets [K]: " + ", ".join(f"{g.name} {o:+.3f}" for g, o in zip(grids, offsets)))
    if model.fixed:
        notes += ("held at the parameter file's values (not identifiable from the casing sensor alone): "
                  + ", ".join(model.fixed),)
    notes += _thermometry_notes(model, grids, sims)
    return ThermalFit(model.name, parameters, stderr, residuals, fitted, ok, status, str(message),
                      np.concatenate([g.time_s for g in grids]), {k: UNITS[k] for k in keys}, notes,
                      terms=model.terms, recordings=tuple(g.name for g in grids),
                      sample_counts=tuple(len(g) for g in grids),
                      initial_offset_c={g.name: float(o) for g, o in zip(grids, offsets)},
                      stderr_inflation=inflation, nodes=model.nodes,
                      node_temperatures_c=tuple(s[0] for s in sims), nfev=nfev,
                      correlation={a: {b: float(corr[i, j]) for j, b in enumerate(keys)} for i, a in enumerate(keys)},
                      rank_deficient=rank < len(names))


def _thermometry_notes(model: ThermalModel, grids, sims) -> tuple[str, ...]:
    """How the winding thermometry (if any) entered the fit and how well the winding follows it."""
    counts = [g.thermometry_samples for g in grids]
    if not model.thermometry or not sum(counts):
        return ()
    err = np.concatenate([(s[0][model.winding] - g.winding_c)[g.winding_weight > 0]
                          for g, s in zip(grids, sims) if g.thermometry_samples])
    return (f"winding resistance thermometry from voltage_v: {sum(counts)} samples "
            f"({', '.join(f'{g.name} {c}' for g, c in zip(grids, counts))}); model winding minus thermometry "
            f"mean {err.mean():+.2f} K, rms {math.sqrt(float(np.mean(err ** 2))):.2f} K",)


# ----------------------------------------------------------------------------- public API
def load_joint_parameters(parameters: JointParameters | str | Path | None) -> JointParameters:
    if isinstance(parameters, JointParameters):
        return parameters
    return load_parameters(parameters if parameters is not None else packaged_parameter_file("arm_left_4_joint"))


def default_fixed(terms: Sequence[str], room_stand_in: bool = False) -> tuple[str, ...]:
    """Keys held at the file's values: on a casing sensor the drive's ambient path and i^2 loss trade off against its
    idle heat and coupling; on one node its i^2 loss is the copper's R i^2 (bar alpha), unless the term only stands
    in for an unlogged room (free, it takes up the file's copper error: UR3 J2 later stretch 0.128 K, held 0.194 K)."""
    if network_model(terms) == "two_node_drive":
        return DRIVE_FIXED
    return DRIVE_FIXED[1:] if "drive_heating" in terms and not room_stand_in else ()


def identify_thermal(recordings, model: str = "one_node", *, terms: Sequence[str] = (),
                     parameters: JointParameters | str | Path | None = None,
                     settings: ThermalSettings | None = None, start: Mapping[str, float] | None = None,
                     fixed: Sequence[str] | None = None) -> ThermalFit:
    """Fit ``model`` (+ ``terms``) to one or several recordings (CSV paths or Recording objects) with
    shared parameters and per-recording initial states.  Fixed values (motor, ambient when the
    recording has no ``ambient_c``) and start values come from ``parameters`` (default: the elbow file);
    ``fixed`` names free keys to hold at their start values (default :func:`default_fixed`)."""
    settings = settings or ThermalSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "thermal")
    terms = canonical_terms(model, terms)
    values = start_values(params, terms) | dict(start or {})
    fixed = default_fixed(terms) if fixed is None else tuple(fixed)
    for key in fixed:
        require(key in values, "identify_thermal", "fixed", key, f"not a parameter of {structure_name(terms)}")
    structure = ThermalModel(params, terms, {k: values[k] for k in fixed})
    start = values
    grids = [thermal_grid(r, params, settings) for r in recs]
    return fit_grids(structure, grids, start=start, settings=settings)


def parameter_file(params: JointParameters, fit: ThermalFit, recordings: Sequence[str] = (),
                   envelope: Mapping[str, Sequence[float]] | None = None) -> dict:
    """The contract parameter sections with ``fit``'s thermal model (validated by parameters_from_dict); ``iron_losses``
    k v^2 as the contract's iron loss (``iron_loss_w`` = k at 1 rad/s, exponent 2); the fitted values' [uncertainty]
    (95 %), [covariance] (of log(value) for log-normal intervals) and ``envelope`` replace the file's own."""
    data = {k: v for k, v in params.to_dict().items() if k not in LEARNED_SECTIONS}
    values = dict(fit.parameters)  # each interval within the range searched (not 1e-303 to 1e305 K/W)
    finite = {k: [min(max(lo, _SEARCH[k][1], 0.0), values[k]), max(min(hi, _SEARCH[k][2]), values[k])]
              for k, (lo, hi) in fit.confidence.items() if math.isfinite(hi - lo)}
    if finite:  # a value the data do not pin down has no finite interval: not written
        keys, paths = list(finite), [_PATHS.get(k, f"thermal.{k}") for k in finite]
        data["uncertainty"] = dict(zip(paths, finite.values()))
        log = [_SEARCH[k][0] == "log" and values[k] > 0 for k in keys]  # as ThermalFit.confidence
        cov = Covariance.of_errors(paths, log, [values[k] for k in keys], [fit.stderr[k] for k in keys],
                                   [[fit.correlation[a][b] for b in keys] for a in keys])
        data |= {"covariance": cov.to_dict()} if cov else {}
    data |= {"envelope": {k: list(v) for k, v in envelope.items()}} if envelope else {}
    model = network_model(fit.terms)
    data["thermal"] = structure_parameters(params.thermal, model, values).to_dict()
    if "copper_alpha_per_k" in values:
        data["motor"]["copper_alpha_per_k"] = values["copper_alpha_per_k"]
    identified = [*THERMAL_KEYS[model], *(k for k in (*SENSOR_DRIVE_KEYS, *FRICTION_KEYS, "copper_alpha_per_k")
                                          if k in values and k not in THERMAL_KEYS[model])]
    if IRON_KEY in values:
        identified += ["iron_loss_w", *_IRON_CONTRACT]
    where = ", ".join(recordings) or "recordings"
    data["sources"] = {k: v for k, v in data["sources"].items() if k not in identified} | dict.fromkeys(
        identified, f"identified by thermo-ddp ({fit.model}, output-error least squares) from {where}")
    return parameters_from_dict(data, f"identified from {where}").to_dict()

