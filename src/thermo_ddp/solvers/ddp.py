"""Constrained multiple-shooting DDP / iLQR with an augmented Lagrangian.

Method (each part stated, as logged):
- Local model: Gauss-Newton iLQR (cost Hessian J'J, no dynamics curvature) by default;
  ``full_second_order`` uses exact cost Hessians and the dynamics tensor contracted with the
  value gradient (full DDP).
- Multiple shooting with gaps (feasibility-driven, as crocoddyl FDDP, Mastalli et al. ICRA
  2020): the backward pass uses Vx' + Vxx' c with the gap c = f(x_k,u_k) - x_{k+1}; the
  forward pass closes a fraction alpha of every gap, so an infeasible warm start is accepted
  and a full step yields a dynamically feasible trajectory. x_0 is set to x0 before the first
  iteration.
- Control box: box-QP per knot by projected Newton (see _riccati), forward pass clamps.
- Inequalities g <= 0 (stage and terminal): PHR augmented Lagrangian (as ALTRO, Howell et al.
  IROS 2019): inner DDP iterations on cost + sum (max(0, lam + rho g)^2 - lam^2) / (2 rho);
  when the inner stationarity is below the current inner tolerance (or after
  ``inner_max_iterations`` inner iterations), multipliers are updated lam <- max(0, lam + rho g)
  and rho grows by ``penalty_factor`` when the violation did not fall to a quarter of its value
  at the previous update (at the first update of a cold start: of the initial guess's).
- Line search: backtracking (factor 1/2) on the merit phi = cost + AL terms + mu |gaps|_1,
  Armijo test against the quadratic model alpha d1 + alpha^2 d2 / 2 - alpha mu |gaps|_1;
  mu grows as needed to make the step a descent direction (Nocedal & Wright eq. 18.36).
  A failed line search whose model predicts no decrease above rounding (|d1| <= ``decrement_tolerance``
  * (1 + |cost|)) ends the inner loop: the multipliers are updated at the next pass (measured: the
  stalled probes of the lift's longest-hold search otherwise spent 14 forward passes per retry, raising
  the regularisation up to reg_max). Passes and updates are counted in ``SolverResult.info``
  (:data:`PASS_COUNTS`).
- Regularisation: rho_reg I added to Quu; multiplied by ``reg_factor`` on a failed line search,
  and in Gauss-Newton mode also after a step shorter than 1/2 (Levenberg-Marquardt-like damping
  of a too optimistic model); on a failed backward pass multiplied by ``reg_factor`` or, with
  ``pivot_jump``, raised to at least rho_reg - 2p (p the non-positive pivot at the first failing
  knot, the last in time; not beyond ``reg_max``), so that knot's pivot becomes >= |p| in one
  retry instead of climbing from ``reg_min``; divided by ``reg_decrease`` after a full step.
  Defaults are the conservative schedule (both x10, no jump); a problem may tune them (the lift
  does: ``thermo_ddp.tasks.lift.DDP_OPTIONS``). Measured: a slow decrease (sqrt 10) with the
  Levenberg-Marquardt damping stalls Gauss-Newton on the multi-joint hold (300 iterations against
  32), and the jump made receding-horizon re-solves near infeasibility fail more often.
- Stopping: converged when the projected control gradient |Qu|_inf <= ``tolerance`` (or, with
  no regularisation, the predicted decrease |d1| <= ``decrement_tolerance`` * (1 + |cost|): no
  progress is possible above rounding), the largest gap <= ``gap_tolerance`` and
  |max(g, -lam/rho)|_inf <= ``constraint_tolerance``. After a full step (gaps closed) from an
  iterate with |Qu|_inf <= sqrt(``tolerance``), |Qu|_inf of the new iterate is first measured by
  a first-order pass (Qu0 = lu + B'a, a = lx + A'a' + K'Qu0 with the last pass's gains K; zero
  exactly where the full pass's Qu0 is): if within tolerance the solve stops there (K, k are then
  those of that last pass), otherwise a full backward pass follows as usual.
- The first backward pass of a solve also evaluates the initial guess (cost, constraints, gaps)
  in the same sweep over the knots.
- Warm start (MPC): trajectories, constraint multipliers and penalty of a previous result
  (WarmStart.from_result shifts them); with multipliers the inner tolerance starts at
  ``tolerance``. Measured: Gauss-Newton converges slowly when a heating term R(T) i^2 is
  constrained (its curvature is in the dynamics); use ``full_second_order=True`` there.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Mapping

import numpy as np

from .._config import require, settings_from_mapping
from ..errors import InputError
from ..ocp import OptimalControlProblem
from ._backends import Layout, make_backend
from .kkt import KKT_KEYS, KKTEvaluator, constraint_rows
from .result import HISTORY_KEYS, STATUSES, SolverResult, WarmStart, constraint_violation

log = logging.getLogger(__name__)

BACKENDS = ("codegen", "casadi", "numpy")
# The work of a solve, in SolverResult.info: backward (Riccati) passes, forward (rollout) passes of the line
# search, first-order gradient passes, augmented-Lagrangian multiplier updates.
PASS_COUNTS = ("backward_passes", "forward_passes", "gradient_passes", "multiplier_updates")
_SRC = "DDPSettings"


@dataclasses.dataclass(frozen=True)
class DDPSettings:
    """Options of DDPSolver (frozen, validated; unknown keys in from_mapping raise)."""

    max_iterations: int = 200
    tolerance: float = 1e-6                 # projected |Qu|_inf at convergence
    gap_tolerance: float = 1e-8             # largest dynamics gap at convergence
    constraint_tolerance: float = 1e-6      # |max(g, -lam/rho)|_inf at convergence
    decrement_tolerance: float = 1e-12      # or: predicted decrease |d1| <= this * (1 + |cost|)
    inner_tolerance_init: float = 1e-2      # first inner tolerance of the AL loop (cold start)
    inner_tolerance_factor: float = 0.1     # inner tolerance shrink per converged inner loop
    inner_max_iterations: int = 25          # multiplier update after this many inner iterations at most
    full_second_order: bool = False         # full DDP (True) or Gauss-Newton iLQR (False)
    reg_init: float = 0.0                   # Quu regularisation at the start of a solve
    reg_min: float = 1e-9                   # smallest non-zero regularisation
    reg_max: float = 1e9
    reg_factor: float = 10.0                # increase on a failed pass or line search
    reg_decrease: float = 10.0              # decrease after a full step
    pivot_jump: bool = False                # after a failed pass: reg to at least reg - 2 * (failed pivot)
    line_search_factor: float = 0.5
    line_search_min_step: float = 1e-4
    armijo: float = 1e-4                    # fraction of the model decrease required
    penalty_init: float = 100.0             # AL penalty rho at a cold start
    penalty_factor: float = 10.0
    penalty_max: float = 1e8
    infeasibility_growth: float = 1e3       # "infeasible" if the violation has not halved while rho grew this much
    box_iterations: int = 2                 # projected-Newton passes per knot (nu > 1)
    backend: str = "codegen"                # "codegen" (C via gcc), "casadi" (VM) or "numpy"
    compiler_flags: tuple = ("-O2", "-march=native")  # gcc; big generated files at -O1/-O0 (see codegen)

    def __post_init__(self):
        ints = ("max_iterations", "box_iterations", "inner_max_iterations")
        for name in ints:
            v = getattr(self, name)
            require(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0, _SRC, name, v,
                    "expected an integer >= 0")
        positive = ("tolerance", "decrement_tolerance", "gap_tolerance", "constraint_tolerance",
                    "inner_tolerance_init", "reg_max", "reg_factor", "reg_decrease", "penalty_init",
                    "penalty_factor", "penalty_max", "line_search_min_step", "infeasibility_growth")
        for name in positive:
            v = getattr(self, name)
            require(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0,
                    _SRC, name, v, "expected a finite number > 0")
        for name in ("reg_init", "reg_min"):
            v = getattr(self, name)
            require(isinstance(v, (int, float)) and np.isfinite(v) and v >= 0, _SRC, name, v, "expected a number >= 0")
        for name in ("line_search_factor", "armijo", "inner_tolerance_factor"):
            v = getattr(self, name)
            require(isinstance(v, (int, float)) and 0 < v < 1, _SRC, name, v, "expected a number in (0, 1)")
        require(self.reg_factor > 1 and self.reg_decrease > 1 and self.penalty_factor >= 1, _SRC,
                "reg_factor/reg_decrease/penalty_factor", (self.reg_factor, self.reg_decrease, self.penalty_factor),
                "expected reg_factor > 1, reg_decrease > 1 and penalty_factor >= 1")
        require(self.reg_init <= self.reg_max and self.reg_min <= self.reg_max, _SRC, "reg_init/reg_min",
                (self.reg_init, self.reg_min), "expected reg_init <= reg_max and reg_min <= reg_max")
        require(self.penalty_init <= self.penalty_max, _SRC, "penalty_init", self.penalty_init,
                "expected <= penalty_max")
        for name in ("full_second_order", "pivot_jump"):
            require(isinstance(getattr(self, name), bool), _SRC, name, getattr(self, name), "expected True or False")
        require(self.backend in BACKENDS, _SRC, "backend", self.backend, f"expected one of {', '.join(BACKENDS)}")
        require(isinstance(self.compiler_flags, (tuple, list)) and all(isinstance(f, str) for f in self.compiler_flags),
                _SRC, "compiler_flags", self.compiler_flags, "expected a tuple of strings")
        object.__setattr__(self, "compiler_flags", tuple(self.compiler_flags))

    @classmethod
    def from_mapping(cls, values: Mapping, source: str = _SRC) -> "DDPSettings":
        return settings_from_mapping(cls, values, source)


@dataclasses.dataclass
class _Iterate:
    """The accepted trajectory and its evaluations (solver workspace, never returned)."""

    X: np.ndarray
    U: np.ndarray
    J: float
    G: np.ndarray
    GN: np.ndarray
    C: np.ndarray


class DDPSolver:
    """Build once (all code generation and compilation here), then ``solve`` many times."""

    def __init__(self, problem: OptimalControlProblem, settings: DDPSettings | Mapping | None = None):
        if not isinstance(problem, OptimalControlProblem):
            raise InputError("DDPSolver", "problem", type(problem).__name__, "expected an OptimalControlProblem")
        if settings is None:
            settings = DDPSettings()
        elif isinstance(settings, Mapping):
            settings = DDPSettings.from_mapping(settings)
        elif not isinstance(settings, DDPSettings):
            raise InputError("DDPSolver", "settings", type(settings).__name__, "expected DDPSettings or a mapping")
        self.problem, self.settings = problem, settings
        self.layout = Layout(problem.nx, problem.nu)
        self._ng, self._ngN = problem.n_constraints, problem.n_terminal_constraints  # sizes, computed once
        start = time.perf_counter()
        self.backend = make_backend(problem, settings, self.layout)
        self.kkt, self._rows = KKTEvaluator(problem), constraint_rows(problem)
        self.build_s = time.perf_counter() - start
        log.info("DDP built for %s (nx=%d nu=%d N=%d) in %.2f s: backend %s, %s, multiple shooting (gaps), "
                 "box-QP by projected Newton, PHR augmented Lagrangian for %d+%d inequalities, Armijo backtracking "
                 "on cost + AL + mu|gaps|_1, Quu regularisation x%g, stop at |Qu| <= %g, gaps <= %g, "
                 "constraints <= %g", problem.name, problem.nx, problem.nu, problem.horizon, self.build_s,
                 self.backend.name, "full DDP" if settings.full_second_order else "Gauss-Newton iLQR",
                 problem.n_constraints, problem.n_terminal_constraints, settings.reg_factor, settings.tolerance,
                 settings.gap_tolerance, settings.constraint_tolerance)

    # -- public ---------------------------------------------------------------------------------
    def solve(self, x0, params=None, warm_start: WarmStart | SolverResult | None = None) -> SolverResult:
        """Solve from initial state x0 with per-knot params (N+1, np) and an optional warm start."""
        pr = self.problem
        x0 = pr.check_x0(x0, "DDPSolver.solve")
        P = np.ascontiguousarray(pr.check_params(params, "DDPSolver.solve"))
        X, U, lam, lamN, rho, cold = self._initial_guess(x0, warm_start)
        start = time.perf_counter()
        return self._run(X, U, P, lam, lamN, rho, cold, start)

    # -- internals ------------------------------------------------------------------------------
    def _initial_guess(self, x0, warm):
        pr, s = self.problem, self.settings
        N, ng, ngN = pr.horizon, self._ng, self._ngN
        lam, lamN, rho, cold = np.zeros((N, ng)), np.zeros(ngN), s.penalty_init, True
        if warm is None:
            xs, us = np.tile(x0, (N + 1, 1)), np.zeros((N, pr.nu))
        else:
            if isinstance(warm, SolverResult):
                warm = WarmStart(warm.xs, warm.us, warm.multipliers)
            if not isinstance(warm, WarmStart):
                raise InputError("DDPSolver.solve", "warm_start", type(warm).__name__,
                                 "expected a WarmStart or SolverResult")
            xs, us = pr.check_trajectory(warm.xs, warm.us)
            m = warm.multipliers
            if m.get("constraints") is not None and np.shape(m["constraints"]) == (N, ng):
                lam, cold = np.maximum(np.asarray(m["constraints"], float), 0.0), False
            if m.get("terminal_constraints") is not None and np.shape(m["terminal_constraints"]) == (ngN,):
                lamN = np.maximum(np.asarray(m["terminal_constraints"], float), 0.0)
            if m.get("penalty") is not None:
                rho = float(np.clip(m["penalty"], s.penalty_init, s.penalty_max))
        X = np.array(xs, dtype=float)
        X[0] = x0
        U = np.ascontiguousarray(np.clip(us, pr.u_lb, pr.u_ub))
        return X, U, lam, lamN, rho, cold

    def _al(self, G, GN, lam, lamN, rho) -> float:
        """Augmented-Lagrangian terms sum (max(0, lam + rho g)^2 - lam^2) / (2 rho)."""
        return float((np.sum(np.maximum(0.0, lam + rho * G) ** 2 - lam ** 2)
                      + np.sum(np.maximum(0.0, lamN + rho * GN) ** 2 - lamN ** 2)) / (2 * rho))

    @staticmethod
    def _kkt_constraint(G, GN, lam, lamN, rho) -> float:
        vals = [np.max(np.abs(np.maximum(G, -lam / rho)))] if G.size else [0.0]
        if GN.size:
            vals.append(np.max(np.abs(np.maximum(GN, -lamN / rho))))
        return float(max(vals))

    def _run(self, X, U, P, lam, lamN, rho, cold, start) -> SolverResult:
        s, pr, be = self.settings, self.problem, self.backend
        has_constraints = self._ng + self._ngN > 0
        evaluation, first = be.evaluate_backward(X, U, P, lam, lamN, rho, s.reg_init)  # the first pass, fused
        it_ = _Iterate(X, U, *evaluation)
        if not all(np.all(np.isfinite(v)) for v in (it_.J, it_.G, it_.GN, it_.C)):
            return self._result(it_, P, lam, lamN, rho, None, "numerical_error",
                                "the model gives non-finite values at the initial guess", 0, start,
                                {k: [] for k in HISTORY_KEYS})
        reg, mu_gap, omega = s.reg_init, 0.0, max(s.inner_tolerance_init if cold else s.tolerance, s.tolerance)
        viol_prev = self._violation(it_) if cold else np.inf  # a cold start's first loop must cut it to a quarter
        al_log: list[tuple[float, float]] = []  # (penalty, violation) at each multiplier update
        hist = {k: [] for k in HISTORY_KEYS}
        status, message = "max_iterations", f"no convergence in {s.max_iterations} iterations"
        policy = values = costates = None
        iteration = inner = 0
        counts = dict.fromkeys(PASS_COUNTS, 0)  # the work done: passes of each kind, multiplier updates
        while iteration < s.max_iterations and counts["backward_passes"] < 4 * s.max_iterations + 20:
            counts["backward_passes"] += 1
            policy_try, summary, values_try = first or be.backward(it_.X, it_.U, P, lam, lamN, it_.C, rho, reg)
            first = None
            d1, d2, stat, pivot = summary
            if not (pivot > 0 and np.all(np.isfinite(summary))):
                reg = self._increase(reg, policy_try)
                log.debug("iteration %d: backward pass failed (pivot %.2e), reg -> %.1e", iteration, pivot, reg)
                if reg > s.reg_max:
                    status, message = "regularisation_failed", "Quu not positive definite up to reg_max"
                    break
                continue
            policy, values = policy_try, values_try
            gap = float(np.max(np.abs(it_.C))) if it_.C.size else 0.0
            kkt_c = self._kkt_constraint(it_.G, it_.GN, lam, lamN, rho)
            flat = abs(d1) <= s.decrement_tolerance * (1.0 + abs(it_.J)) and reg <= s.reg_min
            inner_done = (stat <= omega or flat) and gap <= s.gap_tolerance
            if inner_done or (has_constraints and inner >= s.inner_max_iterations and kkt_c > s.constraint_tolerance):
                if inner_done and (stat <= s.tolerance or flat) and kkt_c <= s.constraint_tolerance:
                    status = "converged"
                    message = ("predicted decrease below rounding" if stat > s.tolerance else "stationarity") + \
                        ", gaps and constraints within tolerance"
                    self._record(hist, it_, lam, lamN, rho, stat, gap, 0.0, reg, 0.0)
                    break
                if inner_done:
                    omega = max(s.tolerance, omega * s.inner_tolerance_factor)
                if has_constraints and kkt_c > s.constraint_tolerance:
                    inner = 0
                    al_log.append((rho, self._violation(it_)))
                    if self._stalled(al_log):
                        status = "infeasible"
                        message = (f"locally infeasible: the violation {al_log[-1][1]:.3g} did not halve while "
                                   f"the penalty grew {s.infeasibility_growth:g}x")
                        break
                    lam, lamN, rho, viol_prev = self._update_multipliers(it_, lam, lamN, rho, viol_prev)
                    counts["multiplier_updates"] += 1
                    continue
            alpha, trial, mu_gap, tries = self._line_search(it_, P, policy, d1, d2, lam, lamN, rho, mu_gap)
            counts["forward_passes"] += tries
            if trial is None:
                if has_constraints and abs(d1) <= s.decrement_tolerance * (1.0 + abs(it_.J)):
                    inner = s.inner_max_iterations  # no decrease left at this penalty: update the multipliers next
                reg = self._increase(reg)
                log.debug("iteration %d: line search failed, reg -> %.1e", iteration, reg)
                if reg > s.reg_max:
                    status, message = "line_search_failed", "no acceptable step up to reg_max"
                    break
                continue
            iteration, inner = iteration + 1, inner + 1
            step = alpha * float(np.max(np.abs(policy[:, : pr.nu])))
            it_ = trial
            if alpha == 1.0:
                reg = reg / s.reg_decrease if reg / s.reg_decrease >= s.reg_min else 0.0
            elif alpha < 0.5 and not s.full_second_order:  # Gauss-Newton model too optimistic: damp (LM-like)
                reg = self._increase(reg)
            self._record(hist, it_, lam, lamN, rho, stat, gap, step, reg, alpha)
            log.debug("iteration %d: cost %.6e stat %.2e gap %.2e alpha %.3g reg %.1e rho %.1e", iteration, it_.J,
                      stat, gap, alpha, reg, rho)
            if alpha == 1.0 and stat <= s.tolerance ** 0.5 and \
                    self._kkt_constraint(it_.G, it_.GN, lam, lamN, rho) <= s.constraint_tolerance:
                counts["gradient_passes"] += 1  # the step closed the gaps: a first-order pass may show convergence
                stat_new, a = be.gradient(it_.X, it_.U, P, lam, lamN, policy, rho)
                if stat_new <= s.tolerance:
                    status = "converged"
                    message = "stationarity (previous gains), gaps and constraints within tolerance"
                    self._record(hist, it_, lam, lamN, rho, stat_new, 0.0, 0.0, reg, 0.0)
                    costates = a
                    break
        lam_out = np.maximum(0.0, lam + rho * it_.G)
        lamN_out = np.maximum(0.0, lamN + rho * it_.GN)
        if costates is None and values is not None:
            costates = self.layout.costates(values)
        return self._result(it_, P, lam_out, lamN_out, rho, (policy, costates), status, message, iteration, start,
                            hist, counts, al_log)

    def _increase(self, reg: float, policy=None) -> float:
        """reg x reg_factor; after a failed backward pass (``policy``) at least reg - 2 p, with p the
        non-positive pivot of the first failed knot (the last in time): that knot's Quu then has pivot >= |p|."""
        s, lay = self.settings, self.layout
        reg_new = max(reg * s.reg_factor, s.reg_min)
        if policy is not None and s.pivot_jump:
            pivots = policy[:, lay.nu + lay.nu * lay.nx]
            failed = np.flatnonzero(~(pivots > 0))
            jump = reg - 2.0 * pivots[failed[-1]] if failed.size else -np.inf
            if np.isfinite(jump) and jump <= s.reg_max:  # beyond reg_max: climb instead, the pivot may be spurious
                reg_new = max(reg_new, jump)
        return reg_new

    @staticmethod
    def _violation(it_) -> float:
        return max(float(np.max(it_.G, initial=0.0)), float(np.max(it_.GN, initial=0.0)))

    def _stalled(self, al_log: list[tuple[float, float]]) -> bool:
        """True when, since the penalty was ``infeasibility_growth`` times smaller, the violation has
        not halved: more penalty no longer buys feasibility (a local infeasibility certificate)."""
        rho, viol = al_log[-1]
        earlier = [v for r, v in al_log if r * self.settings.infeasibility_growth <= rho]
        return bool(earlier) and viol > 0.5 * earlier[-1] and viol > 10 * self.settings.constraint_tolerance

    def _update_multipliers(self, it_, lam, lamN, rho, viol_prev):
        s = self.settings
        viol = self._violation(it_)
        lam = np.maximum(0.0, lam + rho * it_.G)
        lamN = np.maximum(0.0, lamN + rho * it_.GN)
        if viol > 0.25 * viol_prev:
            rho = min(rho * s.penalty_factor, s.penalty_max)
        log.debug("multiplier update: violation %.2e, rho %.1e", viol, rho)
        return lam, lamN, rho, viol

    def _line_search(self, it_, P, policy, d1, d2, lam, lamN, rho, mu_gap):
        """Backtracking on the merit; returns (alpha, accepted iterate or None, gap penalty, forward passes)."""
        s, be = self.settings, self.backend
        gap_l1 = float(np.sum(np.abs(it_.C)))
        if gap_l1 > 0:
            need = (d1 + 0.5 * max(d2, 0.0)) / (0.9 * gap_l1)
            mu_gap = max(mu_gap, need + 1e-8)
        merit0 = it_.J + self._al(it_.G, it_.GN, lam, lamN, rho) + mu_gap * gap_l1
        noise = 1e-13 * (1.0 + abs(merit0))
        alpha, tries = 1.0, 0
        while alpha >= s.line_search_min_step:
            tries += 1
            X, U, J, G, GN = be.forward(it_.X, it_.U, P, policy, it_.C, alpha)
            if np.isfinite(J) and np.all(np.isfinite(X)):
                merit = J + self._al(G, GN, lam, lamN, rho) + mu_gap * (1 - alpha) * gap_l1
                model = alpha * d1 + 0.5 * alpha ** 2 * d2 - alpha * mu_gap * gap_l1
                if merit - merit0 <= s.armijo * min(model, 0.0) + noise:
                    C = np.zeros_like(it_.C) if alpha == 1.0 else (1 - alpha) * it_.C
                    return alpha, _Iterate(X, U, J, G, GN, C), mu_gap, tries
            alpha *= s.line_search_factor
        return alpha, None, mu_gap, tries

    def _record(self, hist, it_, lam, lamN, rho, stat, gap, step, reg, alpha):
        viol = constraint_violation(it_.G, it_.GN, it_.C, it_.U, self.problem.u_lb, self.problem.u_ub)
        for key, value in (("cost", it_.J), ("merit", it_.J + self._al(it_.G, it_.GN, lam, lamN, rho)),
                           ("violation", viol), ("gap", gap), ("stationarity", stat), ("step", step),
                           ("reg", reg), ("alpha", alpha), ("penalty", rho)):
            hist[key].append(float(value))

    def _result(self, it_, P, lam, lamN, rho, pol, status, message, iterations, start, hist,
                counts: Mapping[str, int] | None = None, al_log=()) -> SolverResult:
        """The result of the contract: ``status`` is "converged", "infeasible" (with its certificate from the
        multiplier updates' (penalty, violation) log) or a failure reason (status "failed")."""
        pr = self.problem
        solve_s = time.perf_counter() - start
        viol = constraint_violation(it_.G, it_.GN, it_.C, it_.U, pr.u_lb, pr.u_ub)
        K = k = None
        mult = {"constraints": lam.copy(), "terminal_constraints": lamN.copy(), "penalty": rho}
        if pol is not None and pol[0] is not None:
            k, K = self.layout.gains(pol[0])
            mult["dynamics"] = pol[1][1:]
        finite = bool(np.all(np.isfinite(it_.X)) and np.all(np.isfinite(it_.U)) and np.isfinite(it_.J))
        if not finite and status != "numerical_error":
            status, message = "numerical_error", "non-finite iterate"
        viol = viol if np.isfinite(viol) else float("inf")
        reason, certificate = ("", None) if status == "converged" else (status, None)
        if status == "infeasible":
            reason, certificate = "locally_infeasible", self._certificate(it_, al_log)
        kkt = self.kkt.residuals(it_.X, it_.U, P, lam, lamN, it_.X[0]) if finite else dict.fromkeys(KKT_KEYS, float("inf"))
        log.info("DDP %s after %d iterations: cost %.8g, violation %.2e, %.3f ms", reason or status, iterations, it_.J, viol, 1e3 * solve_s)
        return SolverResult(solver=f"ddp[{self.backend.name}]", success=status == "converged",
                            status=status if status in STATUSES else "failed", reason=reason, message=message,
                            certificate=certificate, kkt=kkt,
                            xs=it_.X.copy(), us=it_.U.copy(), cost=float(it_.J) if finite else float("inf"),
                            max_constraint_violation=viol,
                            iterations=iterations, solve_s=solve_s, K=K, k=k, multipliers=mult, history=hist,
                            info={"backend": self.backend.name, **(counts or dict.fromkeys(PASS_COUNTS, 0)),
                                  "full_second_order": self.settings.full_second_order})

    def _certificate(self, it_, al_log) -> dict:
        """Penalties and violations at the multiplier updates, and the constraints violated at the end."""
        tol = self.settings.constraint_tolerance
        names = [n for rows, G in zip(self._rows, (it_.G, it_.GN)) if G.size
                 for n, v in zip(rows, np.max(np.atleast_2d(G), axis=0)) if v > tol]
        return {"penalty": [float(r) for r, _ in al_log], "violation": [float(v) for _, v in al_log],
                "constraints": list(dict.fromkeys(names))}
