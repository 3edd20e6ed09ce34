"""Benchmark (c): one warm MPC step of the elbow lift (elbow + thermal, N = 200 knots), DDP vs IPOPT.

The closed loop (plant with +15 % thermal resistances, noisy quantised casing sensor, EKF) is run
once with the DDP controller; its per-period problems (estimated state, window parameters) are then
replayed by DDP and by IPOPT, each warm-started from its own previous solution shifted by one
knot (IPOPT primal and dual, the duals shifted too). Medians over the periods k >= 1.
Closed-loop figures (peak true winding vs the limit, margin, solve times) are written alongside.

Usage: python benchmarks/bench_mpc_closed_loop.py [--hold-s 12] [--plot OUT.png]
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from _common import write

from thermo_ddp.tasks.lift import initial_guess, make_solver
from thermo_ddp.mpc import MPCSettings, build_models, mpc_solver, planning_problem, run_closed_loop
from thermo_ddp.solvers import DDPSettings, IpoptSolver, WarmStart


def shift_blocks(a: np.ndarray, head: int, block: int, count: int) -> np.ndarray:
    """Shift ``count`` blocks of ``block`` entries after ``head`` entries by one block (last repeated)."""
    a = np.asarray(a, float)
    body = a[head:head + count * block].reshape(count, block)
    body = np.vstack([body[1:], body[-1:]])
    return np.concatenate([a[:head], body.ravel(), a[head + count * block:]])


def ipopt_warm(prev, problem) -> WarmStart:
    warm = WarmStart.from_result(prev, shift=1)
    nx, nu, ng, N = problem.nx, problem.nu, problem.n_constraints, problem.horizon
    m = prev.multipliers
    return WarmStart(warm.xs, warm.us, {"nlp_lam_g": shift_blocks(m["nlp_lam_g"], nx, nx + ng, N),
                                        "nlp_lam_x": shift_blocks(m["nlp_lam_x"], 0, nx + nu, N)})


def replay(solver, lp, x0s, params, warm_fn, cold_solver=None):
    """Solve the recorded problems in order, each warm-started from the previous solution."""
    first = dataclasses.replace(lp, x0=x0s[0], params=params[0])
    prev = (cold_solver or solver).solve(x0s[0], params[0], initial_guess(first))
    out = []
    for x0, p in zip(x0s[1:], params[1:]):
        prev = solver.solve(x0, p, warm_fn(prev))
        out.append(prev)
    return out


def ddp_warm(settings):
    """As the controller: shifted trajectories and multipliers, the AL penalty capped."""
    def warm(prev):
        w = WarmStart.from_result(prev, shift=1)
        mult = dict(w.multipliers)
        mult["penalty"] = min(float(mult["penalty"]), settings.controller.warm_penalty_max)
        return WarmStart(w.xs, w.us, mult)
    return warm


def stats(results) -> dict:
    t = np.array([r.solve_s for r in results])
    return {"median_s": float(np.median(t)), "max_s": float(t.max()), "mean_s": float(t.mean()),
            "median_iterations": float(np.median([r.iterations for r in results])),
            "failures": int(sum(not r.success for r in results)),
            "max_constraint_violation": float(max(r.max_constraint_violation for r in results))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hold-s", type=float, default=12.0)
    ap.add_argument("--plot", default=None)
    args = ap.parse_args()
    settings = MPCSettings.from_options(hold_s=args.hold_s)
    loop = run_closed_loop(settings)
    settings = loop.settings  # the limit resolved from the parameter file
    print(loop.report())
    if args.plot:
        loop.plot(args.plot)
    model, _ = build_models(settings)
    lp = planning_problem(settings, model)
    x0s, params = loop.planner_x0, loop.planner_params
    ddp = mpc_solver(lp, settings)
    cold = make_solver(lp, "ddp", DDPSettings(full_second_order=True, max_iterations=500))
    ddp_runs = replay(ddp, lp, x0s, params, ddp_warm(settings), cold)
    ipopt_runs = replay(IpoptSolver(lp.problem), lp, x0s, params, lambda prev: ipopt_warm(prev, lp.problem))
    d, i = stats(ddp_runs), stats(ipopt_runs)
    cost_gap = [abs(a.cost - b.cost) / abs(b.cost) for a, b in zip(ddp_runs, ipopt_runs) if a.success and b.success]
    payload = {
        "problem": f"elbow lift {settings.scenario.payload_kg:g} kg, nx={lp.problem.nx}, nu=1, N={lp.problem.horizon}, "
                   f"{settings.controller.integrator} dt={settings.controller.control_period_s} s, "
                   f"winding limit {settings.planning_limit_c} °C (planning), full-second-order DDP",
        "periods": int(len(ddp_runs)),
        "warm_step": {"ddp": d, "ipopt": i, "ipopt_over_ddp_median": i["median_s"] / d["median_s"],
                      "ddp_median_le_5ms": d["median_s"] <= 5e-3,
                      "ratio_ge_20": i["median_s"] / d["median_s"] >= 20,
                      "cost_rel_diff_median": float(np.median(cost_gap)) if cost_gap else None,
                      "cost_rel_diff_max": float(np.max(cost_gap)) if cost_gap else None},
        "closed_loop": loop.summary(),
    }
    write("mpc_closed_loop", payload)
    print(f"warm step: DDP {1e3 * d['median_s']:.2f} ms median ({1e3 * d['max_s']:.1f} max), "
          f"IPOPT {1e3 * i['median_s']:.1f} ms median: ratio {payload['warm_step']['ipopt_over_ddp_median']:.1f}")


if __name__ == "__main__":
    main()
