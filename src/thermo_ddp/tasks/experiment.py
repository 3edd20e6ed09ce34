"""``design_experiment()``: plan the recording that settles what the recordings leave undetermined.

1. The recordings are diagnosed (:func:`thermo_ddp.diagnose.thermal.diagnose_thermal`); its undetermined heat
   terms and their rivals (:mod:`thermo_ddp.tasks.experiment_rivals`) are the competing explanations.
2. One optimal-control problem holds them all (:class:`thermo_ddp.multi_model.MultiModelProblem`): one thermal
   state per explanation, every one driven by the same control u = (winding current, joint speed), held over
   knots of ``dt_s`` (a coarse parametrisation of an experiment of up to ``duration_s``).
3. Criterion (a model-discrimination design after Hunter & Reiner, Technometrics 7, 1965: maximise the squared
   difference of the rival models' predicted responses): the sensor predictions of the reference and of each
   rival should differ by as many sensor-noise standard deviations as possible at every knot, each prediction
   counted from its explanation's state at rest (the start): resting temperatures apart are what the passive
   recordings pin (and a fit's initial offset absorbs), not divergence; the responses to the programme are.  The
   DDP minimises sums of squares, so the divergence d_j = s_j (y_0 - y_j) / sigma (s_j: its sign on the start) enters as
   the residual (D - d_j) / D with a target D far above the reachable divergence: the cost falls as every d_j
   grows.  sigma: the diagnosis's residual noise.
4. Constraints on every explanation: the winding under ``limit_c``, the winding never taken below the sensor
   plus a winding-over-sensor resistance times the copper loss at the limit (:func:`winding_rise_k_per_w`: the
   upper end of a fitted casing node's interval, or for one node :data:`WINDING_RISE_FACTOR` times the file's:
   a winding node the data cannot pin down must not let the design overheat the real one); the bus voltage
   R(T) i + K_b N abs(v) <= V_bus; the current within the file's peak and the speed within the joint's limit.
5. The criterion is not convex: the DDP starts from simple excitation families (:data:`FAMILIES`), each scaled
   to keep every explanation under the limit.  Of the designs within the limits, the one kept is D_s-optimal
   for the target values: the largest log det of their Fisher information (relative to their values) from the
   passive recordings and the design together, the richest explanation's sensor sensitivities over the noise,
   its other values and every segment's initial offset nuisances.  Discrimination plans, information chooses:
   telling the explanations apart does not by itself pin each value down (two speeds for a linear and a
   quadratic friction heat), and the passive recordings already hold part of the information.
6. Before any run, the design lists as ``not_determinable`` the values of the named terms and the targets that no
   start's design pins within +-50 % by their predicted covariance
   (:func:`~thermo_ddp.tasks.experiment_information.undeterminable`): not demanded of this experiment.
7. The programme (``time_s``, ``current_a``, ``position``, ``velocity``) moves the joint back and forth inside
   its range at each knot's speed with a bounded acceleration (careful motion: reversals and the final stop
   at ``acceleration_rad_s2``), the current held per knot.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time

import casadi as ca
import numpy as np
from tqdm import tqdm

from .._config import checked_settings, require
from ..diagnose.thermal import ThermalDiagnosis, ThermalDiagnosisSettings, diagnose_thermal, term_specs
from ..identify.thermal import load_joint_parameters
from ..identify.thermal_data import INPUT_ROWS, ThermalGrid, _drivers
from ..model import motor
from ..model.actuated import ActuatedArm
from ..model.arm import ArmSettings
from ..multi_model import MultiModelProblem
from ..ocp import Constraint, Cost, KnotParameters
from ..solvers import DDPSettings, DDPSolver, WarmStart
from .experiment_information import half_widths, information, log_det, undeterminable
from .experiment_rivals import Explanations, explanations
from .experiment_motion import PROGRAMME_COLUMNS, joint_bounds, plot_experiment, programme
from .limits import check_idle_below_limits, joint_limit_c

log = logging.getLogger(__name__)

MAX_DURATION_S = 24 * 3600.0
WINDING_RISE_FACTOR = 1.5   # margin on the file's winding-casing resistance, which a one-node fit does not identify
SUBSTEPS = 3                # thermal sub-steps per knot (the diagnosis integrates on 10 s steps)
TARGET_FACTOR = 5.0         # each pair's divergence target D_j: this many times its largest on any start
TOLERANCE = 1e-4            # DDP stationarity |Qu|: the criterion is O(1), the controls O(1-10)
LIMIT_MARGIN_K = 2.0        # the starts are scaled to stay this far under the limit
GRID_S = 10.0               # the diagnosis's grid step: the weight of one sample of information
FEASIBILITY_K = 0.05        # largest excess of a design's simulated winding (K) or bus voltage (V) over its limit
FAMILIES = ("current_steps", "two_speeds", "speeds_then_holds", "move_then_hold", "hold_then_move")
_SRC = "design_experiment"


@checked_settings(_SRC, duration_s=f"(0, {MAX_DURATION_S:g}]", dt_s="[1, 600]", sample_s="(0, 10]",
                  acceleration_rad_s2="(0, inf)", margin_rad="[0, inf)", max_iterations="[1, inf)",
                  winding_rise_k_per_w="[0, inf)")
class ExperimentSettings:
    """``duration_s``: the longest experiment; ``limit_c``: the winding limit (None: the file's cut-off);
    ``dt_s``: knots of the control (current and speed held over each); ``sample_s``: rows of the programme;
    ``acceleration_rad_s2``: careful motion's reversal and stop acceleration; ``margin_rad``: kept inside the
    joint range; ``max_iterations``: DDP iterations per start; ``progress``: bar over the starts (None: only
    on a terminal); ``winding_rise_k_per_w``: the least winding-over-sensor resistance the limit is guarded with
    (a sequential design keeps its first round's: :func:`winding_rise_k_per_w`)."""

    duration_s: float = 3600.0
    limit_c: float | None = None
    dt_s: float = 30.0
    sample_s: float = 0.1
    acceleration_rad_s2: float = 10.0
    margin_rad: float = 0.2
    max_iterations: int = 300
    progress: bool | None = None
    winding_rise_k_per_w: float = 0.0



# ----------------------------------------------------------------------------- the multi-model problem
def winding_rise_k_per_w(diagnosis: ThermalDiagnosis) -> float:
    """The winding-over-sensor resistance the limit is guarded with: with a casing node, the upper end of its
    fitted winding-casing resistance's 95 % interval (within the physical range of the diagnosis); with one node,
    :data:`WINDING_RISE_FACTOR` times the parameter file's (the data cannot resolve the winding node)."""
    key = "winding_casing_k_per_w"
    fit = diagnosis.final_fit
    if key in fit.parameters:
        top = term_specs(diagnosis.params)["casing_node"].bounds[key][1]
        return float(min(fit.confidence.get(key, (0.0, top))[1], top))
    return WINDING_RISE_FACTOR * float(diagnosis.params.thermal.values.get(key, 0.0))


def _winding_expr(model, params, x, u, limit_c, rise_k_per_w: float):
    """The winding of one explanation (state x, control u) as the limit sees it: its winding node, and never less
    than its sensor plus ``rise_k_per_w`` times the copper loss at the limit (the steady rise over the sensor)."""
    bound = x[model.sensor] + rise_k_per_w * motor.joule_w(params.motor, u[0], limit_c)
    return bound if model.winding == model.sensor else ca.fmax(x[model.winding], bound)


def _pairs(explanations: int) -> list[tuple[int, int]]:
    """Every pair of explanations (i < j): each is to be told from every other."""
    return [(i, j) for i in range(explanations) for j in range(i + 1, explanations)]


def _functions(model, params, dt_s: float, explanations: int, rise_k_per_w: float):
    """(step(x, u, p, theta), winding(x, u), divergence(X, p), limits(x, u, p)) of the explanations' structure;
    p = [ambient_c, limit_c, then per pair its sign over its target D_j, then per pair its difference at rest]."""
    n, q = len(model.nodes), len(model.keys)
    x, u, th = ca.SX.sym("x", n), ca.SX.sym("u", 2), ca.SX.sym("theta", q)
    pairs = len(_pairs(explanations))
    p = ca.SX.sym("p", 2 + 2 * pairs)
    drivers = _drivers(params)(u[0], u[1])
    h = dt_s / SUBSTEPS
    inputs = ca.vertcat(h, drivers[:3], p[0], drivers[3:], p[0])  # INPUT_ROWS: the room at the ambient
    z = x
    for _ in range(SUBSTEPS):
        z = model.step(ca.vertcat(z, ca.SX.zeros(n * (q + 1))), inputs, th)[:n]
    step = ca.Function("experiment_step", [x, u, p, th], [z], ["x", "u", "p", "theta"], ["x_next"])
    w = _winding_expr(model, params, x, u, p[1], rise_k_per_w)
    winding = ca.Function("winding", [x, u, p], [w], ["x", "u", "p"], ["winding_c"])
    m = params.motor
    g = ca.vertcat(w - p[1], motor.resistance_ohm(m, w) * u[0] + m.back_emf_v_s_per_rad * m.gear_ratio * u[1]
                   - m.bus_voltage_v)
    limits = ca.Function("limits", [x, u, p], [g], ["x", "u", "p"], ["g"])
    X = ca.SX.sym("X", n, explanations)
    y = X[model.sensor, :]
    r = ca.vertcat(*[1 - p[2 + k] * (y[i] - y[j] - p[2 + pairs + k])
                     for k, (i, j) in enumerate(_pairs(explanations))])
    divergence = ca.Function("divergence", [X, p], [r], ["X", "p"], ["r"])
    return step, winding, divergence, limits


@dataclasses.dataclass(frozen=True)
class _Design:
    """The multi-model problem of the explanations and its data (costs scaled by the sensor noise)."""

    expl: Explanations
    mm: MultiModelProblem
    thetas: np.ndarray
    x0: np.ndarray
    winding: ca.Function
    sigma_c: float
    limit_c: float
    ambient_c: float
    u_max: np.ndarray
    dt_s: float

    @property
    def pairs(self) -> int:
        return len(_pairs(self.thetas.shape[0]))

    @functools.cached_property
    def rest_c(self) -> np.ndarray:
        """Every explanation's sensor at rest (the start): what the passive recordings already pin."""
        return self.sensors(self.x0[None, :])[0]

    def own(self, scales) -> np.ndarray:
        """The problem's own parameters: ambient, limit, each pair's sign over its target (``scales``) and each
        pair's sensor difference at rest (:attr:`rest_c`: not divergence)."""
        rest = self.rest_c
        return np.concatenate([[self.ambient_c, self.limit_c], scales, [rest[i] - rest[j] for i, j in
                                                                        _pairs(self.thetas.shape[0])]])

    def params(self, scales) -> np.ndarray:
        """Per-knot parameters (:meth:`own`) with each pair's sign over its target (``scales``)."""
        return self.mm.params(np.tile(self.own(scales), (self.mm.horizon + 1, 1)), self.thetas)

    def rollout(self, us: np.ndarray) -> np.ndarray:
        """Stacked states along the controls ``us`` (N, 2)."""
        f, p = self.mm.problem.functions.step, self.params(np.ones(self.pairs))[0]
        xs = [self.x0]
        for u in us:
            xs.append(np.array(f(xs[-1], u, p)).ravel())
        return np.array(xs)

    def sensors(self, xs) -> np.ndarray:
        """(N+1, K) every explanation's predicted sensor temperature."""
        return self.mm.scenario_states(xs)[:, :, self.expl.model.sensor]

    def windings(self, xs, us) -> np.ndarray:
        """(N+1, K) every explanation's winding (at the last knot with the last control)."""
        states = self.mm.scenario_states(xs)
        u, p = np.vstack([us, us[-1:]]), self.own(np.ones(self.pairs))
        return np.array([[float(self.winding(s, uk, p)) for s in st] for st, uk in zip(states, u)])

    def divergences(self, xs) -> np.ndarray:
        """(N+1, pairs) the difference of the sensor predictions of every pair of explanations, in K, each counted
        from its state at rest (the start, ``xs[0]``): a different resting temperature is no divergence."""
        y = self.sensors(xs) - self.rest_c
        return np.column_stack([y[:, i] - y[:, j] for i, j in _pairs(y.shape[1])])


def _build(expl: Explanations, sigma_c: float, limit_c: float, ambient_c: float, u_max, settings,
           rise_k_per_w: float) -> _Design:
    model, params = expl.model, expl.model.params
    knots = max(1, int(math.ceil(settings.duration_s / settings.dt_s - 1e-9)))
    dt_s = settings.duration_s / knots
    thetas = np.array([expl.theta(r) for r in expl.rivals])
    pairs = len(_pairs(thetas.shape[0]))
    step, winding, divergence, limits = _functions(model, params, dt_s, thetas.shape[0], rise_k_per_w)
    u = ca.SX.sym("u", 2)
    effort = Cost("effort", 1e-6, ca.Function("r", [u], [u / ca.DM(u_max)], ["u"], ["r"]))
    cross = Cost("divergence", 1.0 / (knots * pairs), _cross(divergence, len(model.nodes), thetas.shape[0]))
    mm = MultiModelProblem(step, knots, thetas.shape[0], costs=[effort], cross_costs=[cross],
                           constraints=[Constraint("winding_and_bus", limits)], u_lb=[0.0, 0.0], u_ub=list(u_max),
                           parameters=KnotParameters((("ambient_limit", 2), ("pair_scales", pairs),
                                                      ("rest_differences", pairs))),
                           name="designed_experiment")
    rest = _rest(expl, ambient_c)[0]
    x0 = mm.x0(np.array([np.asarray(model.equilibrium(rest, th)).ravel() for th in thetas]))
    return _Design(expl, mm, thetas, x0, winding, sigma_c, limit_c, ambient_c, np.asarray(u_max, float), dt_s)


def _cross(divergence: ca.Function, n: int, explanations: int) -> ca.Function:
    X, p = ca.SX.sym("X", n, explanations), ca.SX.sym("p", 2 + 2 * len(_pairs(explanations)))
    return ca.Function("r", [X, p], [divergence(X, p)], ["X", "p"], ["r"])


# ----------------------------------------------------------------------------- starts and solves
def _family(name: str, knots: int, u_max: np.ndarray) -> np.ndarray:
    """The shape of a start (N, 2): current as a share of the peak, speed as a share of the limit."""
    k = np.arange(knots) / knots
    i = np.ones(knots)
    if name == "current_steps":
        i, v = np.where((k < 0.25) | ((k >= 0.5) & (k < 0.75)), 1.0, 0.0), np.zeros(knots)
    elif name == "two_speeds":
        v = np.select([k < 1 / 3, k < 2 / 3], [0.3, 0.8], 0.0)
    elif name == "speeds_then_holds":  # each heat alone: friction at two speeds, then copper, then the idle heat
        i = np.select([k < 0.5, k < 0.75], [0.0, 1.0], 0.0)
        v = np.select([k < 0.25, k < 0.5], [0.9, 0.4], 0.0)
    elif name == "move_then_hold":
        v = np.where(k < 0.5, 0.8, 0.0)
    else:  # hold_then_move
        v = np.where(k < 0.5, 0.0, 0.8)
    return np.column_stack([i * u_max[0], v * u_max[1]])


def _scaled(design: _Design, shape: np.ndarray) -> np.ndarray | None:
    """The start ``shape`` with its current scaled (bisection) so that every explanation's winding stays
    :data:`LIMIT_MARGIN_K` under the limit, and its speed so that the bus voltage holds; None if nothing fits."""
    def peak(c):
        us = shape * [c, 1.0]
        return design.windings(design.rollout(us), us).max()

    lo, hi = 0.0, 1.0
    if peak(hi) <= design.limit_c - LIMIT_MARGIN_K:
        lo = hi
    for _ in range(25 if lo < hi else 0):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if peak(mid) <= design.limit_c - LIMIT_MARGIN_K else (lo, mid)
    us = shape * [lo, 1.0]
    m = design.expl.model.params.motor
    emf = m.back_emf_v_s_per_rad * m.gear_ratio
    bus = (m.bus_voltage_v - 1.0 - motor.resistance_ohm(m, design.limit_c) * us[:, 0]) / emf
    us[:, 1] = np.clip(np.minimum(us[:, 1], bus), 0.0, None)
    return us if lo > 0 else None


# ----------------------------------------------------------------------------- information (choice among starts)
def _knot_grid(design: _Design, us: np.ndarray) -> ThermalGrid:
    """The design's knots as a diagnosis grid, after an instant at rest (its start: the state at rest)."""
    params, n = design.expl.model.params, us.shape[0]
    drivers = np.array(_drivers(params)(np.r_[0.0, us[:, 0]][None, :], np.r_[0.0, us[:, 1]][None, :]))
    steps = np.r_[1e-6, np.full(n, design.dt_s / SUBSTEPS)]
    ambient = np.full(n + 1, design.ambient_c)
    cols = np.vstack([steps, drivers[:3], ambient, drivers[3:], ambient])  # INPUT_ROWS: the room at the ambient
    inputs = np.hstack([cols[:, :1], np.repeat(cols[:, 1:], SUBSTEPS, axis=1)])
    time_s = np.arange(n + 1) * design.dt_s
    return ThermalGrid("design", time_s, np.zeros(n + 1), np.r_[us[:, 0], 0.0], np.r_[us[:, 1], 0.0], inputs,
                       np.arange(1, n + 1) * SUBSTEPS, True, True)


def _sensitivities(design: _Design, grid: ThermalGrid, weight: float) -> np.ndarray:
    """Weighted sensor sensitivities (samples x (parameters + offset)) of the richest explanation on ``grid``,
    each parameter scaled by its value (relative), over the sensor noise."""
    model, theta = design.expl.model, design.expl.theta(design.expl.richest)
    _, _, sens, _ = model.simulate(grid, theta, 0.0)
    scale = np.r_[np.where(theta > 0, theta, 1.0), 1.0]
    return np.sqrt(weight) * sens * scale / design.sigma_c


@dataclasses.dataclass(frozen=True)
class _Solved:
    family: str
    converged: bool
    us: np.ndarray
    xs: np.ndarray   # the explanations' states simulated along ``us`` (not the solver's)
    score: float     # mean over the pairs of log(RMS divergence / sensor noise) (-inf: violates a limit)
    message: str
    information: float = -math.inf   # D-criterion with the passive recordings (what picks the design)
    half_widths: np.ndarray | None = None   # predicted relative 95 % half-width of every free value (None: no design)


def _solve(design: _Design, family: str, us0: np.ndarray, settings: ExperimentSettings, targets,
           passive: list[np.ndarray]) -> _Solved:
    """The DDP from the start ``us0``; each pair's divergence keeps the sign it has on the start."""
    d0 = design.divergences(design.rollout(us0))
    signs = np.where(d0.mean(axis=0) >= 0, 1.0, -1.0)
    solver = DDPSolver(design.mm.problem, DDPSettings(max_iterations=settings.max_iterations, tolerance=TOLERANCE))
    result = solver.solve(design.x0, design.params(signs / targets), WarmStart(design.rollout(us0), us0))
    us = np.clip(result.us, 0.0, design.u_max)
    xs = design.rollout(us)
    if not np.all(np.isfinite(xs)) or _over(design, xs, us) > FEASIBILITY_K:
        return _Solved(family, result.success, us, xs, -math.inf, f"{family}: {result.message}; exceeds a limit")
    rms = np.sqrt(np.mean(design.divergences(xs) ** 2, axis=0))
    score = float(np.mean(np.log(np.maximum(rms / design.sigma_c, 1e-12))))
    blocks = passive + [_sensitivities(design, _knot_grid(design, us), design.dt_s / GRID_S)]
    info = log_det(information(blocks, design.expl.target_keys()))
    log.info("start %s: %s; divergence %.3g, information %.3g", family, result.message, score, info)
    return _Solved(family, result.success, us, xs, score, f"{family}: {result.message}", info, half_widths(blocks))


def _over(design: _Design, xs, us) -> float:
    """The largest excess over the winding limit or the bus voltage of any explanation along the design."""
    u = np.vstack([us, us[-1:]])
    windings = design.windings(xs, us)
    m = design.expl.model.params.motor
    emf = m.back_emf_v_s_per_rad * m.gear_ratio
    bus = motor.resistance_ohm(m, windings) * u[:, :1] + emf * u[:, 1:] - m.bus_voltage_v
    return float(max((windings - design.limit_c).max(), bus.max()))


# ----------------------------------------------------------------------------- the result
@dataclasses.dataclass(frozen=True)
class ExperimentDesign:
    """Result of :func:`design_experiment`: the contract's experiment JSON (:meth:`to_dict`), the knots'
    current and speed, each explanation's predicted sensor temperature and winding, and the programme
    (:meth:`programme`) the robot runs.  ``status``: ``designed``; ``nothing_undetermined`` and ``not_designable``
    (success, no experiment: nothing to settle, or only what needs other measurements than current and motion, or
    explanations no programme within the limits separates); ``diagnosis_failed``, ``unsupported`` (several
    sensors) and ``failed`` (no start gave a design within the limits): success false."""

    success: bool
    status: str
    message: str
    settings: ExperimentSettings
    limit_c: float
    targets: tuple[str, ...] = ()
    predicted_separation_k: dict = dataclasses.field(default_factory=dict)
    untargeted: tuple[dict, ...] = ()
    undeterminable: tuple[dict, ...] = ()
    labels: tuple[str, ...] = ()
    time_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    current_a: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    speed_rad_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    sensor_c: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    winding_c: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    bounds_rad: tuple[float, float] = (0.0, 0.0)
    starts: dict = dataclasses.field(default_factory=dict)   # family -> score (mean squared divergence / noise)
    solve_s: float = 0.0

    @property
    def designed(self) -> bool:
        return self.status == "designed"

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1]) if self.designed else 0.0

    @property
    def peak_winding_c(self) -> float | None:
        return float(self.winding_c.max()) if self.designed else None

    def programme(self) -> dict[str, np.ndarray]:
        """The rows the robot runs: ``time_s``, ``current_a``, ``position``, ``velocity`` (careful motion)."""
        require(self.designed, _SRC, "status", self.status, "no experiment was designed")
        s = self.settings
        return programme(float(self.time_s[1] - self.time_s[0]), self.current_a, self.speed_rad_s, self.bounds_rad,
                         s.acceleration_rad_s2, s.sample_s)

    def to_dict(self) -> dict:
        return {"success": self.success, "status": self.status, "message": self.message, "targets": list(self.targets),
                "duration_s": self.duration_s, "peak_winding_c": self.peak_winding_c, "limit_c": self.limit_c,
                "predicted_separation_k": dict(self.predicted_separation_k), "explanations": list(self.labels),
                "not_targeted": list(self.untargeted), "not_determinable": list(self.undeterminable), "starts": dict(self.starts), "solve_s": self.solve_s}

    def report(self) -> str:
        lines = [f"design-experiment: {self.status}: {self.message}"]
        if self.designed:
            lines.append(f"  {self.duration_s / 60:.0f} min, current up to {self.current_a.max():.2f} A, speed up to "
                         f"{self.speed_rad_s.max():.2f} rad/s, predicted winding peak {self.peak_winding_c:.1f} °C "
                         f"(limit {self.limit_c:g} °C)")
            lines += [f"  {t}: the explanations' sensor predictions differ by {k:.2f} K (RMS, weakest rival)"
                      for t, k in self.predicted_separation_k.items()]
        lines += [f"  not targeted: {u['term']}: {u['reason']}" for u in self.untargeted]
        lines += [f"  not determinable: {u['key']} ({u['term']}): {u['reason']}" for u in self.undeterminable]
        return "\n".join(lines)

    def plot(self, path) -> None:
        """The figure (:func:`~thermo_ddp.tasks.experiment_motion.plot_experiment`) written to ``path``."""
        require(self.designed, _SRC, "status", self.status, "no experiment was designed")
        plot_experiment(self, path)


