"""Constrained multiple-shooting DDP / iLQR with an augmented Lagrangian.

The loop (``DDPSolver._run``) is a sequence of named steps, as crocoddyl's solvers: ``_direction`` (backward
pass and regularisation), ``_stopping`` (the convergence test, the end of an inner loop and the multiplier
update, or the infeasibility certificate), ``_step`` (line search), ``_accepted`` (regularisation schedule,
history, the callback, the first-order convergence check). ``solve(..., callback=f)`` calls ``f`` once per
accepted iteration with a read-only :class:`IterationView`; ``f`` returning True stops the solve.

Method (each part stated, as logged):
- Local model: Gauss-Newton iLQR (cost Hessian J'J, no dynamics curvature) by default;
  ``full_second_order`` uses exact cost Hessians and the dynamics tensor contracted with the
  value gradient (full DDP).
- Multiple shooting with gaps (feasibility-driven, as crocoddyl FDDP, Mastalli et al. ICRA
  2020): the backward pass uses Vx' + Vxx' c with the gap c = f(x_k,u_k) - x_{k+1}; the
  forward pass closes a fraction alpha of every gap, so an infeasible warm start is accepted
  and a full step yields a dynamically feasible trajectory. x_0 is set to x0 before the first
  iteration.
- Control box: box-QP per knot by projected Newton with a search along the projection arc, up to
  ``box_iterations`` steps (exact on random QPs with 2-7 controls in 3; see _riccati), forward pass clamps.
- Inequalities g <= 0 (stage and terminal): PHR augmented Lagrangian (as ALTRO, Howell et al.
  IROS 2019; solvers/_augmented_lagrangian.py): inner DDP iterations on cost + sum (max(0, lam + rho g)^2
  - lam^2) / (2 rho); when the inner stationarity is below the current inner tolerance (or after
  ``inner_max_iterations`` inner iterations), multipliers are updated lam <- max(0, lam + rho g)
  and, one penalty per constraint row (rows in degC, V, rad, rad/s each get their own), rho grows by
  ``penalty_factor`` where the row is violated and its violation did not fall to a quarter of its value
  at the previous update (at the first update of a cold start: of the initial guess's), and shrinks by
  sqrt(``penalty_factor``), not below ``penalty_init``, where it fell below a hundredth of it.
  "infeasible" only with a certificate: at two updates after converged inner loops, the penalty grew
  ``infeasibility_growth`` times and neither the largest violation nor the own violation of a row whose own
  penalty grew that much halved (an inner loop stopped by ``inner_max_iterations`` is no evidence).
- Local model of the AL terms: Gauss-Newton curvature rho Jg'Jg on the active rows (lam + rho g > 0) and, with
  ``active_margin`` > 0, on the rows with lam > 0 within ``active_margin`` (their own units) of g = 0: a full
  step across the kink of a row just short of it otherwise meets curvature rho the model did not have. That
  curvature is about the row's current value, not its kink, so a row creeping toward its kink stalls |Qu|:
  after ``margin_release_steps`` full steps that each cut |Qu| by less than 10 %, such rows' multipliers are set
  to 0 (``DDPSolver._released``; measured on 11 longest-hold searches: 13 % fewer iterations, 11 % fewer
  forward passes). With ``retry_crossed_rows``, on a gap-free iterate whose first ``CROSSED_TRIALS`` trial steps
  were rejected and crossed, within the first ``CROSSED_REACH`` of their way, kinks of rows outside the model, the
  direction is computed again with those rows active (curvature rho Jg'Jg, gradient (lam + rho g) Jg: a semismooth
  Newton step with the trials' active set) and searched from a full step (``DDPSolver._step``; measured on 12
  longest-hold searches: 15 % fewer forward passes, 7 % fewer iterations; benchmarks/README.md, passes7).
- Line search: backtracking (factor 1/2) on the merit phi = cost + AL terms + mu |gaps|_1,
  Armijo test against the quadratic model alpha d1 + alpha^2 d2 / 2 - alpha mu |gaps|_1;
  mu grows as needed to make the step a descent direction (Nocedal & Wright eq. 18.36). With
  ``nonmonotone_memory`` m > 1 the reference of a gap-free iterate is the largest merit of its last m iterates at
  the same multipliers (Grippo, Lampariello & Lucidi, SIAM J. Numer. Anal. 1986), so a full step that raises the
  merit a little after a decrease is taken. Measured on the lift's default longest-hold searches (40 kg, 84 and
  140 °C; benchmarks/README.md): forward passes per iteration 3.3 / 2.3 -> 1.45 / 1.46, no failed line search.
  A failed line search whose model predicts no decrease above rounding (|d1| <= ``decrement_tolerance``
  * (1 + |cost|)) ends the inner loop: the multipliers are updated at the next pass (measured: the
  stalled probes of the lift's longest-hold search otherwise spent 14 forward passes per retry, raising
  the regularisation up to reg_max). Passes and updates are counted in ``SolverResult.info``
  (:data:`PASS_COUNTS`).
- Regularisation: rho_reg I added to Quu; multiplied by ``reg_factor`` on a failed line search, and in Gauss-Newton
  mode also after a step shorter than 1/2 (Levenberg-Marquardt-like damping of a too optimistic model); on a failed
  backward pass multiplied by ``reg_factor`` or, with ``pivot_jump``, raised to at least rho_reg - 2p (p the
  non-positive pivot at the first failing knot, the last in time; not beyond ``reg_max``), so that knot's pivot
  becomes >= |p| in one retry instead of climbing from ``reg_min``; divided by ``reg_decrease`` after a full step.
  Defaults are the conservative schedule (both x10, no jump); a problem may tune them (the lift does:
  ``thermo_ddp.tasks.lift.DDP_OPTIONS``). Measured: a slow decrease (sqrt 10) with the Levenberg-Marquardt damping
  stalls Gauss-Newton on the multi-joint hold (300 iterations against 32), and the jump made receding-horizon
  re-solves near infeasibility fail more often.
- Stopping: converged when the projected control gradient |Qu|_inf <= ``tolerance`` (or, with no regularisation, the
  predicted decrease |d1| <= ``decrement_tolerance`` * (1 + |cost|): no progress is possible above rounding, and
  |Qu|_inf <= ``flat_stationarity`` * (1 + |cost|): the gradient left lies along the penalty's large curvature;
  measured 8e-4 to 1e-3 on MPC re-solves, 1e-5 to 8e-5 on the lift's longest-hold probes, at costs of hundreds), the
  largest gap <= ``gap_tolerance`` and |max(g, -lam/rho)|_inf <= ``constraint_tolerance``. After a full step (gaps
  closed) from an iterate with |Qu|_inf <= sqrt(``tolerance``), |Qu|_inf of the new iterate is first measured by a
  first-order pass (Qu0 = lu + B'a, a = lx + A'a' + K'Qu0 with the last pass's gains K; zero exactly where the full
  pass's Qu0 is): if within tolerance the solve stops there (K, k are then those of that last pass), otherwise a full
  backward pass follows as usual.
- The first backward pass of a solve also evaluates the initial guess (cost, constraints, gaps) in the same sweep over
  the knots.
- Warm start (MPC): trajectories, constraint multipliers and penalty of a previous result (WarmStart.from_result
  shifts them); with multipliers the inner tolerance starts at ``tolerance``. Measured: Gauss-Newton converges slowly
  when a heating term R(T) i^2 is constrained (its curvature is in the dynamics); use ``full_second_order=True``
  there.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable, Mapping

import numpy as np

from .._config import require, settings_from_mapping
from ..errors import InputError
from ..ocp import OptimalControlProblem
from . import _augmented_lagrangian as al
from ._backends import CasadiBackend, CompiledBackend, compiled_library, penalties
from ._layout import Layout
from ._line_search import CROSSED_TRIALS, Iterate as _Iterate, backtrack
from ._numpy_backend import NumpyBackend
from .kkt import KKT_KEYS, KKTEvaluator, constraint_rows
from .result import HISTORY_KEYS, STATUSES, LazyKKT, SolverResult, WarmStart

log = logging.getLogger(__name__)

BACKENDS = ("codegen", "casadi", "numpy")
# The work of a solve, in SolverResult.info: backward (Riccati) passes, forward (rollout) passes of the line
# search, first-order gradient passes, augmented-Lagrangian multiplier updates, releases of stalled margin rows.
PASS_COUNTS = ("backward_passes", "forward_passes", "gradient_passes", "multiplier_updates", "margin_releases")
_SRC = "DDPSettings"


@dataclasses.dataclass(frozen=True)
class DDPSettings:
    """Options of DDPSolver (frozen, validated; unknown keys in from_mapping raise)."""

    max_iterations: int = 200
    tolerance: float = 1e-6                 # projected |Qu|_inf at convergence
    gap_tolerance: float = 1e-8             # largest dynamics gap at convergence
    constraint_tolerance: float = 1e-6      # |max(g, -lam/rho)|_inf at convergence
    decrement_tolerance: float = 1e-12      # or: predicted decrease |d1| <= this * (1 + |cost|) ...
    flat_stationarity: float = 1e-5         # ... and |Qu|_inf <= this * (1 + |cost|) (never while |Qu| is large)
    merit_resolution: float = 1e-9          # a failed line search predicting less (x (1 + |cost|)) ends the inner loop
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
    nonmonotone_memory: int = 1             # Armijo against the largest merit of this many last iterates (1: monotone)
    armijo: float = 1e-4                    # fraction of the model decrease required
    penalty_init: float = 100.0             # AL penalty rho at a cold start
    penalty_factor: float = 10.0
    penalty_max: float = 1e8
    infeasibility_growth: float = 1e3       # "infeasible": the violation not halved while rho grew this much
    active_margin: float = 0.0              # rows with lam > 0 within this of g = 0 get the penalty's curvature
    margin_release_steps: int = 3           # ... released after this many stalled full steps (0: never)
    retry_crossed_rows: bool = False        # a new direction with the rows a cut-short line search crossed early
    box_iterations: int = 8                 # projected-Newton steps per knot at most (nu > 1; see _riccati)
    backend: str = "codegen"                # "codegen" (C via gcc), "casadi" (VM) or "numpy"
    compiler_flags: tuple = ("-O2", "-march=native")  # gcc; big generated files at -O1/-O0 (see codegen)

    def __post_init__(self):
        ints = ("max_iterations", "box_iterations", "inner_max_iterations", "nonmonotone_memory",
                "margin_release_steps")
        for name in ints:
            v = getattr(self, name)
            require(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0, _SRC, name, v,
                    "expected an integer >= 0")
        positive = ("tolerance", "decrement_tolerance", "flat_stationarity", "merit_resolution", "gap_tolerance",
                    "constraint_tolerance", "inner_tolerance_init", "reg_max", "reg_factor", "reg_decrease",
                    "penalty_init", "penalty_factor", "penalty_max", "line_search_min_step", "infeasibility_growth")
        for name in positive:
            v = getattr(self, name)
            require(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0,
                    _SRC, name, v, "expected a finite number > 0")
        for name in ("reg_init", "reg_min", "active_margin"):
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
        for name in ("full_second_order", "pivot_jump", "retry_crossed_rows"):
            require(isinstance(getattr(self, name), bool), _SRC, name, getattr(self, name), "expected True or False")
        require(self.backend in BACKENDS, _SRC, "backend", self.backend, f"expected one of {', '.join(BACKENDS)}")
        require(isinstance(self.compiler_flags, (tuple, list)) and all(isinstance(f, str) for f in self.compiler_flags),
                _SRC, "compiler_flags", self.compiler_flags, "expected a tuple of strings")
        object.__setattr__(self, "compiler_flags", tuple(self.compiler_flags))

    @classmethod
    def from_mapping(cls, values: Mapping, source: str = _SRC) -> "DDPSettings":
        return settings_from_mapping(cls, values, source)


@dataclasses.dataclass(frozen=True)
class IterationView:
    """Read-only figures of one accepted iteration, given to the solve's callback (HISTORY_KEYS and the
    work of the iteration's line search)."""

    iteration: int
    cost: float
    merit: float
    violation: float
    gap: float
    stationarity: float
    step: float
    reg: float
    alpha: float
    penalty: float
    forward_passes: int


