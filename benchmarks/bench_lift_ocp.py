"""The elbow + thermal lift OCP: DDP against IPOPT and fatrop, same problem, same knots, one process.

1. solvers: the lift (40 kg at the gripper, 20 s scenario, see _ocp_bench.SCENARIO) on N = 100, 200,
   400, 800 knots (dt = 20 s / N, so the same scenario is discretised ever finer), under a
   140 °C limit (inactive: the plan peaks near 95 °C) and a 94 °C limit (active during the hold).
   Each solver cold (from lift.initial_guess, as plan_lift starts) and warm: from its own solution
   of the neighbouring problem, the same lift with the hold one knot shorter (the previous probe
   of plan_lift's longest-hold search); DDP takes that solution's trajectories, AL multipliers and
   penalty, IPOPT its primal and dual solution (warm_start_init_point), fatrop the primal only.
   Reported: median wall time of ``solve`` (and the solver's own clock), iterations, final cost,
   max violation, status, cost difference to IPOPT's cold optimum; DDP's time ratio N=800 / N=100.
2. plan_lift: whole cold calls (problem and solver built inside; DDP's compiled code comes from
   the on-disk cache, filled by one untimed call first): a feasible plan (40 kg, 140 °C, 20 s hold)
   and an infeasible one (40 kg, 84 °C, 30 s hold) that runs the longest-hold search.

    python benchmarks/bench_lift_ocp.py [--repeats 5] [--quick]
"""
from __future__ import annotations

import argparse
import logging
import statistics
import time

from _common import write
from _ocp_bench import SCENARIO, SCENARIO_S, lift_problem, nlp_warm_start, row, timed_solves
from thermo_ddp.tasks.lift import LiftSettings, binding_constraints, initial_guess, make_solver, plan_lift

KNOTS = (100, 200, 400, 800)
LIMITS_C = {"limit_inactive_140c": 140.0, "limit_active_94c": 94.0}
SOLVERS = ("ddp", "ipopt", "fatrop")
PLANS = {"feasible_40kg_140c_hold20s": (40.0, 140.0, 20.0), "infeasible_40kg_84c_hold30s": (40.0, 84.0, 30.0)}


def bench_knots(knots: int, limit_c: float, repeats: int) -> dict:
    """Cold and warm solves of every solver on one transcription."""
    lp = lift_problem(knots, limit_c)
    neighbour = lp.with_hold(lp.hold_s - lp.settings.dt_s)
    out, reference = {"dt_s": lp.settings.dt_s, "nx": lp.problem.nx, "nu": lp.problem.nu}, None
    for name in SOLVERS:
        start = time.perf_counter()
        solver = make_solver(lp, name)
        build_s = time.perf_counter() - start
        cold, t_cold = timed_solves(lambda: solver.solve(lp.x0, lp.params, initial_guess(lp)), repeats)
        reference = cold if name == "ipopt" else reference
        previous = solver.solve(neighbour.x0, neighbour.params, initial_guess(neighbour))
        warm_start = nlp_warm_start(previous)
        solver.solve(lp.x0, lp.params, warm_start)  # untimed: IPOPT builds its dual-warm-start instance here
        warm, t_warm = timed_solves(lambda: solver.solve(lp.x0, lp.params, warm_start), repeats)
        out[name] = {"build_s": build_s, "cold": row(cold, t_cold), "warm": row(warm, t_warm),
                     "binding": binding_constraints(lp, cold),
                     "peak_winding_c": float(cold.xs[:, lp.model.index(lp.model.joints[0], "winding_c")].max())}
        print(f"  N={knots:4d} {name:>6}: cold {1e3 * t_cold['wall_median_s']:9.1f} ms ({cold.iterations:3d} it, "
              f"{cold.status}), warm {1e3 * t_warm['wall_median_s']:9.1f} ms ({warm.iterations:3d} it, {warm.status})",
              flush=True)
    for name in SOLVERS:
        for kind in ("cold", "warm"):
            res = out[name][kind]
            res["cost_rel_diff_vs_ipopt_cold"] = abs(res["cost"] - reference.cost) / abs(reference.cost)
            if name != "ddp":
                res["time_over_ddp"] = res["wall_median_s"] / out["ddp"][kind]["wall_median_s"]
    return out


def bench_plan(payload_kg: float, limit_c: float, hold_s: float, repeats: int) -> dict:
    """Whole plan_lift calls per solver; the ratio IPOPT / DDP of wall and solver time."""
    out = {"payload_kg": payload_kg, "limit_c": limit_c, "hold_s": hold_s}
    for name in ("ddp", "ipopt"):
        walls, plan = [], None
        for _ in range(repeats):
            start = time.perf_counter()
            plan = plan_lift(payload_kg, limit_c, hold_s, solver=name)
            walls.append(time.perf_counter() - start)
        out[name] = {"wall_median_s": statistics.median(walls), "wall_min_s": min(walls), "repeats": repeats,
                     "solve_s": plan.solver["total_solve_s"], "solves": plan.solver["solves"],
                     "status": plan.status, "achieved_hold_s": plan.achieved_hold_s,
                     "iterations_last": plan.solver["iterations"], "cost": plan.solver["cost"],
                     "max_violation": plan.solver["max_constraint_violation"]}
        print(f"  plan_lift {payload_kg:g} kg {limit_c:g} °C hold {hold_s:g} s {name:>5}: "
              f"{out[name]['wall_median_s']:.3f} s wall, {out[name]['solve_s']:.3f} s in {plan.solver['solves']} "
              f"solve(s), {plan.status}, hold {plan.achieved_hold_s:.1f} s", flush=True)
    out["ipopt_over_ddp_wall"] = out["ipopt"]["wall_median_s"] / out["ddp"]["wall_median_s"]
    out["ipopt_over_ddp_solve"] = out["ipopt"]["solve_s"] / out["ddp"]["solve_s"]
    return out


def run(repeats: int, quick: bool) -> dict:
    knots = KNOTS
    cases = {}
    for label, limit_c in LIMITS_C.items():
        print(f"lift OCP, {label}", flush=True)
        cases[label] = {str(n): bench_knots(n, limit_c, repeats) for n in knots}
        for kind in ("cold", "warm"):
            t = {n: cases[label][str(n)]["ddp"][kind]["wall_median_s"] for n in knots}
            cases[label][f"ddp_{kind}_time_ratio_800_over_100"] = t[800] / t[100]
    for args in PLANS.values():  # untimed: fills DDP's on-disk code cache for both horizons
        plan_lift(*args, solver="ddp")
    plans = {label: bench_plan(*args, repeats=1 if quick else max(2, repeats // 2)) for label, args in PLANS.items()}
    return {"description": "elbow + thermal lift OCP, DDP (full second order, codegen) vs IPOPT vs fatrop; "
                           "median wall time of solve(); plan_lift whole calls",
            "scenario": {**SCENARIO, "duration_s": SCENARIO_S, "dt_s": "20 s / N",
                         "integrator": LiftSettings().integrator},
            "limits_c": LIMITS_C, "repeats": repeats, "lift": cases, "plan_lift": plans}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="2 repeats, one plan_lift call per case")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    write("lift_ocp", run(2 if args.quick else args.repeats, args.quick))


if __name__ == "__main__":
    main()
