"""Receding-horizon control of the elbow lift: the lift OCP re-solved from the estimated state
every control period, warm-started from the previous plan shifted by one knot.

The horizon keeps a fixed length (one built solver); the task's per-knot parameters (reference,
hold flag, ambient) are shifted in time and the last row (at rest at the start) is held beyond the
task's end. When a re-solve is infeasible, the remaining hold is shortened (the winding limit has
priority over holding) and the problem re-solved; if still infeasible, the controller falls back
to the previous plan's shifted control with its feedback gains, u = u_j + K_j (x - x_j).

Faults: a solve that fails, or takes longer than ``settings.controller.max_solve_s`` (its answer would come
too late; it is discarded), also leads to that fallback, and the period says so in its events. With
``settings.controller.derate`` the fallback current is capped at the no-heating current (the current whose
Joule heat the winding conducts away at its present temperatures, from the model's ODE) once the
planning state's winding is at the planning limit; the range guard (:meth:`RecedingHorizonController.range_guard`)
then brakes a fallback's current, and every current from the lowering's start on, into the ``stop_approach``
envelope toward the joint's stops, over the derating; the voltage guard
(:meth:`RecedingHorizonController.voltage_guard`) keeps every period's voltage under the bus, over both. While the
lowering lies ahead, its knots' winding limit is lowered by ``lowering_reserve_c`` (the hold keeps the lowering's
heat). ``tightening_c`` raises every thermal node of the planning state (the estimate) by that many kelvin: with a
nearly linear network and a casing time constant of tens of minutes this tightens the limit by about as much over
the whole window.

With ``settings.controller.robust_uncertainty`` the hold is also kept safe for every motor of an uncertainty
set (:mod:`thermo_ddp.mpc.robust`).
"""
from __future__ import annotations

import dataclasses
import functools
import logging

import casadi as ca
import numpy as np

from ..tasks.attempts import SolverLadder
from ..tasks.constraints import bus_voltage, toward_stops
from ..tasks.hold_search import longest_feasible_hold
from ..tasks.lift import LiftProblem, LiftSettings, build_lift_problem, initial_guess, make_solver, time_to_limit_s
from .._config import require
from ..model.actuated import ActuatedArm
from ..ocp import Constraint, OptimalControlProblem, term_function
from ..solvers import DDPSettings, SolverResult, WarmStart
from ..solvers.kkt import constraint_rows
from ..tasks.limits import default_limit_c
from .robust import RobustHold
from .settings import MPCSettings

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class ControlStep:
    """One control period: the current sent and how it was obtained."""

    current_a: np.ndarray
    status: str                # "cold", "solved", "hold_shortened" or "fallback"
    solver_status: str         # of the last solve
    solve_s: float             # all solves of this period
    first_solve_s: float       # the first (warm) solve alone
    iterations: int            # of all solves
    solves: int
    hold_s: float              # the planned hold after this period
    cost: float                # of the last solve
    events: tuple[str, ...] = ()   # solve_failed, solve_timeout, fallback_plan, derate, hold_shortened, ...


def planning_problem(settings: MPCSettings, model: ActuatedArm) -> LiftProblem:
    """The lift OCP of the controller: ``horizon_knots`` knots at the control period, limit backed off,
    careful motion unless ``settings.controller.careful_motion`` is off."""
    settings = settings.with_default_limit(default_limit_c(model.params[model.joints[0]]))
    base = LiftSettings(payload_kg=settings.scenario.payload_kg, limit_c=settings.planning_limit_c,
                        dt_s=settings.controller.control_period_s, integrator=settings.controller.integrator,
                        parameter_file=settings.scenario.parameter_file,
                        careful_motion=settings.controller.careful_motion)
    room = settings.controller.horizon_knots * base.dt_s - base.lift_s - base.lower_s - base.settle_s
    require(room >= -1e-9, "MPCSettings", "horizon_knots", settings.controller.horizon_knots,
            f"the window must span the lift, lowering and settling ({base.lift_s + base.lower_s + base.settle_s:g} s)")
    lp = build_lift_problem(dataclasses.replace(base, hold_s=max(room, 0.0)), model)
    return dataclasses.replace(lp, problem=controller_ocp(lp.problem, settings))