# ----------------------------------------------------------------------------- the API
def _ambient(diagnosis: ThermalDiagnosis) -> float:
    rooms = [g.ambient_c for g in diagnosis.grids if g.has_ambient and g.ambient_c is not None]
    return float(np.mean(np.concatenate(rooms))) if rooms else diagnosis.params.thermal.ambient_c


def _separations(design: _Design, xs) -> dict[str, float]:
    """Per target: the RMS sensor difference of its least separated pair of explanations (pairs holding one of its
    rivals) [K]."""
    rms = np.sqrt(np.mean(design.divergences(xs) ** 2, axis=0))
    expl, pairs = design.expl, _pairs(design.thetas.shape[0])
    return {t.term: float(min(rms[k] for k, (i, j) in enumerate(pairs) if {i, j} & {expl.index(r) for r in t.rivals}))
            for t in expl.targets}


def _not_designed(status: str, message: str, settings, limit_c, **fields) -> ExperimentDesign:
    return ExperimentDesign(status in ("nothing_undetermined", "not_designable"), status, message, settings, limit_c,
                            **fields)


def design_experiment(recordings, parameters=None, settings: ExperimentSettings | None = None,
                      diagnosis: ThermalDiagnosis | None = None) -> ExperimentDesign:
    """Plan the experiment that settles what ``recordings`` leave undetermined (module docstring).
    ``parameters``: the parameter file (path or :class:`JointParameters`; default: the elbow's);
    ``diagnosis``: the recordings' diagnosis when already computed."""
    settings = settings or ExperimentSettings()
    params = load_joint_parameters(parameters)
    limit_c = joint_limit_c(params, settings.limit_c)
    diagnosis = diagnosis or diagnose_thermal(recordings, parameters=params,
                                              settings=ThermalDiagnosisSettings(progress=settings.progress))
    if not isinstance(diagnosis, ThermalDiagnosis):
        return _not_designed("unsupported", "no experiment designed: recordings with several sensors (a network "
                             "diagnosis) are not supported yet", settings, limit_c)
    if not diagnosis.success:
        return _not_designed("diagnosis_failed", f"no experiment designed: the diagnosis did not succeed "
                             f"({diagnosis.status}: {diagnosis.message})", settings, limit_c)
    if not diagnosis.not_determinable:
        return _not_designed("nothing_undetermined", "the recordings leave nothing undetermined: no experiment needed",
                             settings, limit_c)
    expl = explanations(diagnosis)
    if not expl.targets:
        return _not_designed("not_designable", "what the recordings leave undetermined needs other measurements "
                             "than a current and motion programme", settings, limit_c, untargeted=expl.untargeted)
    idle = float(np.asarray(expl.model.equilibrium(*_rest(expl, _ambient(diagnosis)))).ravel()[expl.model.winding])
    require(idle < limit_c, params.path, "limit_c", limit_c,
            f"not above the winding's temperature at rest, {idle:.1f} °C: raise the limit")
    return _design(expl, diagnosis, params, limit_c, settings)