@dataclasses.dataclass(frozen=True)
class _Direction:
    """A backward pass's outcome at the current iterate: policy, model decrease terms and the stopping figures."""

    policy: np.ndarray
    d1: float
    d2: float
    stat: float     # projected |Qu|_inf
    gap: float      # largest dynamics gap
    kkt_c: float    # |max(g, -lam/rho)|_inf
    flat: bool      # predicted decrease below rounding


@dataclasses.dataclass
class _Workspace:
    """The state of one solve (never returned): iterate, multipliers, penalty, schedules, counts, history."""

    it: _Iterate
    P: np.ndarray
    lam: np.ndarray
    lamN: np.ndarray
    rho: np.ndarray                 # a penalty per row of g, then of g_N
    reg: float
    omega: float                    # the inner loop's stationarity tolerance
    viol_prev: np.ndarray           # the rows' violations at the previous multiplier update
    start: float
    first: tuple | None = None      # the fused first pass's backward outputs, used by the first direction
    mu_gap: float = 0.0
    inner: int = 0
    iteration: int = 0
    alpha: float = 0.0
    tries: int = 0
    policy: np.ndarray | None = None
    values: np.ndarray | None = None
    costates: np.ndarray | None = None
    status: str | None = None
    message: str = ""
    counts: dict = dataclasses.field(default_factory=lambda: dict.fromkeys(PASS_COUNTS, 0))
    hist: dict = dataclasses.field(default_factory=lambda: {k: [] for k in HISTORY_KEYS})
    al_log: list = dataclasses.field(default_factory=list)  # al.Update at each multiplier update
    recent: list = dataclasses.field(default_factory=list)  # merits of the last iterates at these multipliers

    def stop(self, status: str, message: str) -> None:
        self.status, self.message = status, message

    def record(self, solver: "DDPSolver", stat, gap, step, alpha) -> IterationView:
        """Append this iteration's figures to the history; its read-only view."""
        it_, pr = self.it, solver.problem
        view = IterationView(
            self.iteration, float(it_.J), float(it_.J + it_.al_terms(self.lam, self.lamN, self.rho)),
            it_.max_violation(pr.u_lb, pr.u_ub), float(gap), float(stat),
            float(step), float(self.reg), float(alpha), float(self.rho.max(initial=0.0)), self.tries)
        for key in HISTORY_KEYS:
            self.hist[key].append(getattr(view, key))
        return view


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
        self._has_constraints = self._ng + self._ngN > 0
        start = time.perf_counter()
        self.backend = _backend(problem, settings, self.layout)
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
    def solve(self, x0, params=None, warm_start: WarmStart | SolverResult | None = None,
              callback: Callable[[IterationView], bool | None] | None = None) -> SolverResult:
        """Solve from initial state x0 with per-knot params (N+1, np) and an optional warm start.

        ``callback`` (as crocoddyl's ``CallbackAbstract``) is called once per accepted iteration with a
        read-only :class:`IterationView`; returning True stops the solve (status "failed", reason "stopped")."""
        pr = self.problem
        x0 = pr.check_x0(x0, "DDPSolver.solve")
        P = np.ascontiguousarray(pr.check_params(params, "DDPSolver.solve"))
        if callback is not None and not callable(callback):
            raise InputError("DDPSolver.solve", "callback", type(callback).__name__, "expected a callable")
        X, U, lam, lamN, rho, cold = self._initial_guess(x0, warm_start)
        start = time.perf_counter()
        s = self.settings
        evaluation, first = self.backend.evaluate_backward(X, U, P, lam, lamN, rho, s.reg_init)  # the first pass
        it_ = _Iterate(X, U, *evaluation)
        viol0 = al.row_violation(it_.G, it_.GN) if cold else np.full(rho.size, np.inf)  # cold: vs the guess's
        ws = _Workspace(it_, P, lam, lamN, rho, reg=s.reg_init, start=start, first=first, viol_prev=viol0,
                        omega=max(s.inner_tolerance_init if cold else s.tolerance, s.tolerance))
        if not (np.isfinite(it_.J) and np.isfinite(it_.G).all() and np.isfinite(it_.GN).all()
                and np.isfinite(it_.C).all()):
            ws.first = None
            ws.stop("numerical_error", "the model gives non-finite values at the initial guess")
            return self._finish(ws)
        return self._run(ws, callback)

    # -- internals ------------------------------------------------------------------------------
    def _initial_guess(self, x0, warm):
        pr, s = self.problem, self.settings
        N, ng, ngN = pr.horizon, self._ng, self._ngN
        lam, lamN, rho, cold = np.zeros((N, ng)), np.zeros(ngN), np.full(ng + ngN, s.penalty_init), True
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
                if np.size(m["penalty"]) in (1, ng + ngN):  # one for all rows, or one per row
                    rho = penalties(ng + ngN, m["penalty"]).clip(s.penalty_init, s.penalty_max)
        X = np.array(xs, dtype=float)
        X[0] = x0
        U = np.ascontiguousarray(us.clip(pr.u_lb, pr.u_ub))
        return X, U, lam, lamN, rho, cold

    def _run(self, ws: "_Workspace", callback) -> SolverResult:
        """The loop: per pass a direction, the stopping test (or a multiplier update), a step, the callback."""
        s = self.settings
        while ws.status is None:
            if ws.iteration >= s.max_iterations or ws.counts["backward_passes"] >= 4 * s.max_iterations + 20:
                ws.stop("max_iterations", f"no convergence in {s.max_iterations} iterations")
                break
            direction = self._direction(ws)
            if direction is None or self._stopping(ws, direction) or self._released(ws, direction):
                continue
            direction = self._step(ws, direction)
            if direction is not None:
                self._accepted(ws, direction, callback)
        return self._finish(ws)

    def _direction(self, ws: "_Workspace", flags=None) -> "_Direction | None":
        """Backward pass with regularisation; None after a failed pass (regularisation raised, or exhausted:
        then the workspace is stopped). ``flags``: rows modelled as active (al.flagged; a failed pass then
        changes nothing)."""
        s = self.settings
        ws.counts["backward_passes"] += 1
        it_ = ws.it
        lam, lamN = (ws.lam, ws.lamN) if flags is None else (al.flagged(ws.lam, flags[0]),
                                                              al.flagged(ws.lamN, flags[1]))
        policy, summary, values = ws.first or self.backend.backward(it_.X, it_.U, ws.P, lam, lamN, it_.C, ws.rho,
                                                                    ws.reg)
        ws.first = None
        d1, d2, stat, pivot = summary
        if not (pivot > 0 and np.isfinite(summary).all()):
            if flags is not None:
                return None
            ws.reg = self._increase(ws.reg, policy)
            log.debug("iteration %d: backward pass failed (pivot %.2e), reg -> %.1e", ws.iteration, pivot, ws.reg)
            if ws.reg > s.reg_max:
                ws.stop("regularisation_failed", "Quu not positive definite up to reg_max")
            return None
        ws.policy, ws.values = policy, values
        gap = float(np.abs(it_.C).max(initial=0.0))
        kkt_c = it_.kkt_constraint(ws.lam, ws.lamN, ws.rho)
        flat = abs(d1) <= s.decrement_tolerance * (1.0 + abs(it_.J))
        return _Direction(policy, float(d1), float(d2), float(stat), gap, kkt_c, flat)

    def _stopping(self, ws: "_Workspace", d: "_Direction") -> bool:
        """The stopping test and the end of an inner loop: True when the solve stopped (converged or certified
        infeasible) or the multipliers were updated (no step at this direction)."""
        s = self.settings
        flat = d.flat and ws.reg <= s.reg_min
        inner_done = (d.stat <= ws.omega or flat) and d.gap <= s.gap_tolerance
        over = self._has_constraints and ws.inner >= s.inner_max_iterations and d.kkt_c > s.constraint_tolerance
        if not (inner_done or over):
            return False
        flat_ok = flat and d.stat <= s.flat_stationarity * (1.0 + abs(ws.it.J))
        if inner_done and (d.stat <= s.tolerance or flat_ok) and d.kkt_c <= s.constraint_tolerance:
            ws.record(self, d.stat, d.gap, 0.0, 0.0)
            ws.stop("converged", ("predicted decrease below rounding" if d.stat > s.tolerance else "stationarity")
                    + ", gaps and constraints within tolerance")
            return True
        if inner_done:
            ws.omega = max(s.tolerance, ws.omega * s.inner_tolerance_factor)
        if not (self._has_constraints and d.kkt_c > s.constraint_tolerance):
            return False
        ws.inner = 0
        ws.al_log.append(al.Update.at(s, ws.it.G, ws.it.GN, ws.rho, inner_done))
        if al.stalled(s, ws.al_log):
            ws.stop("infeasible", f"locally infeasible: the violation {ws.al_log[-1].violation:.3g} did not halve "
                    f"while the penalty grew {s.infeasibility_growth:g}x")
            return True
        ws.recent = []
        ws.it.new_multipliers()
        ws.lam, ws.lamN, ws.rho, ws.viol_prev = al.update(s, ws.it.G, ws.it.GN, ws.lam, ws.lamN, ws.rho,
                                                          ws.viol_prev)
        ws.counts["multiplier_updates"] += 1
        return True

    def _released(self, ws: "_Workspace", d: "_Direction") -> bool:
        """Rows kept in the local model by ``active_margin`` (lam > 0, inactive, within the margin of g = 0) get
        the penalty's curvature about where they are, not about their kink: a row creeping toward its kink then
        limits every step along it to about its gradient / rho, and |Qu| stalls. After ``margin_release_steps``
        full steps at these multipliers that each cut |Qu| by less than 10 %, their multipliers are set to 0 (the
        PHR estimate max(0, lam + rho g) of an inactive row: the kink moves by lam / rho) and the direction is
        computed again (True). Measured on 11 longest-hold searches (benchmarks/README.md): one row stalled
        the feasible probe of the 40 kg 140 °C search for 13 iterations, |Qu| 4.9e-3 -> 4.8e-3."""
        s = self.settings
        n = s.margin_release_steps
        if not (s.active_margin > 0 and n and ws.inner >= n and all(a == 1.0 for a in ws.hist["alpha"][-n:])):
            return False
        stats = [*ws.hist["stationarity"][-n:], d.stat]
        if not all(0.9 * a < b <= a for a, b in zip(stats, stats[1:])):
            return False
        rg = ws.rho[:ws.lam.shape[1]]
        band = (ws.lam > 0) & (ws.lam + rg * ws.it.G <= 0) & (ws.it.G > -s.active_margin)
        if not band.any():
            return False
        ws.lam = np.where(band, 0.0, ws.lam)
        ws.recent = []
        ws.it.new_multipliers()
        ws.counts["margin_releases"] += 1
        log.debug("iteration %d: |Qu| stalled at %.2e, %d margin rows released", ws.iteration, d.stat, band.sum())
        return True

    def _step(self, ws: "_Workspace", d: "_Direction") -> "_Direction | None":
        """The line search along the direction (again along one with the rows crossed, ``retry_crossed_rows``: module
        docstring; the next active set of a semismooth Newton step, Hintermueller, Ito & Kunisch, SIAM J. Optim.
        2002); on failure the regularisation grows (None); else the direction taken."""
        s = self.settings

        def search(direction, cut=0, start=1.0, floor=s.line_search_min_step):
            return self._line_search(ws.it, ws.P, direction.policy, direction.d1, direction.d2, ws.lam, ws.lamN,
                                     ws.rho, ws.mu_gap, max(ws.recent, default=-np.inf), cut, start, floor)
        cut = CROSSED_TRIALS if s.retry_crossed_rows and not ws.it.C.any() else 0
        alpha, trial, ws.mu_gap, ws.tries, crossed = search(d, cut)
        if trial is None and crossed is not None:
            d, alpha, trial = self._retry(ws, d, alpha, crossed, search)
        ws.counts["forward_passes"] += ws.tries
        if trial is None:
            if self._has_constraints and abs(d.d1) <= s.merit_resolution * (1.0 + abs(ws.it.J)):
                ws.inner = s.inner_max_iterations  # no decrease left at this penalty: update the multipliers next
            ws.reg = self._increase(ws.reg)
            log.debug("iteration %d: line search failed, reg -> %.1e", ws.iteration, ws.reg)
            if ws.reg > s.reg_max:
                ws.stop("line_search_failed", "no acceptable step up to reg_max")
            return None
        if s.nonmonotone_memory > 1 and not ws.it.C.any():
            merit = ws.it.J + ws.it.al_terms(ws.lam, ws.lamN, ws.rho)
            ws.recent = (ws.recent + [merit])[-(s.nonmonotone_memory - 1):]
        ws.it, ws.alpha = trial, alpha
        return d

    def _retry(self, ws: "_Workspace", d: "_Direction", alpha: float, crossed, search):
        """The direction with the ``crossed`` rows active, searched from a full step down to a half (the new model's
        decrease is not the merit's); none taken, or no such direction: ``d``'s search goes on from ``alpha``.
        Returns (direction, step, iterate or None); the trials are added to ``ws.tries``."""
        kept = ws.policy, ws.values
        again = self._direction(ws, crossed)
        if again is not None:  # the iterate's own stopping figures
            again = dataclasses.replace(again, stat=d.stat, flat=d.flat)
            step, trial, ws.mu_gap, tries, _ = search(again, floor=0.5)
            ws.tries += tries
            if trial is not None:
                return again, step, trial
            ws.policy, ws.values = kept
        alpha, trial, ws.mu_gap, tries, _ = search(d, 0, alpha)
        ws.tries += tries
        return d, alpha, trial

    def _accepted(self, ws: "_Workspace", d: "_Direction", callback) -> None:
        """After an accepted step: regularisation schedule, history, callback and the first-order check of
        convergence after a full step."""
        s = self.settings
        ws.iteration, ws.inner = ws.iteration + 1, ws.inner + 1
        if ws.alpha == 1.0:
            ws.reg = ws.reg / s.reg_decrease if ws.reg / s.reg_decrease >= s.reg_min else 0.0
        elif ws.alpha < 0.5 and not s.full_second_order:  # Gauss-Newton model too optimistic: damp (LM-like)
            ws.reg = self._increase(ws.reg)
        step = ws.alpha * float(np.abs(d.policy[:, : self.problem.nu]).max(initial=0.0))
        view = ws.record(self, d.stat, d.gap, step, ws.alpha)
        log.debug("iteration %d: cost %.6e stat %.2e gap %.2e alpha %.3g reg %.1e rho %.1e", ws.iteration, ws.it.J,
                  d.stat, d.gap, ws.alpha, ws.reg, view.penalty)
        if callback is not None and callback(view):
            ws.stop("stopped", f"stopped by the callback after iteration {ws.iteration}")
            return
        if ws.alpha == 1.0 and d.stat <= s.tolerance ** 0.5 and \
                ws.it.kkt_constraint(ws.lam, ws.lamN, ws.rho) <= s.constraint_tolerance:
            self._first_order_check(ws, d)

    def _first_order_check(self, ws: "_Workspace", d: "_Direction") -> None:
        """The step closed the gaps: a first-order pass with the last gains may show convergence already."""
        ws.counts["gradient_passes"] += 1
        stat, costates = self.backend.gradient(ws.it.X, ws.it.U, ws.P, ws.lam, ws.lamN, d.policy, ws.rho)
        if stat <= self.settings.tolerance:
            ws.record(self, stat, 0.0, 0.0, 0.0)
            ws.costates = costates
            ws.stop("converged", "stationarity (previous gains), gaps and constraints within tolerance")

    def _finish(self, ws: "_Workspace") -> SolverResult:
        it_ = ws.it
        lam_out, lamN_out = al.multipliers(it_.G, it_.GN, ws.lam, ws.lamN, ws.rho)
        if not (np.isfinite(lam_out).all() and np.isfinite(lamN_out).all()):  # a non-finite iterate
            lam_out, lamN_out = ws.lam, ws.lamN
        if ws.costates is None and ws.values is not None:
            ws.costates = self.layout.costates(ws.values)
        return self._result(it_, ws.P, lam_out, lamN_out, ws.rho, (ws.policy, ws.costates), ws.status, ws.message,
                            ws.iteration, ws.start, ws.hist, ws.counts, ws.al_log)

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

    def _line_search(self, *args, **kwargs):
        """The line search (``_line_search.backtrack``) with this solver's settings and backend."""
        return backtrack(self.settings, self.backend, *args, **kwargs)

    def _result(self, it_, P, lam, lamN, rho, pol, status, message, iterations, start, hist,
                counts: Mapping[str, int] | None = None, al_log=()) -> SolverResult:
        """The result of the contract: ``status`` is "converged", "infeasible" (with its certificate from the
        multiplier updates' (penalty, violation) log) or a failure reason (status "failed")."""
        pr = self.problem
        solve_s = time.perf_counter() - start
        viol = it_.max_violation(pr.u_lb, pr.u_ub)
        K = k = None
        mult = {"constraints": lam.copy(), "terminal_constraints": lamN.copy(), "penalty": rho.copy()}
        if pol is not None and pol[0] is not None:
            k, K = self.layout.gains(pol[0])
            mult["dynamics"] = pol[1][1:]
        finite = bool(np.isfinite(it_.X).all() and np.isfinite(it_.U).all() and np.isfinite(it_.J))
        if not finite and status != "numerical_error":
            status, message = "numerical_error", "non-finite iterate"
        viol = viol if np.isfinite(viol) else float("inf")
        reason, certificate = ("", None) if status == "converged" else (status, None)
        if status == "infeasible":
            reason = "locally_infeasible"
            certificate = al.certificate(self.settings, self._rows, it_.G, it_.GN, al_log)
        kkt = dict.fromkeys(KKT_KEYS, float("inf"))
        if finite:  # x_0 is x0 on every DDP iterate (set before the first pass, kept by the rollouts)
            X, U, P = it_.X.copy(), it_.U.copy(), P.copy()
            kkt = LazyKKT(lambda: self.kkt.residuals(X, U, P, lam, lamN, X[0]))
        log.info("DDP %s after %d iterations: cost %.8g, violation %.2e, %.3f ms", reason or status, iterations,
                 it_.J, viol, 1e3 * solve_s)
        return SolverResult(solver=f"ddp[{self.backend.name}]", success=status == "converged",
                            status=status if status in STATUSES else "failed", reason=reason, message=message,
                            certificate=certificate, kkt=kkt,
                            xs=it_.X.copy(), us=it_.U.copy(), cost=float(it_.J) if finite else float("inf"),
                            max_constraint_violation=viol,
                            iterations=iterations, solve_s=solve_s, K=K, k=k, multipliers=mult, history=hist,
                            info={"backend": self.backend.name, **(counts or dict.fromkeys(PASS_COUNTS, 0)),
                                  "full_second_order": self.settings.full_second_order})


def _backend(problem, settings: DDPSettings, layout: Layout):
    """The passes of ``settings.backend``; "codegen" without a compiler falls back to the VM (with a warning)."""
    if settings.backend == "numpy":
        return NumpyBackend(problem, settings, layout)
    if settings.backend == "codegen":
        library = compiled_library(problem, settings, layout)
        if library is not None:
            return CompiledBackend(problem, library, layout)
    return CasadiBackend(problem, settings, layout)