def controller_ocp(problem: OptimalControlProblem, settings: MPCSettings) -> OptimalControlProblem:
    """``problem`` (the lift's OCP) as the controller of ``settings`` plans it (:func:`planner_ocp` with the
    settings' back-off band, careful-motion weights and margins)."""
    c = settings.controller
    return planner_ocp(problem, settings.scenario.backoff_c, c.backoff_weight_per_k2, c.motion_weight, c.stop_weight,
                       {"joint_range": c.range_margin_rad, "bus_voltage": c.voltage_margin_v})


# Stage rows on the state alone that the window switches off at the measured present state x_0, which no control
# can change (:func:`free_present`): the hold band (hold_flag 0) and the winding limit (limit_c at PRESENT_LIMIT_C).
FREE_AT_PRESENT = ("hold_band", "winding_limit")
PRESENT_LIMIT_C = 1e4  # the window's winding limit at x_0: none (a finite number: IPOPT refuses infinite values)
MARGIN_WEIGHTS = {"joint_range": 1e6, "bus_voltage": 1e3}  # per rad^2, per V^2
SOFT_ROWS = ("stop_approach", "one_way")  # careful motion's stage rows (tasks.lift)
ON_NEXT_STATE = SOFT_ROWS  # hard careful motion (weight 0): moved from x_k to x_{k+1}


def free_present(params: np.ndarray, layout) -> np.ndarray:
    """The per-knot parameters ``params`` (the lift's layout) with the rows of :data:`FREE_AT_PRESENT` switched
    off at knot 0 (a copy)."""
    params = np.array(params, dtype=float)
    layout.assign(params[:1], "hold_flag", 0.0)
    layout.assign(params[:1], "limit_c", PRESENT_LIMIT_C)
    return params


