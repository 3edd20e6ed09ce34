"""Helpers shared by the solver benchmarks: timed solves (medians), result rows, the lift scenario
at a given number of knots, and shifting a solution by one knot (DDP and IPOPT warm starts alike)."""
from __future__ import annotations

import statistics
import time

import numpy as np

from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem
from thermo_ddp.tasks.verdicts import solve_work
from thermo_ddp.solvers import SolverResult, WarmStart

# The lift scenario at every N: 40 kg at the gripper, lift 2 s, hold 15.6 s, lower 2 s, rest 0.4 s
# (20 s in all), dt = 20 s / N so that every phase is a whole number of knots for N = 100..800.
# The per-knot tracking and velocity weights scale with dt (LiftSettings' defaults hold at dt = 0.1 s;
# the Joule term is already R i^2 dt), so every N approximates the same continuous-time problem.
SCENARIO_S = 20.0
SCENARIO = {"payload_kg": 40.0, "hold_s": 15.6, "lift_s": 2.0, "lower_s": 2.0, "settle_s": 0.4}
_DEFAULT = LiftSettings()


def lift_problem(knots: int, limit_c: float, **overrides):
    """The elbow + thermal lift transcribed on ``knots`` intervals (dt = 20 s / knots)."""
    dt = SCENARIO_S / knots
    scale = dt / _DEFAULT.dt_s
    weights = {"tracking_weight": _DEFAULT.tracking_weight * scale, "velocity_weight": _DEFAULT.velocity_weight * scale}
    settings = LiftSettings(limit_c=limit_c, dt_s=dt, **{**SCENARIO, **weights, **overrides})
    lp = build_lift_problem(settings)
    if lp.problem.horizon != knots:
        raise RuntimeError(f"lift transcribed on {lp.problem.horizon} knots, expected {knots}")
    return lp


def timed_solves(solve, repeats: int) -> tuple[SolverResult, dict]:
    """Run ``solve()`` ``repeats`` times; the last result and the median wall and solver times."""
    walls, inner, result = [], [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = solve()
        walls.append(time.perf_counter() - start)
        inner.append(result.solve_s)
    return result, {"wall_median_s": statistics.median(walls), "wall_min_s": min(walls),
                    "wall_max_s": max(walls), "solver_median_s": statistics.median(inner), "repeats": repeats}


def timed_cpu(solve, repeats: int):
    """``timed_solves`` plus the median process CPU time of a solve (steadier than wall time on a loaded machine)."""
    cpu = []

    def once():
        start = time.process_time()
        result = solve()
        cpu.append(time.process_time() - start)
        return result

    result, timing = timed_solves(once, repeats)
    return result, {**timing, "cpu_median_s": statistics.median(cpu)}


def row(result: SolverResult, timing: dict, reference: SolverResult | None = None) -> dict:
    """One table row: timings, iterations (and DDP's passes and multiplier updates), final cost, max violation,
    status (and cost gap to a peer)."""
    out = {**timing, **solve_work([result]), "cost": float(result.cost),
           "max_violation": float(result.max_constraint_violation), "status": result.status,
           "success": bool(result.success)}
    if reference is not None and np.isfinite(reference.cost):
        out["cost_rel_diff_vs_ipopt"] = float(abs(result.cost - reference.cost) / abs(reference.cost))
    return out


def _shift_rows(a: np.ndarray, shift: int) -> np.ndarray:
    return np.concatenate([a[shift:], np.repeat(a[-1:], shift, axis=0)])


def shifted_nlp_warm_start(result: SolverResult, problem, shift: int = 1) -> WarmStart:
    """Primal trajectories and IPOPT's NLP duals shifted by ``shift`` knots (last knot repeated).

    lam_g is [initial (nx), N stages of (dynamics nx, path ng), terminal ngN]; lam_x is N stages
    of (x nx, u nu) and x_N: the stage blocks move exactly as the trajectories do.
    """
    warm = WarmStart.from_result(result, shift=shift)
    m = result.multipliers
    if "nlp_lam_g" not in m:
        return warm
    nx, nu, ng, N = problem.nx, problem.nu, problem.n_constraints, problem.horizon
    lam_g, lam_x = np.asarray(m["nlp_lam_g"]), np.asarray(m["nlp_lam_x"])
    stages_g = _shift_rows(lam_g[nx: nx + N * (nx + ng)].reshape(N, nx + ng), shift)
    stages_x = _shift_rows(lam_x[: N * (nx + nu)].reshape(N, nx + nu), shift)
    lam_g = np.concatenate([lam_g[:nx], stages_g.ravel(), lam_g[nx + N * (nx + ng):]])
    lam_x = np.concatenate([stages_x.ravel(), lam_x[N * (nx + nu):]])
    return WarmStart(warm.xs, warm.us, {**warm.multipliers, "nlp_lam_g": lam_g, "nlp_lam_x": lam_x})


def nlp_warm_start(result: SolverResult) -> WarmStart:
    """Unshifted warm start keeping every multiplier (IPOPT's NLP duals included)."""
    return WarmStart(result.xs, result.us, dict(result.multipliers))
