"""The lift transcription solved by Drake's SNOPT (and Drake's IPOPT) beside our DDP and CasADi's IPOPT.

A peer outside CasADi: the multiple-shooting NLP that IPOPT and fatrop solve (``problem.transcription``:
variables w, parameters, cost f, constraints g with lbg/ubg, bounds lbx/ubx) is handed to pydrake's
``MathematicalProgram`` unchanged:
- decision variables: w (1 per entry, stage order);
- the NLP is cut into blocks of ``--knots-per-block`` knots (default 5). Each block is one Drake cost
  (0.5 |r_k|^2 of its knots' weighted residuals, the terminal one in the last block: the same sum as the
  transcription's f) and one Drake constraint (its rows of the transcription's g, lbg <= g <= ubg) on the
  block's variables (x_k, u_k, ..., x_k1), with its gradient sparsity pattern. Values and Jacobians come
  from CasADi (the transcription expanded to SX, then one jacobian per block); a Python evaluator returns
  them to Drake as AutoDiffXd (value, Jacobian times the input's derivatives);
- the current box: a bounding-box constraint from lbx/ubx.
Before timing, the program is checked equal to the transcription at the initial guess: f, grad f, g and
the Jacobian of g, evaluated through Drake's bindings against CasADi's own (they must agree to 1e-9).

Problems (the lift's default transcription, careful motion on, dt = 0.1 s, cold start from
``lift.initial_guess``, as in ``bench_lift_ocp.py`` and ``plan_lift``):
- ``feasible_40kg_140c_hold20s``: 40 kg, 140 °C, 20 s hold: feasible, the limit inactive (245 knots);
- ``limit_active_40kg_84c_hold12.4s``: 40 kg, 84 °C, 12.4 s hold: the longest hold ``plan_lift`` finds
  under 84 °C (results/lift_ocp.json, DDP and IPOPT alike), ``winding_limit`` binding (169 knots).

Reported per solver: median wall and process CPU time of the solve (of ``--repeats``; Drake's IPOPT, about
2 minutes a solve, once), iterations (SNOPT: major and minor iterations, user function calls and its own CPU
timers, from its print file), final cost (the transcription's f at the returned w), max violation (as
``IpoptSolver`` computes it), status; the wall time inside our Python/CasADi evaluators (last run; the rest is
the solver and Drake's calls into Python); ratios against DDP and CasADi IPOPT; agreement with CasADi IPOPT:
cost within 1e-3 relative, the same feasibility and binding constraints, the largest state differences.

Needs pydrake (PyPI ``drake``), which is not in the project's venv: ``make bench-drake`` creates
``.venv-drake`` with thermo-ddp and benchmarks/requirements-drake.txt and runs this file.

    python benchmarks/bench_lift_drake.py [--repeats 3] [--knots-per-block 5] [--drake-solvers snopt ipopt]
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import logging
import re
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

try:
    from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
    from pydrake.solvers import CommonSolverOption, IpoptSolver, MathematicalProgram, SnoptSolver, SolverOptions
except ImportError:  # one line, no traceback: this benchmark has its own venv
    raise SystemExit("bench_lift_drake: pydrake is not installed in this Python; run `make bench-drake` "
                     "(creates .venv-drake with thermo-ddp and benchmarks/requirements-drake.txt)") from None

from _common import write
from _ocp_bench import row, timed_cpu
from thermo_ddp.solvers import SolverResult
from thermo_ddp.tasks.lift import LiftSettings, binding_constraints, build_lift_problem, initial_guess, make_solver

PROBLEMS = {"feasible_40kg_140c_hold20s": {"payload_kg": 40.0, "limit_c": 140.0, "hold_s": 20.0},
            "limit_active_40kg_84c_hold12.4s": {"payload_kg": 40.0, "limit_c": 84.0, "hold_s": 12.4}}
COST_RTOL = 1e-3          # agreement bound (issue 23)
FEASIBLE_VIOLATION = 1e-6  # a converged solve whose max violation is at most this is feasible
CHECK_RTOL = 1e-9         # the Drake program against the transcription, at the initial guess
# SNOPT: Drake's defaults (limited-memory Hessian, as SNOPT picks for n > 75) with the tolerances tightened
# toward CasADi IPOPT's 1e-8 and room for the many minor (QP) iterations of 5000 constraints. Measured on the
# 140 °C problem, all slower: "Hessian full memory" (100+ major iterations, stopped), "Hessian updates" 30 or
# 100 (CPU 1.7x, 7.7x), "Scale option" 2 (2.8x). The blocks' size hardly matters from 1 to 5 knots (20 knots:
# the dense AutoDiff products double the time).
SNOPT_OPTIONS = {"Major optimality tolerance": 1e-6, "Major feasibility tolerance": 1e-8,
                 "Major iterations limit": 3000, "Iterations limit": 10 ** 7, "Major print level": 1,
                 "Minor print level": 0, "Solution": "No", "Timing level": 3}
# Drake's IPOPT has no Hessian of Python costs: it runs with a limited-memory quasi-Newton Hessian.
# Measured: about 2 minutes a solve, so it is timed once (``DRAKE_IPOPT_REPEATS``).
DRAKE_IPOPT_OPTIONS = {"tol": 1e-8, "constr_viol_tol": 1e-8, "max_iter": 3000, "print_level": 0,
                       "file_print_level": 5}
DRAKE_IPOPT_REPEATS = 1
SOLVERS = {"snopt": (SnoptSolver, SNOPT_OPTIONS), "ipopt": (IpoptSolver, DRAKE_IPOPT_OPTIONS)}


@dataclasses.dataclass
class CallbackClock:
    """Time spent and CasADi calls made in our evaluators (reset before each solve)."""

    seconds: float = 0.0
    casadi_calls: int = 0


class _Block:
    """One block of knots: a Drake cost and a Drake constraint on the same variables, one CasADi call
    per new point (the cost and the constraint of a point share it)."""

    def __init__(self, fun: ca.Function, par: np.ndarray, clock: CallbackClock):
        self.fun, self.par, self.clock = fun, par, clock
        self._key, self._out = None, None

    def _eval(self, w: np.ndarray):
        key = w.tobytes()
        if key != self._key:
            f, df, g, jac = self.fun(w, self.par)
            self._out = (float(f), np.asarray(df).ravel(), np.asarray(g).ravel(), np.asarray(jac))
            self._key = key
            self.clock.casadi_calls += 1
        return self._out

    def cost(self, x):
        start = time.perf_counter()
        if x.dtype == object:
            f, df, _, _ = self._eval(np.asarray(ExtractValue(x), float).ravel())
            out = AutoDiffXd(f, df @ ExtractGradient(x))
        else:
            out = self._eval(np.asarray(x, float))[0]
        self.clock.seconds += time.perf_counter() - start
        return out

    def constraint(self, x):
        start = time.perf_counter()
        if x.dtype == object:
            _, _, g, jac = self._eval(np.asarray(ExtractValue(x), float).ravel())
            out = InitializeAutoDiff(g, jac @ ExtractGradient(x)).ravel()
        else:
            out = self._eval(np.asarray(x, float))[2]
        self.clock.seconds += time.perf_counter() - start
        return out


@dataclasses.dataclass(frozen=True)
class _BlockSpec:
    fun: ca.Function        # (w[cols], par[par_index]) -> (f, grad f, g[rows], dense jacobian of g[rows])
    cols: slice
    rows: slice
    par_index: np.ndarray
    sparsity: list          # (row, col) of the Jacobian's structural nonzeros, block-local


class DrakeTranscription:
    """``problem.transcription`` as a Drake MathematicalProgram, blocks of ``knots_per_block`` knots."""

    def __init__(self, problem, knots_per_block: int):
        self.problem, self.tr = problem, problem.transcription
        self.nlp = ca.Function("nlp", [self.tr.nlp["x"], self.tr.nlp["p"]], [self.tr.nlp["f"], self.tr.nlp["g"]])
        w, par = ca.SX.sym("w", self.tr.n_w), ca.SX.sym("par", self.tr.nlp["p"].numel())
        g = self.nlp.expand()(w, par)[1]
        N = problem.horizon
        self.blocks = [self._block(w, par, g, k0, min(k0 + knots_per_block, N))
                       for k0 in range(0, N, knots_per_block)]

    def _block(self, w, par, g, k0: int, k1: int) -> _BlockSpec:
        """Knots k0..k1-1: variables x_k0, u_k0, ..., x_k1; the rows of their dynamics gaps and path
        constraints (and x_0 - x0 in the first block, the terminal constraints in the last)."""
        pr, f = self.problem, self.problem.functions
        nx, nu, ng, n_p, N = pr.nx, pr.nu, pr.n_constraints, pr.n_params, pr.horizon
        stage = nx + nu
        cols = slice(k0 * stage, k1 * stage + nx)
        rows = slice(0 if k0 == 0 else nx + k0 * (nx + ng), nx + k1 * (nx + ng) if k1 < N else g.numel())
        par_index = np.r_[0:nx, nx + k0 * n_p: nx + (k1 + 1) * n_p]

        def p(k):
            return par[nx + k * n_p: nx + (k + 1) * n_p]

        cost = sum(0.5 * ca.sumsqr(f.stage_residual(w[k * stage: k * stage + nx], w[k * stage + nx: (k + 1) * stage],
                                                    p(k))) for k in range(k0, k1))
        if k1 == N:
            cost += 0.5 * ca.sumsqr(f.terminal_residual(w[N * stage:], p(N)))
        wb, pb, gb = w[cols], par[par_index.tolist()], g[rows]
        jac = ca.jacobian(gb, wb)
        fun = ca.Function(f"block_{k0}", [wb, pb], [cost, ca.gradient(cost, wb), gb, ca.densify(jac)])
        return _BlockSpec(fun, cols, rows, par_index, list(zip(*jac.sparsity().get_triplet())))

    def program(self, x0: np.ndarray, params: np.ndarray):
        """The program for one request: (prog, w, bindings [(block, cost, constraint)], clock)."""
        par, clock, tr = self.tr.parameters(x0, params), CallbackClock(), self.tr
        prog = MathematicalProgram()
        w = prog.NewContinuousVariables(tr.n_w, "w")
        bindings = []
        for spec in self.blocks:
            block = _Block(spec.fun, par[spec.par_index], clock)
            cost = prog.AddCost(block.cost, w[spec.cols])
            constraint = prog.AddConstraint(block.constraint, tr.lbg[spec.rows], tr.ubg[spec.rows], w[spec.cols])
            constraint.evaluator().SetGradientSparsityPattern(spec.sparsity)
            bindings.append((spec, cost, constraint))
        prog.AddBoundingBoxConstraint(tr.lbx, tr.ubx, w)
        return prog, w, bindings, clock

    def max_violation(self, w: np.ndarray, g: np.ndarray) -> float:
        """As ``IpoptSolver`` reports it: equality residual, inequality excess, bound excess."""
        tr = self.tr
        return max(float(np.max(np.abs(g[tr.equality]), initial=0.0)), float(np.max(g[~tr.equality], initial=0.0)),
                   float(np.max(tr.lbx - w, initial=0.0)), float(np.max(w - tr.ubx, initial=0.0)))


def check_program(dt: DrakeTranscription, x0, params, w0: np.ndarray) -> dict:
    """f, grad f, g and dg/dw through Drake's bindings at w0 against CasADi's transcription (MX, not expanded)."""
    tr = dt.tr
    x, p = tr.nlp["x"], tr.nlp["p"]
    f_sym, g_sym = tr.nlp["f"], tr.nlp["g"]
    ref = ca.Function("ref", [x, p], [f_sym, ca.gradient(f_sym, x), g_sym, ca.jacobian(g_sym, x)])
    f_ref, df_ref, g_ref, jac_ref = (np.asarray(ca.densify(v)) for v in ref(w0, tr.parameters(x0, params)))
    f_ref, df_ref, g_ref = f_ref.item(), df_ref.ravel(), g_ref.ravel()
    _, _, bindings, _ = dt.program(x0, params)
    f, df, g, jac = 0.0, np.zeros(tr.n_w), np.zeros(tr.lbg.size), np.zeros((tr.lbg.size, tr.n_w))
    for spec, cost, constraint in bindings:
        wa = InitializeAutoDiff(w0[spec.cols]).ravel()
        c = cost.evaluator().Eval(wa)[0]
        f += c.value()
        df[spec.cols] += c.derivatives()
        gv = constraint.evaluator().Eval(wa)
        g[spec.rows], jac[spec.rows, spec.cols] = ExtractValue(gv).ravel(), ExtractGradient(gv)
    out = {"blocks": len(bindings),
           "cost_rel_diff": abs(f - f_ref) / abs(f_ref),
           "gradient_rel_diff": float(np.max(np.abs(df - df_ref)) / np.max(np.abs(df_ref))),
           "constraint_rel_diff": float(np.max(np.abs(g - g_ref)) / max(np.max(np.abs(g_ref)), 1.0)),
           "jacobian_rel_diff": float(np.max(np.abs(jac - jac_ref)) / np.max(np.abs(jac_ref)))}
    if max(v for k, v in out.items() if k != "blocks") > CHECK_RTOL:
        raise RuntimeError(f"the Drake program is not the transcription: {out}")
    return out


# What each solver's print file says: its exit text and iteration counts.
_LOG_PATTERNS = {"snopt": {"version": r"S N O P T\s+(\S+)", "message": r"SNOPTA INFO\s+\d+ -- (.+)",
                           "major_iterations": r"No\. of major iterations\s+(\d+)",
                           "minor_iterations": r"No\. of iterations\s+(\d+)",
                           "function_calls": r"User function calls \(total\)\s+(\d+)",
                           "snopt_solving_s": r"Time for solving problem\s+([\d.]+) seconds",
                           "snopt_functions_s": r"Time for constraint functions\s+([\d.]+) seconds",
                           "snopt_objective_s": r"Time for objective function\s+([\d.]+) seconds"},
                 "ipopt": {"message": r"EXIT: (.+)", "major_iterations": r"Number of Iterations\.+:\s*(\d+)"}}


def parse_log(name: str, text: str) -> dict:
    out = {}
    for key, pattern in _LOG_PATTERNS[name].items():
        found = re.findall(pattern, text)
        if found:
            value = found[-1].strip()
            out[key] = value if key in ("message", "version") else float(value) if key.endswith("_s") else int(value)
    return out


class DrakeSolver:
    """Drake's ``name`` solver ("snopt" or "ipopt") on the transcription; ``solve`` as our solvers' (x0, params,
    warm start) -> SolverResult. The program is built once per (x0, params), outside the timed solve."""

    def __init__(self, transcription: DrakeTranscription, name: str):
        self.dt, self.name = transcription, name
        cls, self.options = SOLVERS[name]
        self.solver = cls()
        self._programs: dict[bytes, tuple] = {}

    def _program(self, x0, params):
        key = np.concatenate([x0, params.ravel()]).tobytes()
        if key not in self._programs:
            self._programs[key] = self.dt.program(x0, params)
        return self._programs[key]

    def _solver_options(self, print_file: Path) -> SolverOptions:
        options = SolverOptions()
        options.SetOption(CommonSolverOption.kPrintFileName, str(print_file))
        for key, value in self.options.items():
            options.SetOption(self.solver.solver_id(), key, value)
        return options

    def solve(self, x0, params, warm_start) -> SolverResult:
        pr, tr = self.dt.problem, self.dt.tr
        prog, w, _, clock = self._program(x0, params)
        w0 = tr.pack(warm_start.xs, np.clip(warm_start.us, pr.u_lb, pr.u_ub))
        prog.SetInitialGuess(w, w0)
        clock.seconds, clock.casadi_calls = 0.0, 0
        with tempfile.TemporaryDirectory() as tmp:
            print_file = Path(tmp) / f"{self.name}.out"
            options = self._solver_options(print_file)
            start = time.perf_counter()
            result = self.solver.Solve(prog, None, options)
            solve_s = time.perf_counter() - start
            log_info = parse_log(self.name, print_file.read_text() if print_file.exists() else "")
        w_opt = np.asarray(result.GetSolution(w), float)
        f, g = (np.asarray(v).ravel() for v in self.dt.nlp(w_opt, tr.parameters(x0, params)))
        cost, success = float(f[0]), bool(result.is_success())
        if not (np.all(np.isfinite(w_opt)) and np.all(np.isfinite(g)) and np.isfinite(cost)):
            success, cost, g, w_opt = False, float("inf"), np.full_like(g, np.inf), w0
        xs, us = tr.unpack(w_opt)
        message = log_info.get("message", result.get_solution_result().name)
        info = {"solution_result": result.get_solution_result().name, "callback_s": clock.seconds,
                "casadi_calls": clock.casadi_calls, **{k: v for k, v in log_info.items() if k != "message"}}
        return SolverResult(solver=f"drake_{self.name}", success=success, status="converged" if success else "failed",
                            reason="" if success else info["solution_result"], message=message, xs=xs, us=us, cost=cost,
                            iterations=int(log_info.get("major_iterations", -1)), solve_s=solve_s, info=info,
                            max_constraint_violation=self.dt.max_violation(w_opt, g))


def feasible(result: SolverResult) -> bool:
    return bool(result.success and result.max_constraint_violation <= FEASIBLE_VIOLATION)


def agreement(lp, result: SolverResult, reference: SolverResult) -> dict:
    """``result`` against CasADi IPOPT's: cost, feasibility, binding constraints, largest state differences."""
    joint = lp.model.joints[0]
    columns = {name: lp.model.index(joint, name) for name in ("q_rad", "winding_c")}
    diff = {name: float(np.max(np.abs(result.xs[:, i] - reference.xs[:, i]))) for name, i in columns.items()}
    cost_rel = abs(result.cost - reference.cost) / abs(reference.cost)
    same_binding = binding_constraints(lp, result) == binding_constraints(lp, reference)
    return {"cost_rel_diff_vs_ipopt": float(cost_rel), "same_feasibility": feasible(result) == feasible(reference),
            "same_binding": same_binding, "max_abs_diff_vs_ipopt": diff,
            "agrees": bool(cost_rel <= COST_RTOL and feasible(result) == feasible(reference))}