def planner_ocp(problem: OptimalControlProblem, backoff_c: float, backoff_weight: float,
                motion_weight: float = 0.0, stop_weight: float = 0.0,
                margins: dict[str, float] | None = None) -> OptimalControlProblem:
    """The lift OCP as the receding-horizon planner solves it: the winding's back-off made soft when
    ``backoff_weight`` > 0, careful motion's rows (:data:`SOFT_ROWS`) soft when their weight is > 0 (``one_way``:
    ``motion_weight``, ``stop_approach``: ``stop_weight``; 0: hard, moved from x_k to x_{k+1} = f(x_k, u_k, p_k),
    renamed ``<name>_next``).

    The state's rows never bind the measured present state x_0: the window switches off the winding limit and
    the hold band there (:func:`free_present`), so the constrained states are x_1..x_N. Otherwise an estimate a
    few mK over the limit (plant mismatch during one period) makes every re-solve infeasible at knot 0; with
    careful motion, so does a measured speed against the phase's direction or near a stop (measured on the
    +15 % resistance plant at 84 °C: 16 fallback periods with them at x_0, 1 moved). The winding limit stays on
    x_k (its knot-0 row off) rather than on f(x_k, u_k): the same constrained states, without the composed
    rows' second derivatives of the step in every knot's local model (bench_mpc_step: the fused backward knot
    11,564 -> 7,608 instructions with careful motion).

    ``margins`` (row name -> margin, in the row's unit; ``joint_range``, ``bus_voltage``): the band within the
    margin of the hard row costs ``0.5 * MARGIN_WEIGHTS[name] * excess^2``, the hard row kept (measured on the
    nominal sweep: without them, loops whose plans used the range to the stop or the whole bus voltage crossed
    them by 0.1-0.9 mrad and 0.1-1.8 V on the mismatched plant).

    Soft back-off: the winding is held hard under the task's limit (the planning limit + ``backoff_c``) and
    the band above the planning limit costs ``0.5 * backoff_weight * excess_K^2``. A plant hotter than
    predicted (the estimate inside the band) then gets the best plan that leaves the band soonest instead
    of an infeasible re-solve and the fallback's open-loop current.

    Soft careful motion: each row costs ``0.5 * motion_weight * excess^2`` (rad/s) on x_k (a cost on x_0 is a
    constant): the motion's quality gives way by what the weight allows; the thermal limit and the hold band stay
    hard. Measured on the closed loop at 84 °C (+15 % resistance plant) with weights 1e4 / 10 / careful motion off:
    speed near the stop 0.30 / 0.29 / 0.36 rad/s, final speed 8e-5 / 8e-5 / 2e-3 rad/s, peak acceleration 8.4 / 11.7
    / 17.9 rad/s^2, 3 / 7 / 8 reversals. Hard rows or a weight of 100 and more: a plant that lags the plan (20 %
    more payload) arrives late at the hold's knot at rest (|v| <= 0.01 rad/s there) and the re-solves fail (5 to 94
    fallback periods, the hold cut to 0.3-0.6 s); at 10, 3 fallback periods and a 7.3 s hold (careful motion off:
    2, 7.1 s).
    """
    x, u, p = (ca.SX.sym(n, problem.dynamics.size1_in(i)) for i, n in enumerate(problem.dynamics.name_in()))
    x_next = ca.SX.sym("x_next", problem.nx)
    constraints, costs = [], list(problem.costs)
    weights = dict(zip(SOFT_ROWS, (stop_weight, motion_weight)))
    for c in problem.constraints:
        if weights.get(c.name, 0.0) > 0:
            costs.append(c.penalty(weights[c.name], f"{c.name}_penalty"))
            continue
        if (margins or {}).get(c.name, 0.0) > 0:
            costs.append(c.shifted(-margins[c.name]).penalty(MARGIN_WEIGHTS[c.name], f"{c.name}_margin"))
        if c.name in ON_NEXT_STATE:
            name = f"{c.name}_next"
            c = Constraint(name, term_function(name, c.function(x_next, u, p), "g", x, p, u, x_next))
        if c.name == "winding_limit" and backoff_weight > 0:
            costs.append(c.penalty(backoff_weight, "winding_backoff"))
            c = c.shifted(backoff_c)
        constraints.append(c)
    return dataclasses.replace(problem, costs=tuple(costs), constraints=tuple(constraints), name="lift_mpc")


# The re-solves' stopping rule: |Qu|_inf <= 1e-5 and constraint rows within 1e-4 (K, rad, rad/s, V): a tenth of the
# violation the controller accepts (ControllerSettings.feasibility_tolerance). Measured on bench_mpc_step's loop
# (careful motion, 140 / 94 °C): the first current within 3.7e-5 / 7.6e-3 A of IPOPT's (tol 1e-8), costs within
# 8e-12 / 1.4e-4 (relative); with careful motion's rows hard, 1.4 / 3.1 backward passes per re-solve against
# 3.1 / 5.2 at 1e-6 / 1e-6.
MPC_TOLERANCES = {"tolerance": 1e-5, "constraint_tolerance": 1e-4}


def mpc_ddp_settings(max_iterations: int) -> DDPSettings:
    """Full-second-order DDP (the R(T) i^2 curvature is in the dynamics), the solver's default schedule (not
    the lift's tuned one: its pivot jump made re-solves near infeasibility fail more often in the robustness
    sweep) with the nonmonotone Armijo test over :data:`MPC_NONMONOTONE_MEMORY` iterates, the stopping rule of
    :data:`MPC_TOLERANCES`, capped at ``max_iterations`` per period."""
    return DDPSettings(full_second_order=True, max_iterations=max_iterations,
                       nonmonotone_memory=MPC_NONMONOTONE_MEMORY, **MPC_TOLERANCES)


