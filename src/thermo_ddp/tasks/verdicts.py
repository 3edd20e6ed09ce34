"""Verdicts on a solved task: feasibility, binding and violated constraints by name, solver summaries."""
from __future__ import annotations

import numpy as np

from ..solvers import SolverResult
from ..solvers.ddp import PASS_COUNTS
from .problem import TaskProblem

FEASIBLE_TOL = 1e-4       # largest constraint violation of a plan called feasible
ACTIVE_TOL = 1e-3         # a constraint within this of its bound is binding


def is_feasible(result: SolverResult, tol: float = FEASIBLE_TOL) -> bool:
    return bool(result.success and result.max_constraint_violation <= tol)


def constraint_maxima(tp: TaskProblem, result: SolverResult) -> dict[str, float]:
    """Largest value over the plan of every constraint (g <= 0) by name, the current boxes included
    (|u| - peak)."""
    f, pr = tp.problem.functions, tp.problem
    g = np.array(f.stage_constraint.map(pr.horizon)(result.xs[:-1].T, result.us.T, tp.params[:-1].T)).T
    gn = np.array(f.terminal_constraint(result.xs[-1], tp.params[-1])).ravel()
    out: dict[str, float] = {}
    for values, items in ((g.max(axis=0) if g.size else g, pr.constraints), (gn, pr.terminal_constraints)):
        labels = [c.name for c in items for _ in range(c.size)]
        for value, label in zip(values, labels):
            out[label] = max(out.get(label, -np.inf), float(value))
    peak = np.abs(result.us).max(axis=0) - np.broadcast_to(pr.u_ub, result.us.shape[1:])
    out.update({name: float(v) for name, v in zip(tp.box_names, peak)})
    return out


def binding_constraints(tp: TaskProblem, result: SolverResult, active_tol: float = ACTIVE_TOL) -> list[str]:
    """Names of the constraints at (or past) their bound somewhere on the plan."""
    return sorted(k for k, v in constraint_maxima(tp, result).items() if v >= -active_tol)


def violated_constraints(tp: TaskProblem, result: SolverResult, tol: float = ACTIVE_TOL) -> list[str]:
    """Names of the constraints violated by more than ``tol`` somewhere on the plan."""
    return sorted(k for k, v in constraint_maxima(tp, result).items() if v > tol)


def solver_summary(result: SolverResult, total_solve_s: float, solves: int, every_result=None, **override) -> dict:
    """The plan JSON's ``solver``: the result's summary, its status, all solves' time and count, and ``work``:
    :func:`solve_work` of every solve (``every_result``; default: the result alone)."""
    return {**result.summary(), "status": result.status, "total_solve_s": float(total_solve_s), "solves": solves,
            "work": solve_work(every_result or [result]), **override}


def solve_work(results) -> dict[str, int]:
    """Iterations and, where the solver counts them (DDP), its passes of each kind and multiplier updates
    (:data:`thermo_ddp.solvers.ddp.PASS_COUNTS`), summed over ``results``."""
    results = list(results)
    work = {"iterations": sum(int(r.iterations) for r in results)}
    work.update({k: sum(int(r.info[k]) for r in results) for k in PASS_COUNTS if all(k in r.info for r in results)})
    return work