def _rest(expl: Explanations, ambient_c: float):
    rest = np.zeros(len(INPUT_ROWS))
    rest[[INPUT_ROWS.index("ambient_c"), INPUT_ROWS.index("room_c")]] = ambient_c
    return rest, expl.theta(expl.reference)


def _starts(design: _Design) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The starts within the limits, and each pair's largest divergence over them (K)."""
    starts = {f: _scaled(design, _family(f, design.mm.horizon, design.u_max)) for f in FAMILIES}
    starts = {f: us for f, us in starts.items() if us is not None}
    reach = np.max([np.abs(design.divergences(design.rollout(us))).max(axis=0) for us in starts.values()]
                   or [np.zeros(design.pairs)], axis=0)
    return starts, reach


def _distinct(count: int, reach: np.ndarray, sigma_c: float) -> list[int]:
    """The explanations kept: a later one that no start moves a sensor-noise apart from a kept one is the same
    explanation for this experiment (e.g. a rival whose fitted extra heat is nil)."""
    keep = []
    for k in range(count):
        if all(reach[_pairs(count).index((i, k))] >= sigma_c for i in keep):
            keep.append(k)
    return keep


def _design(expl, diagnosis, params, limit_c, settings) -> ExperimentDesign:
    lo, hi, vmax = joint_bounds(params, settings.margin_rad)
    u_max = np.array([params.motor.current_peak_a, vmax])
    tic = time.perf_counter()
    rise = max(winding_rise_k_per_w(diagnosis), settings.winding_rise_k_per_w)
    design = _build(expl, diagnosis.noise.total_c, limit_c, _ambient(diagnosis), u_max, settings, rise)
    starts, reach = _starts(design)
    keep = _distinct(design.thetas.shape[0], reach, design.sigma_c)
    if len(keep) < design.thetas.shape[0]:
        expl = expl.subset(keep)
        if not expl.targets:
            return _not_designed("not_designable", "no current and motion programme within the limits moves the "
                                 "explanations' predictions a sensor noise apart", settings, limit_c,
                                 untargeted=expl.untargeted)
        design = _build(expl, diagnosis.noise.total_c, limit_c, _ambient(diagnosis), u_max, settings, rise)
        starts, reach = _starts(design)
    targets = TARGET_FACTOR * np.maximum(reach, design.sigma_c)
    passive = [_sensitivities(design, g, float(np.median(np.diff(g.time_s))) / GRID_S) for g in diagnosis.grids]
    solved = [_solve(design, f, us, settings, targets, passive)
              for f, us in tqdm(starts.items(), desc="design-experiment starts", disable=_hide(settings))]
    best = max((s for s in solved if math.isfinite(s.score)), key=lambda s: s.information, default=None)
    common = dict(untargeted=expl.untargeted, labels=tuple(r.label for r in expl.rivals),
                  targets=tuple(t.term for t in expl.targets),
                  starts={s.family: {"divergence": s.score, "information": s.information}
                          if math.isfinite(s.score) else None for s in solved},
                  solve_s=time.perf_counter() - tic)
    if best is None:
        reasons = "; ".join(s.message for s in solved) or "no start stays under the limit"
        return _not_designed("failed", f"no design within the limits ({reasons})", settings, limit_c, **common)
    optimum = "converged" if best.converged else (f"not converged in {settings.max_iterations} DDP iterations: the "
                                                  "best iterate, its limits checked by simulation")
    message = (f"settles {', '.join(common['targets'])} in {settings.duration_s / 60:.0f} min "
               f"(best start: {best.family}, {optimum}; {len(expl.rivals)} explanations)")
    widths = [s.half_widths for s in solved if math.isfinite(s.score)]
    return ExperimentDesign(True, "designed", message, settings, limit_c,
                            undeterminable=undeterminable(expl, widths, diagnosis.final_fit.stderr_inflation),
                            predicted_separation_k=_separations(design, best.xs),
                            time_s=np.arange(design.mm.horizon + 1) * design.dt_s, current_a=best.us[:, 0],
                            speed_rad_s=best.us[:, 1], sensor_c=design.sensors(best.xs),
                            winding_c=design.windings(best.xs, best.us), bounds_rad=(lo, hi), **common)


def check_request(parameters, settings: ExperimentSettings):
    """The parameter file and the limit, checked before any work (InputError): a limit above the winding's rating,
    not above the room, or not above the winding's temperature at rest (the file's drive idle heat)."""
    params = load_joint_parameters(parameters)
    limit_c = joint_limit_c(params, settings.limit_c)
    arm = ActuatedArm.from_parameters(ArmSettings(joints=(params.joint,)), {params.joint: params})
    check_idle_below_limits(arm, {params.joint: limit_c})
    return params


def write_programme(rows: dict[str, np.ndarray], path) -> None:
    """The programme as a recording-format CSV (header row, :data:`PROGRAMME_COLUMNS`)."""
    table = np.column_stack([rows[c] for c in PROGRAMME_COLUMNS])
    np.savetxt(path, table, delimiter=",", header=",".join(PROGRAMME_COLUMNS), comments="", fmt="%.6g")


def _hide(settings: ExperimentSettings) -> bool | None:
    return None if settings.progress is None else not settings.progress


__all__ = ["ExperimentDesign", "ExperimentSettings", "FAMILIES", "PROGRAMME_COLUMNS", "check_request",
           "design_experiment", "winding_rise_k_per_w", "write_programme"]