# The line search accepts a full step that raises the merit a little after a decrease (DDPSettings.nonmonotone_memory,
# as the lift's searches). Measured on the loop's oracle row (tests/test_loop.py, 84 °C): monotone, the start's
# cold probes of 11.4-12.6 s stopped at the 50-iteration cap without a verdict (11.3 s planned) and a re-solve at
# t = 12.5 s ended on a failed line search, which cut the hold to 10.8 s (margin 2.08 K); over 3 iterates the
# start plans 11.6 s, held to the end (0.59 K).
MPC_NONMONOTONE_MEMORY = 3
# RecedingHorizonController.reachable_limit: checked when the estimate is within this of the hard winding limit,
# raised to the warm start's winding plus this margin (a tenth of the accepted violation, feasibility_tolerance).
REACHABLE_CHECK_C = 0.1
REACHABLE_MARGIN_C = 1e-4


def shifted_warm_start(result: SolverResult, problem: OptimalControlProblem, shift: int = 1,
                       penalty_max: float = np.inf) -> WarmStart:
    """``result`` shifted by ``shift`` knots (:meth:`WarmStart.from_result`) for the next window: the multipliers
    of the rows of :data:`FREE_AT_PRESENT` at knot 0 are zero (inactive there: a multiplier carried from knot 1
    would cost a multiplier update to clear), the AL penalty is capped at ``penalty_max`` (a penalty grown near
    infeasibility would leave the next problems ill-conditioned)."""
    warm = WarmStart.from_result(result, shift=shift)
    multipliers = dict(warm.multipliers)
    if multipliers.get("constraints") is not None:
        lam = np.array(multipliers["constraints"], dtype=float)
        lam[0, np.isin(constraint_rows(problem)[0], FREE_AT_PRESENT)] = 0.0
        multipliers["constraints"] = lam
    if "penalty" in multipliers:
        multipliers["penalty"] = np.minimum(multipliers["penalty"], penalty_max)
    return WarmStart(warm.xs, warm.us, multipliers)


def mpc_solver(lp: LiftProblem, settings: MPCSettings):
    """The receding-horizon DDP of :func:`mpc_ddp_settings` on ``lp``."""
    return make_solver(lp, "ddp", mpc_ddp_settings(settings.controller.max_iterations))


