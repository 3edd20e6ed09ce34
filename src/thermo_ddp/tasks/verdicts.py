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



# --------------------------------------------------------------------------------------------
# What a solve says: a verdict (or none), and the constraints that decide it by cause
# --------------------------------------------------------------------------------------------
# The cause classes of the plan JSON's "cause" (contract, third round): constraint kinds by class; a joint's
# constraints carry its name after the kind (``winding_limit_arm_left_4_joint``). The task's own bands
# (``hold_band``, ``return_band``) define the task: they are what the others prevent, never a cause.
CAUSES = {"thermal": ("winding_limit", "terminal_winding_limit"),
          "actuator": ("bus_voltage", "current_peak", "joint_velocity"),
          "motion": ("stop_approach", "one_way", "terminal_rest", "acceleration_limit"),
          "range": ("joint_range",)}
CAUSE_WORDS = {"thermal": "the winding limit decides", "actuator": "the motor's current or voltage decides",
               "motion": "the careful-motion bounds decide", "range": "the joint range decides"}


def verdict(result: SolverResult, tol: float = FEASIBLE_TOL) -> str | None:
    """``"feasible"`` (converged within ``tol``), ``"infeasible"`` (the solver's certificate) or None: the
    solve reached no verdict (failed, or converged with a violation above ``tol``), so it says nothing
    about the robot."""
    if result.status == "converged" and result.max_constraint_violation <= tol:
        return "feasible"
    return "infeasible" if result.status == "infeasible" else None


def cause_class(name: str) -> str | None:
    """The cause class of a constraint name (None: a task band); a scenario's copy ``winding_limit[s2]`` is its kind's."""
    name = name.split("[", 1)[0]
    for cause, kinds in CAUSES.items():
        if any(name == k or name.startswith(k + "_") for k in kinds):
            return cause
    return None


def multiplier_sums(tp: TaskProblem, result: SolverResult) -> dict[str, float]:
    """Sum over the plan of each named constraint's multipliers (0 where the solver gives none)."""
    pr, m, out = tp.problem, result.multipliers, {}
    for key, items, axis in (("constraints", pr.constraints, 0), ("terminal_constraints", pr.terminal_constraints, None)):
        lam = np.asarray(m.get(key, []), float)
        labels = [c.name for c in items for _ in range(c.size)]
        if lam.size == 0 or lam.shape[-1] != len(labels):
            continue
        sums = np.abs(lam).sum(axis=axis) if axis is not None else np.abs(lam)
        for value, label in zip(sums, labels):
            out[label] = out.get(label, 0.0) + float(value)
    return out


def deciding_constraints(tp: TaskProblem, result: SolverResult, violated: bool) -> list[str]:
    """The constraints that decide a verdict, most decisive first: those violated (``violated``: an
    infeasible verdict; those the certificate names) or, when only task bands give way or the plan is
    feasible, those at their bound; task bands left out, ranked by their multipliers, then by how far past
    the bound they are."""
    maxima = constraint_maxima(tp, result)
    lams = multiplier_sums(tp, result)
    names = [k for k, v in maxima.items() if v > ACTIVE_TOL and cause_class(k) is not None] if violated else []
    if violated and result.certificate:  # the solver's own evidence, when it names the constraints
        names = [k for k in names if k in result.certificate["constraints"]] or names
    if not names:  # only the task's bands give way (or a feasible plan): what holds them back is at its bound
        names = [k for k, v in maxima.items() if v >= -ACTIVE_TOL and cause_class(k) is not None]
    return sorted(names, key=lambda k: (-lams.get(k, 0.0), -maxima[k]))


def cause_of(names, heat_decides: bool | None = None) -> str | None:
    """The cause class of ``names`` (most decisive first; None when there is none). A thermal constraint among
    them decides unless ``heat_decides`` is False (e.g. a thermal replay shows the heat alone fits): a winding
    over its limit is never the side effect of a motion bound, while a sagging hold is the side effect of the
    heat (the multipliers of the violated constraints of an infeasible iterate do not tell the two apart)."""
    classes = [cause_class(k) for k in names]
    if "thermal" in classes and heat_decides is not False:
        return "thermal"
    return next((c for c in classes if c not in (None, "thermal")), None)