def bench_problem(spec: dict, repeats: int, knots_per_block: int, drake_solvers) -> dict:
    lp = build_lift_problem(LiftSettings(**spec))
    guess = initial_guess(lp)
    start = time.perf_counter()
    dt = DrakeTranscription(lp.problem, knots_per_block)
    build_s = time.perf_counter() - start
    w0 = lp.problem.transcription.pack(guess.xs, np.clip(guess.us, lp.problem.u_lb, lp.problem.u_ub))
    out = {**spec, "knots": lp.problem.horizon, "n_w": dt.tr.n_w, "n_g": int(dt.tr.lbg.size),
           "drake_build_s": build_s, "check": check_program(dt, lp.x0, lp.params, w0)}
    solvers = {"ddp": make_solver(lp, "ddp"), "ipopt": make_solver(lp, "ipopt"),
               **{f"drake_{name}": DrakeSolver(dt, name) for name in drake_solvers}}
    results = {}
    for label, solver in solvers.items():
        res, timing = timed_cpu(lambda: solver.solve(lp.x0, lp.params, guess),
                                DRAKE_IPOPT_REPEATS if label == "drake_ipopt" else repeats)
        results[label] = res
        out[label] = {**row(res, timing), "message": res.message, "binding": binding_constraints(lp, res)}
        extra = ""
        if label.startswith("drake_"):
            out[label].update(res.info, outside_callbacks_s=timing["wall_median_s"] - res.info["callback_s"])
            extra = f", {res.info['callback_s']:.1f} s in our callbacks"
        print(f"  {label:>12}: {timing['wall_median_s']:8.3f} s, {res.iterations:4d} it, cost {res.cost:.8g}, "
              f"viol {res.max_constraint_violation:.1e}, {res.status} ({res.message}){extra}", flush=True)
    for label, res in results.items():
        out[label]["time_over_ddp"] = out[label]["wall_median_s"] / out["ddp"]["wall_median_s"]
        out[label]["time_over_casadi_ipopt"] = out[label]["wall_median_s"] / out["ipopt"]["wall_median_s"]
        out[label]["cpu_over_ddp"] = out[label]["cpu_median_s"] / out["ddp"]["cpu_median_s"]
        out[label]["cpu_over_casadi_ipopt"] = out[label]["cpu_median_s"] / out["ipopt"]["cpu_median_s"]
        if label != "ipopt":
            out[label]["agreement"] = agreement(lp, res, results["ipopt"])
    out["ddp_ipopt_snopt_agree"] = all(out[k]["agreement"]["agrees"] for k in ("ddp", "drake_snopt") if k in out)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--knots-per-block", type=int, default=5)
    parser.add_argument("--drake-solvers", nargs="+", choices=sorted(SOLVERS), default=["snopt", "ipopt"])
    parser.add_argument("--only", nargs="+", choices=sorted(PROBLEMS), default=None)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    cases = {}
    for label in args.only or PROBLEMS:
        print(f"lift, {label}", flush=True)
        cases[label] = bench_problem(PROBLEMS[label], args.repeats, args.knots_per_block, args.drake_solvers)
    write("lift_drake", {
        "description": "the lift's multiple-shooting transcription (careful motion on, dt = 0.1 s, cold start) "
                       "solved by Drake's SNOPT and IPOPT (Python evaluators of CasADi values and Jacobians) beside "
                       "DDPSolver and CasADi's IPOPT; median wall time of solve()",
        "versions": {p: importlib.metadata.version(p) for p in ("drake", "casadi", "numpy")},
        "snopt_options": SNOPT_OPTIONS, "drake_ipopt_options": DRAKE_IPOPT_OPTIONS,
        "knots_per_block": args.knots_per_block, "repeats": args.repeats, "cost_rtol": COST_RTOL,
        "feasible_violation": FEASIBLE_VIOLATION, "problems": cases})


if __name__ == "__main__":
    main()