class RecedingHorizonController:
    """Plans the lift task of ``settings`` (hold ``settings.scenario.hold_s``) in a window of
    ``lp.problem.horizon`` knots."""

    def __init__(self, lp: LiftProblem, settings: MPCSettings, solver=None):
        self.lp, self.settings = lp, settings
        self.solver = solver if solver is not None else mpc_solver(lp, settings)
        dt = lp.settings.dt_s
        self.lift_knots = lp.settings.knots()["lift"]
        self.hold_knots = int(round(settings.scenario.hold_s / dt))
        fits = self.hold_knots <= lp.hold_knots[1] - lp.hold_knots[0]
        task_settings = dataclasses.replace(lp.settings, hold_s=settings.scenario.hold_s)
        self.task = lp if fits else build_lift_problem(task_settings, lp.model)
        knots = lp.settings.knots()
        self.task_knots = knots["lift"] + self.hold_knots + knots["lower"] + knots["settle"]
        self.k = 0
        self.plan: SolverResult | None = None
        self.plan_age = 0
        self.ambient_c: float | None = None   # the room the planner assumes (None: the model's)
        self.tightening_c = 0.0                # K added to every thermal node of the planning state
        self._thermal = np.arange(2 * lp.model.nu, lp.model.nx)
        self._winding = lp.model.node_indices("winding")
        self._ode = lp.model.ode
        self.robust = RobustHold(self) if settings.controller.robust_uncertainty > 0 else None

    @property
    def hold_s(self) -> float:
        return self.hold_knots * self.lp.settings.dt_s

    def window(self, k: int | None = None) -> np.ndarray:
        """Per-knot parameters of the window starting at knot ``k`` (default: now), last task row held, the
        lowering's reserve applied (:meth:`reserve_lowering`)."""
        k = self.k if k is None else k
        task = self.task.with_hold(self.hold_s).params
        n = self.lp.problem.horizon + 1
        rows = task[k:k + n]
        layout = self.lp.problem.parameters
        window = free_present(np.vstack([rows, np.repeat(task[-1:], n - rows.shape[0], axis=0)]), layout)
        if self.ambient_c is not None:
            layout.assign(window, "ambient_c", self.ambient_c)
        return self.reserve_lowering(window, self.lift_knots + self.hold_knots - k)

    def reserve_lowering(self, params: np.ndarray, lowering: int) -> np.ndarray:
        """``params`` with the winding limit lowered by ``lowering_reserve_c`` from knot ``lowering`` (the
        lowering's first knot) on, while the lowering lies ahead (``lowering`` > 0), in place."""
        reserve = self.settings.controller.lowering_reserve_c
        if reserve > 0 and lowering > 0:
            params[lowering:, self.lp.problem.parameters.slice("limit_c")] -= reserve
        return params

    def planning_state(self, x_est: np.ndarray) -> np.ndarray:
        """The state the planner starts from: the estimate with every thermal node raised by ``tightening_c``."""
        x = np.array(x_est, dtype=float)
        x[self._thermal] += self.tightening_c
        return x

    def _acceptable(self, result: SolverResult, deadline: bool = True) -> bool:
        """Finite, feasible and (re-solves only: the cold plan is made before moving) in time."""
        tolerance = self.settings.controller.feasibility_tolerance
        return bool(np.isfinite(result.cost) and result.max_constraint_violation <= tolerance
                    and not (deadline and self._late(result.solve_s)))

    def _late(self, solve_s: float) -> bool:
        return self.settings.controller.max_solve_s is not None and solve_s > self.settings.controller.max_solve_s

    def start(self, x_est: np.ndarray) -> ControlStep:
        """Cold plan at knot 0. When the requested hold is infeasible from the estimated state, it is cut
        to what the window holds and the longest feasible hold is searched (complete optimisations, as
        plan_lift does)."""
        lp = dataclasses.replace(self.lp, x0=self.planning_state(x_est), params=self.window(0))
        result = self.solver.solve(lp.x0, lp.params, initial_guess(lp))
        total, first_s, iterations, solves, status = result.solve_s, result.solve_s, result.iterations, 1, "cold"
        room = self.lp.hold_knots[1] - self.lp.hold_knots[0]
        if not self._acceptable(result, False) and self.hold_knots > room:
            self.hold_knots, self.task, status = room, self.lp, "hold_shortened"
            result = self.solver.solve(lp.x0, self.window(0), initial_guess(lp.with_hold(self.hold_s)))
            total, iterations, solves = total + result.solve_s, iterations + result.iterations, solves + 1
        if not self._acceptable(result, False) and self.hold_knots > 0:
            ladder = SolverLadder(lp.problem, self.solver)

            def probe(task, warm):  # DDP and its restarts: a real-time loop does not fall back to IPOPT
                params = self.reserve_lowering(free_present(task.params, task.problem.parameters), task.hold_knots[1])
                task = dataclasses.replace(task, params=params)
                return ladder.solve(task, warm or initial_guess(task), reference=False)
            estimate = time_to_limit_s(lp.model, lp.x0, lp.settings.goal_rad, lp.settings.limit_c)
            search = longest_feasible_hold(lp.with_hold(self.hold_s), probe, int(estimate / lp.settings.dt_s),
                                           stop_without_verdict=False)
            solves, total = solves + len(search.results), total + search.solve_s
            if search.knots >= 0 and search.failed is None:
                best_lp, best = search.best[0], search.best[1].result
                log.info("requested hold %.1f s infeasible from the estimated state; planning %.1f s",
                         self.hold_s, best_lp.hold_s)
                self.hold_knots, result, status = best_lp.hold_knots[1] - best_lp.hold_knots[0], best, "hold_shortened"
                iterations += best.iterations
        events = ("hold_shortened",) if status == "hold_shortened" else ()
        if self.robust is not None and self._acceptable(result, False):  # the hold the set allows
            result, more, event = self.robust.review(self, lp.x0, result, extend=False)
            solves, total = solves + len(more), total + sum(r.solve_s for r in more)
            iterations, events = iterations + sum(r.iterations for r in more), events + ((event,) if event else ())
        if not self._acceptable(result, False):
            log.warning("no feasible initial plan (%s); applying the best iterate", result.reason or result.status)
            status, events = "fallback", events + ("no_feasible_plan",)
        self.plan, self.plan_age, self.k = result, 0, 0
        return ControlStep(current_a=self._clip(result.us[0]), status=status, solver_status=result.status,
                           solve_s=total, first_solve_s=first_s, iterations=iterations, solves=solves,
                           hold_s=self.hold_s, cost=result.cost, events=events)

    def step(self, x_est: np.ndarray) -> ControlStep:
        """Advance one knot and re-solve from ``x_est`` (raised by ``tightening_c``), warm-started from the
        shifted plan; a failed or late solve falls back to the previous plan with feedback (derated)."""
        if self.plan is None:
            raise RuntimeError("call start() before step()")
        x_est = self.planning_state(x_est)
        self.k += 1
        age = self.plan_age + 1
        warm = self.warm_start(age)
        result = self.solver.solve(x_est, self.reachable_limit(self.window(), x_est, warm), warm)
        results, status = [result], "solved"
        while (not self._acceptable(result) and not self._late(sum(r.solve_s for r in results))
               and len(results) <= self.settings.controller.max_retries and self._shorten()):
            result = self.solver.solve(x_est, self.reachable_limit(self.window(), x_est, warm), warm)
            results.append(result)
            status = "hold_shortened"
        t = self.k * self.lp.settings.dt_s
        events = ["hold_shortened"] if status == "hold_shortened" else []
        if self._acceptable(result) and not self._late(sum(r.solve_s for r in results)):
            if self.robust is not None and self.robust.due(self.k):  # the set's review (mpc.robust)
                result, more, event = self.robust.review(self, x_est, result)
                results, events = results + more, events + ([event] if event else [])
            self.plan, self.plan_age = result, 0
            current = result.us[0]
            if status == "hold_shortened":
                log.info("t = %.1f s: hold shortened to %.1f s", t, self.hold_s)
        else:
            self.plan_age, status = age, "fallback"
            late = self._late(sum(r.solve_s for r in results))
            events += ["solve_timeout" if late else "solve_failed", "fallback_plan"]
            current, derated = self._fallback(x_est, age)
            if derated:
                events.append("derate")
            log.warning("t = %.1f s: re-solve %s (%s, violation %.2e, %.1f ms); previous plan's control with "
                        "feedback%s", t, "too late" if late else "failed", result.reason or result.status,
                        result.max_constraint_violation, 1e3 * sum(r.solve_s for r in results),
                        ", derated to the no-heating current" if derated else "")
        if status == "fallback" or self.k >= self.lift_knots + self.hold_knots:  # the lift may swing: not braked
            current, braked = self.range_guard(x_est, current)
            events += ["range_brake"] if braked else []
        current, limited = self.voltage_guard(x_est, current)
        events += ["voltage_limit"] if limited else []
        return ControlStep(current_a=self._clip(current), status=status, solver_status=result.status,
                           solve_s=sum(r.solve_s for r in results), first_solve_s=results[0].solve_s,
                           iterations=sum(r.iterations for r in results), solves=len(results), hold_s=self.hold_s,
                           cost=result.cost, events=tuple(events))

    def reachable_limit(self, params: np.ndarray, x0: np.ndarray, warm: WarmStart) -> np.ndarray:
        """The window ``params`` with the winding limit raised, knot by knot, to the winding the warm start's
        currents reach from ``x0``, at most ``x0``'s own (never planned hotter than now), plus
        :data:`REACHABLE_MARGIN_C`, where that is over the hard limit: a winding estimated over the limit cannot
        cool under it within a period or a few, whatever the current, so the hard row there would make every
        re-solve infeasible and hand the period to the fallback. The back-off band's cost still pulls the winding
        down. Unchanged (no rollout) while the estimate is more than :data:`REACHABLE_CHECK_C` under the hard
        limit. Measured (nominal sweep, seed 3681211716): without the cap at ``x0``'s winding the plans braked
        on heat the fallback's derating would not allow (margin 0.49 K against 0.83 K)."""
        layout = self.lp.problem.parameters
        cols = layout.slice("limit_c")
        hard = params[1:, cols] + self._backoff_c
        if np.max(np.asarray(x0)[self._winding]) < np.min(hard) - REACHABLE_CHECK_C:
            return params
        xs = np.asarray(self._rollout(x0, warm.us.T, params[:-1].T)).T   # x_1 .. x_N
        now = np.asarray(x0)[self._winding]
        reached = np.minimum(xs[:, self._winding], now) - self._backoff_c + REACHABLE_MARGIN_C
        out = np.array(params, dtype=float)
        out[1:, cols] = np.maximum(out[1:, cols], reached)
        return out

    @functools.cached_property
    def _rollout(self) -> ca.Function:
        return self.lp.problem.functions.step.mapaccum(self.lp.problem.horizon)

    @property
    def _backoff_c(self) -> float:
        """K between the window's limit_c and the hard winding row (:func:`planner_ocp`: soft back-off band)."""
        return self.settings.scenario.backoff_c if self.settings.controller.backoff_weight_per_k2 > 0 else 0.0

    def warm_start(self, shift: int = 1) -> WarmStart:
        """The plan shifted by ``shift`` knots with its multipliers (:func:`shifted_warm_start`)."""
        return shifted_warm_start(self.plan, self.lp.problem, min(shift, self.lp.problem.horizon),
                                  self.settings.controller.warm_penalty_max)

    def _shorten(self) -> bool:
        """Move the start of the lowering earlier by ``hold_step_s`` (never into the past)."""
        step = max(1, int(round(self.settings.controller.hold_step_s / self.lp.settings.dt_s)))
        shortest = max(0, self.k - self.lift_knots)
        new = max(shortest, self.hold_knots - step)
        if new >= self.hold_knots:
            return False
        self.hold_knots = new
        return True

    def _fallback(self, x_est: np.ndarray, age: int) -> tuple[np.ndarray, bool]:
        """The previous plan's control ``age`` knots on with its feedback; derated (capped at the no-heating
        current) once the winding of ``x_est`` is at the planning limit or the plan has run out."""
        plan = self.plan
        j = min(age, plan.us.shape[0] - 1)
        u = plan.us[j].copy()
        if plan.K is not None:
            u = u + plan.K[j] @ (np.asarray(x_est, float) - plan.xs[j])
        hot = np.max(np.asarray(x_est)[self._winding]) >= self.lp.settings.limit_c - 1e-6
        if not (self.settings.controller.derate and (hot or age >= plan.us.shape[0])):
            return u, False
        cap = self.no_heating_current_a(x_est)
        capped = np.clip(u, -cap, cap)
        return capped, bool(np.any(capped != u))

    def range_guard(self, x: np.ndarray, current: np.ndarray) -> tuple[np.ndarray, bool]:
        """``current`` moved, per joint, into the interval that keeps the next state inside the lift's
        ``stop_approach`` envelope (the speed toward a stop at most ``stop_speed_rad_s + stop_slope_per_s *
        distance``; :func:`thermo_ddp.tasks.constraints.toward_stops`), and whether it was moved: a brake on every
        period's current (the plan's rows are soft, the fallback's current stale), which overrides the derating (a
        load that falls through the joint's stop is not an option; the winding's back-off band and the planning
        state's tightening are the heat it spends). See :meth:`_guard`."""
        return self._guard(x, current, self._envelope)

    def voltage_guard(self, x: np.ndarray, current: np.ndarray) -> tuple[np.ndarray, bool]:
        """``current`` moved, per joint, into the interval that keeps the motor voltage within the bus voltage over
        the whole period (the lift's ``bus_voltage`` rows at its start and its end under the held current,
        :func:`thermo_ddp.tasks.constraints.bus_voltage`), and whether it was moved: the drive cannot apply more,
        so it has the last word, over the range guard's brake (a fallback's stale current, or a plan's first
        current from an estimate the plan did not see). See :meth:`_guard`."""
        return self._guard(x, current, self._bus_envelope, about_current=True)

    def _guard(self, x: np.ndarray, current: np.ndarray, rows, about_current: bool = False) -> tuple[np.ndarray, bool]:
        """``current`` clipped, per joint, to the interval where its ``rows(x, u, params)`` (per joint, <= 0 inside)
        hold. The rows are affine in each joint's own current over one step (evaluated at 0 and 1 A, or, with
        ``about_current``, at ``current`` and 1 A more; the window's first row); a joint whose rows cannot all be
        met gets the current of its most violated row's bound."""
        x = np.asarray(x, float)
        params = self.window()[0]
        n = self.lp.model.nu
        out = np.array(current, dtype=float).reshape(-1)
        at = self._clip(out) if about_current else np.zeros(n)
        base = rows(x, at, params)
        for j in range(n):
            one = np.zeros(n)
            one[j] = 1.0
            slope = rows(x, at + one, params)[j] - base[j]
            bounds = at[j] - base[j] / np.where(slope != 0, slope, np.nan)
            upper = bounds[slope > 0].min(initial=np.inf)
            lower = bounds[slope < 0].max(initial=-np.inf)
            if lower <= upper:
                out[j] = np.clip(out[j], lower, upper)
            else:   # no current meets every row: the bound of the row most violated at the present current
                worst = int(np.argmax(base[j] + slope * (out[j] - at[j])))
                out[j] = bounds[worst] if np.isfinite(bounds[worst]) else out[j]
        out = self._clip(out)
        return out, bool(np.any(np.abs(out - np.asarray(current, float).reshape(-1)) > 1e-9))

    def _envelope(self, x: np.ndarray, u: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Per joint, the ``stop_approach`` rows (<= 0 inside) of the state one step after ``x`` under ``u``."""
        x_next = np.array(self.lp.problem.functions.step(x, u, params)).ravel()
        return np.array(self._stop_rows(x_next)).reshape(self.lp.model.nu, -1)

    def _bus_envelope(self, x: np.ndarray, u: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Per joint, the ``bus_voltage`` rows (<= 0 inside) over the period from ``x`` under ``u``."""
        return np.array(self._bus_rows(x, u, params)).reshape(self.lp.model.nu, -1)

    @functools.cached_property
    def _stop_rows(self) -> ca.Function:
        model, s = self.lp.model, self.lp.settings
        x = ca.SX.sym("x", model.nx)
        rows = [toward_stops(model, joint, x, s.stop_speed_rad_s, s.stop_slope_per_s) for joint in model.joints]
        return ca.Function("stop_rows", [x], [ca.vertcat(*rows)])

    @functools.cached_property
    def _bus_rows(self) -> ca.Function:
        model, pr = self.lp.model, self.lp.problem
        x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("p", pr.n_params)
        x_next = pr.functions.step(x, u, p)
        rows = [bus_voltage(model, joint, x, u[j], x_next) for j, joint in enumerate(model.joints)]
        return ca.Function("bus_rows", [x, u, p], [ca.vertcat(*rows)])

    def no_heating_current_a(self, x: np.ndarray) -> np.ndarray:
        """Per joint, the ``|current|`` at which the winding's temperature stops rising at state ``x`` (model ODE:
        dT_w/dt(i) = a + b i^2, from the rates at 0 and 1 A with the other joints' currents at 0)."""
        amb = self.lp.model.ambient_c if self.ambient_c is None else self.ambient_c
        n = self.lp.model.nu
        rate0 = np.array(self._ode(x, np.zeros(n), amb)).ravel()[self._winding]
        cap = np.zeros(n)
        for k in range(n):
            one = np.zeros(n)
            one[k] = 1.0
            b = np.array(self._ode(x, one, amb)).ravel()[self._winding[k]] - rate0[k]
            cap[k] = np.sqrt(max(0.0, -rate0[k]) / b) if b > 0 else 0.0
        return cap

    def _clip(self, current) -> np.ndarray:
        pr = self.lp.problem
        return np.clip(np.asarray(current, float).reshape(-1), pr.u_lb, pr.u_ub)
