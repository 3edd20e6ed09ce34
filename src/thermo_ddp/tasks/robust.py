"""The robust lift: the longest hold that keeps the winding under the limit for every motor of an uncertainty set.

``plan_lift(..., uncertainty=0.2)`` (or ``uncertainty="file"``: the parameter file's ``[uncertainty]``):

1. the nominal plan (:func:`thermo_ddp.tasks.lift.plan_lift`) gives the nominal hold;
2. the worst motor of the set for the current plan is searched (:class:`~thermo_ddp.tasks.uncertainty.WorstCase`:
   the replay of the plan's current and motion through each motor, the planner's own discrete model);
3. when it exceeds the limit by more than :data:`TOLERANCE_K`, it becomes a scenario of the multi-model
   problem (:class:`thermo_ddp.multi_model.MultiModelProblem`: the mechanics shared, one thermal state per
   scenario, the winding and voltage constraints per scenario, the costs on the nominal scenario), and the
   longest hold of that problem is searched as for the nominal lift;
4. steps 2-3 repeat until no motor of the set exceeds the limit by more than :data:`TOLERANCE_K`: the number
   of scenarios is what binds, not a sample count.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any

import casadi as ca
import numpy as np
from tqdm import tqdm

from .._config import require
from .._memo import Memo
from ..model.parameters import packaged_parameter_file
from ..model.arm import ELBOW
from ..multi_model import MultiModelProblem
from ..model.actuated import ActuatedArm
from .attempts import SolverLadder
from .hold_search import longest_feasible_hold
from .lift import (LIFT_PARAMETERS, LiftPlan, LiftProblem, LiftSettings, build_lift_problem, lift_terms, make_solver,
                   plan_lift, time_to_limit_s)
from .problem import initial_guess
from .verdicts import binding_constraints, cause_of, deciding_constraints, solver_summary
from .uncertainty import UncertaintySet, WorstCase, check_fraction, scenario_step

log = logging.getLogger(__name__)

TOLERANCE_K = 0.1     # the largest excess over the limit of any motor of the set that a robust plan allows
MAX_SCENARIOS = 8     # scenarios added at most (each one a worst motor the previous plan overheated)
BAND_SAMPLES = 50     # random motors of the set replayed for the plot's band (with the worst one)
STARTS = ("sensor", "measured", "rest")
_STRUCTURES = Memo()  # the robust lift's stacked OCP by structure and scenario count
_SRC = "plan_lift"


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """What the robust lift guards against.

    ``value``: a fraction (every thermal capacity and resistance, the winding resistance and the drive's
    losses within +-fraction of the file's values) or ``"file"`` (the parameter file's ``[uncertainty]``
    intervals). ``start``: the temperatures every motor starts from (docs/guide/planning.md):

    - ``"sensor"`` (default): what the robot measures before a lift. Its casing sensor reads the plan's
      initial casing temperature; the motor has rested (no current for minutes), so its faster nodes sit at
      their equilibrium given that casing: the winding, which has no heat source at rest, at the casing's
      temperature (time constant ~36 s), the unmeasured drive at each motor's own balance of idle heat and
      conduction (~2.5 min). The casing itself (time constant tens of minutes) need not be at rest: it is read.
    - ``"measured"``: every node at the plan's initial state for every motor (an observer's estimate taken
      as exact, the drive included).
    - ``"rest"``: each motor at its own equilibrium at rest, its casing included: nothing measured, the most
      conservative (the casing sensor's reading is ignored)."""

    value: Any = 0.2
    start: str = "sensor"

    def __post_init__(self):
        if not (isinstance(self.value, str) and self.value == "file"):
            object.__setattr__(self, "value", check_fraction(self.value))
        require(self.start in STARTS, _SRC, "uncertainty.start", self.start, f"choose one of {', '.join(STARTS)}")

    @classmethod
    def of(cls, uncertainty) -> "Uncertainty":
        return uncertainty if isinstance(uncertainty, cls) else cls(uncertainty)

    def uncertainty_set(self, lp: LiftProblem) -> UncertaintySet:
        params = lp.model.params[lp.model.joints[0]]
        if self.value == "file":
            return UncertaintySet.from_file(params, lp.settings.parameter_file or packaged_parameter_file(ELBOW))
        return UncertaintySet.from_fraction(params, self.value)


@dataclasses.dataclass(frozen=True)
class RobustLiftProblem(LiftProblem):
    """The lift with scenarios: the stacked OCP (``problem``), its data, and the nominal lift it extends."""

    nominal: LiftProblem
    multi: MultiModelProblem
    thetas: np.ndarray

    def with_hold(self, hold_s: float) -> "RobustLiftProblem":
        nominal = self.nominal.with_hold(hold_s)
        return dataclasses.replace(self, nominal=nominal, params=self.multi.params(nominal.params, self.thetas),
                                   hold_knots=nominal.hold_knots)

    def scenario(self, xs: np.ndarray, k: int) -> np.ndarray:
        """Scenario ``k``'s whole states (N+1, nx) from the stacked ones."""
        return self.multi.scenario_states(xs)[:, k]


def start_nodes(model: ActuatedArm, start: str):
    """The thermal nodes every motor of the set starts at the given temperatures for ``start`` (see
    :class:`Uncertainty`): the sensor nodes, every node (None) or none."""
    return tuple(i - 2 * model.nu for i in model.sensor_indices()) if start == "sensor" else \
        None if start == "measured" else ()


def env_of(p):
    """[ambient_c, payload_kg] of the lift's per-knot parameters ``p`` (the scenario step's environment)."""
    return ca.vertcat(p[LIFT_PARAMETERS.slice("ambient_c")], p[LIFT_PARAMETERS.slice("payload_kg")])


def _structure(lp: LiftProblem, uset: UncertaintySet, scenarios: int) -> MultiModelProblem:
    s, model = lp.settings, lp.model

    def build():
        costs, tcosts, cons, tcons, peak = lift_terms(model, s)
        step = scenario_step(model, uset.keys, s.dt_s, s.integrator, LIFT_PARAMETERS.size, env_of)
        mm = MultiModelProblem(step, 1, scenarios, shared=2 * model.nu, costs=costs, terminal_costs=tcosts,
                               constraints=cons, terminal_constraints=tcons, u_lb=[-peak], u_ub=[peak],
                               parameters=LIFT_PARAMETERS, name="robust_lift")
        mm.problem.functions  # built once, shared by every horizon
        return mm

    key = (model.structure_key, s.dt_s, s.integrator, s.careful_motion, s.acceleration_limit_rad_s2 is not None,
           uset.keys, scenarios)
    return _STRUCTURES.get(key, build)


def robust_problem(lp: LiftProblem, uset: UncertaintySet, thetas, worst: WorstCase) -> RobustLiftProblem:
    """The lift ``lp`` (nominal, any hold) with one scenario per row of ``thetas`` (the first: the file's
    values); every scenario starts where the set says (:meth:`WorstCase.initial_c`)."""
    thetas = np.atleast_2d(np.asarray(thetas, float))
    mm = _structure(lp, uset, thetas.shape[0]).with_horizon(lp.problem.horizon)
    n = lp.model.nu
    x0 = np.array([np.concatenate([lp.x0[:2 * n], worst.initial_c(th, lp.model.ambient_c)]) for th in thetas])
    return RobustLiftProblem(model=lp.model, problem=mm.problem, x0=mm.x0(x0), params=mm.params(lp.params, thetas),
                             time_s=lp.time_s, box_names=lp.box_names, settings=lp.settings, hold_knots=lp.hold_knots,
                             nominal=lp, multi=mm, thetas=thetas)


@dataclasses.dataclass(frozen=True)
class RobustSummary:
    """What the robust plan adds (the plan JSON's ``"robust"``): the set, the scenarios it took, the nominal
    hold, the worst motor of the set for the returned plan and the band of windings over the set."""

    uncertainty: Uncertainty
    uset: UncertaintySet
    thetas: np.ndarray
    nominal_hold_s: float
    worst_winding_c: float
    worst_theta: np.ndarray
    worst_certified: bool
    band_c: np.ndarray        # (N+1, 2): the lowest and highest winding over the replayed motors
    nominal_solve_s: float
    worst_case_s: float
    verdict: str = ""         # why no plan can be safe for the set, when the set itself says so

    def to_dict(self) -> dict:
        return {"uncertainty": self.uncertainty.value, "start": self.uncertainty.start, "scenarios": int(self.thetas.shape[0]),
                "nominal_hold_s": self.nominal_hold_s, "worst_winding_c": self.worst_winding_c,
                "worst_motor": dict(zip(self.uset.keys, self.worst_theta.tolist())),
                "worst_certified": self.worst_certified, "set": self.uset.to_dict(),
                "nominal_solve_s": self.nominal_solve_s, "worst_case_s": self.worst_case_s}


@dataclasses.dataclass(frozen=True)
class RobustLiftPlan(LiftPlan):
    """A :class:`LiftPlan` safe for every motor of the set (its trajectories: the nominal motor's)."""

    robust: RobustSummary = dataclasses.field(kw_only=True)

    def to_dict(self) -> dict:
        return {**super().to_dict(), "robust": self.robust.to_dict()}

    def headline(self) -> str:
        r = self.robust
        if r.verdict:
            return f"{self.settings.payload_kg:g} kg: {r.verdict}"
        return (f"{super().headline()}; for every motor of {r.uset.label} (nominal motor alone "
                f"{r.nominal_hold_s:.1f} s; worst motor's winding {r.worst_winding_c:.1f} °C; "
                f"{r.thetas.shape[0]} scenario(s))")

    def plot(self, path=None):
        """The lift's figure with the band of winding temperatures over the set (the replayed motors)."""
        from .plots import plot_lift
        r = self.robust
        fig = plot_lift(self)
        ax = fig.axes[3]
        ax.fill_between(self.time_s, r.band_c[:, 0], r.band_c[:, 1], color="tab:red", alpha=0.25,
                        label=f"winding over the set ({r.uset.label}: {BAND_SAMPLES} random motors and the worst)")
        ax.legend(loc="best", fontsize=8)
        if path is not None:
            fig.savefig(path, dpi=100)
        return fig


@dataclasses.dataclass
class _Round:
    """The current plan of the robust search: its problem, result, hold (knots; -1: none feasible) and the
    searches so far."""

    lp: LiftProblem
    result: Any
    knots: int
    searches: list
    failed: bool = False

    @property
    def qv(self) -> np.ndarray:
        xs = self.lp.scenario(self.result.xs, 0) if isinstance(self.lp, RobustLiftProblem) else self.result.xs
        return xs[:, :2 * self.lp.model.nu]


@dataclasses.dataclass(frozen=True)
class _SearchView:
    """What the longest-hold search sees of a robust lift: its holds are the robust problem's, its thermal
    prediction that of the worst scenario (its motor and start), the one that binds."""

    robust: RobustLiftProblem
    model: ActuatedArm
    x0: np.ndarray

    def __getattr__(self, name):
        return getattr(self.robust, name)

    def with_hold(self, hold_s: float) -> RobustLiftProblem:
        return self.robust.with_hold(hold_s)


def _search_view(rlp: RobustLiftProblem, uset: UncertaintySet, theta, start_c) -> _SearchView:
    model = rlp.model
    params = {j: uset.parameters(model.params[j], theta) for j in model.joints}
    worst_model = ActuatedArm.from_parameters(model.arm.settings, params)
    return _SearchView(rlp, worst_model, np.concatenate([rlp.x0[:2 * model.nu], start_c]))


def _hold_estimate_knots(rnd: _Round, winding: np.ndarray, limit_c: float) -> int:
    """Where the worst motor's winding first crosses the limit, counted from the hold's start: the next
    search's first probe."""
    start = rnd.lp.hold_knots[0]
    over = np.flatnonzero(winding[start:] > limit_c)
    return int(max(0, (over[0] if over.size else rnd.lp.hold_knots[1] - start) - 1))


def plan_robust_lift(settings: LiftSettings, uncertainty) -> RobustLiftPlan:
    """The robust lift (module docstring); ``settings`` as for :func:`plan_lift`; ``uncertainty``: an
    :class:`Uncertainty`, or its ``value`` (a fraction or ``"file"``)."""
    spec = Uncertainty.of(uncertainty)
    lp = build_lift_problem(settings)
    uset = spec.uncertainty_set(lp)
    settings, limit, model = lp.settings, lp.settings.limit_c, lp.model
    step = scenario_step(model, uset.keys, settings.dt_s, settings.integrator, LIFT_PARAMETERS.size, env_of)
    worst = WorstCase(model, uset, step, model.index(model.joints[0], "winding_c"),
                      None if spec.start == "rest" else lp.x0[2 * model.nu:], start_nodes(model, spec.start))
    nominal = plan_lift(settings=settings)
    idle_c, idle_theta = worst.hottest_idle_c(model.ambient_c)
    if idle_c >= limit:
        return _idle_too_hot(nominal, spec, uset, idle_c, idle_theta)
    knots = -1 if nominal.status == "infeasible" else int(round(nominal.achieved_hold_s / settings.dt_s))
    rnd = _Round(lp.with_hold(nominal.achieved_hold_s), _as_result(nominal), knots, [], nominal.status == "failed")
    thetas, failure, worst_s = [uset.nominal], "", 0.0
    bar = tqdm(desc="robust plan: worst motors added", unit="scenario", leave=False, disable=None)  # terminal only
    while True:
        tic = time.perf_counter()
        motor = worst.search(rnd.qv, rnd.result.us, _nominal_params(rnd.lp), model.ambient_c)
        worst_s += time.perf_counter() - tic
        if motor.peak_c <= limit + TOLERANCE_K or rnd.knots < 0 or rnd.failed:
            break
        if len(thetas) > MAX_SCENARIOS or any(np.allclose(motor.theta, th) for th in thetas):
            failure = (f"the robust search did not settle: after {len(thetas)} scenarios a motor of the set still "
                       f"reaches {motor.peak_c:.1f} °C")
            break
        thetas.append(motor.theta)
        rnd = _robust_round(lp, uset, thetas, worst, rnd, motor)
        bar.update(1)
        log.info("%d scenarios: robust hold %.1f s (worst motor %.1f °C before)", len(thetas),
                 max(rnd.knots, 0) * settings.dt_s, motor.peak_c)
    bar.close()
    return _plan(nominal, rnd, spec, uset, np.array(thetas), motor, worst, worst_s, failure)


def _robust_round(lp, uset, thetas, worst: WorstCase, rnd: _Round, motor) -> _Round:
    """The longest hold with the scenarios ``thetas`` (the last: the worst motor of the previous plan)."""
    winding = worst.replay(motor.theta, rnd.qv, rnd.result.us, _nominal_params(rnd.lp), lp.model.ambient_c)
    rlp = robust_problem(lp, uset, thetas, worst)
    ladder = SolverLadder(rlp.problem, make_solver(rlp))
    view = _search_view(rlp, uset, motor.theta, worst.initial_c(motor.theta, lp.model.ambient_c))
    search = longest_feasible_hold(view, lambda probe, warm: ladder.solve(probe, warm or initial_guess(probe)),
                                   _hold_estimate_knots(rnd, winding, lp.settings.limit_c))
    best, outcome = search.best
    return _Round(best, outcome.result, search.knots, rnd.searches + [search], search.failed is not None)


def _nominal_params(lp: LiftProblem) -> np.ndarray:
    return lp.nominal.params if isinstance(lp, RobustLiftProblem) else lp.params


def _as_result(plan: LiftPlan):
    """A stand-in result of the nominal plan for the first round (its trajectories)."""
    return dataclasses.make_dataclass("NominalResult", ["xs", "us"])(plan.xs, plan.us)


def _band(worst: WorstCase, rnd: _Round, motor, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    thetas = [worst.uset.nominal, motor.theta, *worst.uset.sample(rng, BAND_SAMPLES)]
    w = np.array([worst.replay(th, rnd.qv, rnd.result.us, _nominal_params(rnd.lp), rnd.lp.model.ambient_c)
                  for th in thetas])
    return np.column_stack([w.min(axis=0), w.max(axis=0)])


def _status(rnd: _Round, failure: str) -> str:
    if failure or rnd.failed:
        return "failed"
    top = rnd.lp.settings.knots()["hold"]
    return "feasible" if rnd.knots == top else "infeasible" if rnd.knots < 0 else "infeasible_hold"


def _plan(nominal, rnd, spec, uset, thetas, motor, worst, worst_s, failure) -> RobustLiftPlan:
    status = _status(rnd, failure)
    robust = RobustSummary(spec, uset, thetas, nominal.achieved_hold_s, motor.peak_c, motor.theta, motor.certified,
                           _band(worst, rnd, motor), nominal.solver["total_solve_s"], worst_s)
    if not rnd.searches:  # the nominal plan is safe for the whole set (or failed, or cannot lift at all)
        return _robust(nominal, nominal.status, nominal.achieved_hold_s, robust, failure)
    lp, result, s = rnd.lp, rnd.result, rnd.lp.settings
    xs = lp.scenario(result.xs, 0)
    every = [r for search in rnd.searches for r in search.results]
    total = nominal.solver["total_solve_s"] + sum(search.solve_s for search in rnd.searches)
    cause = None if status in ("feasible", "failed") else cause_of(deciding_constraints(lp, result, status == "infeasible"))
    achieved = s.hold_s if status == "feasible" else max(rnd.knots, 0) * s.dt_s
    plan = RobustLiftPlan(
        status == "feasible", status, failure, s, float(achieved), lp.time_s, xs, result.us, lp.model,
        solver_summary(result, total, len(every) + nominal.solver["solves"], every, name=s.solver),
        tuple(binding_constraints(lp, result)), time_to_limit_s(lp.model, xs[lp.hold_knots[0]], s.goal_rad, s.limit_c),
        cause, robust=robust)
    return dataclasses.replace(plan, message=failure or plan.headline())


def _robust(plan: LiftPlan, status, achieved, robust: RobustSummary, message: str = "") -> RobustLiftPlan:
    fields = {f.name: getattr(plan, f.name) for f in dataclasses.fields(LiftPlan)}
    out = RobustLiftPlan(**(fields | {"status": status, "feasible": status == "feasible",
                                      "achieved_hold_s": float(achieved)}), robust=robust)
    return dataclasses.replace(out, message=message or out.headline())


def _idle_too_hot(nominal: LiftPlan, spec, uset, idle_c: float, theta) -> RobustLiftPlan:
    """The set holds a motor that already exceeds the limit at rest: no plan can be safe for it."""
    limit = nominal.settings.limit_c
    verdict = (f"infeasible for the set {uset.label}: its hottest motor already sits at {idle_c:.1f} °C at rest, "
               f"not below the {limit:g} °C limit (narrow the set or raise the limit)")
    band = np.column_stack([nominal.series("winding_c")[:, 0]] * 2)
    return _robust(nominal, "infeasible", 0.0, RobustSummary(
        spec, uset, uset.nominal[None], nominal.achieved_hold_s, idle_c, np.asarray(theta), True, band,
        nominal.solver["total_solve_s"], 0.0, verdict))
