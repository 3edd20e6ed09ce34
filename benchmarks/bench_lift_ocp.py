"""The elbow + thermal lift OCP: DDP against IPOPT and fatrop, same problem, same knots, one process.

1. solvers: the lift (40 kg at the gripper, 20 s scenario, see _ocp_bench.SCENARIO) on N = 100, 200,
   400, 800 knots (dt = 20 s / N, so the same scenario is discretised ever finer), under a
   140 °C limit (inactive: the plan peaks near 95 °C) and a 94 °C limit (active during the hold).
   Each solver cold (from lift.initial_guess, as plan_lift starts) and warm: from its own solution
   of the neighbouring problem, the same lift with the hold one knot shorter (the previous probe
   of plan_lift's longest-hold search); DDP takes that solution's trajectories (as the search does), IPOPT its primal and dual solution (warm_start_init_point), fatrop the primal only.
   Reported: median wall time of ``solve`` (and the solver's own clock), iterations, final cost,
   max violation, status, cost difference to IPOPT's cold optimum; DDP's time ratio N=800 / N=100.
2. plan_lift: whole cold calls (problem and solver built inside; DDP's compiled code comes from
   the on-disk cache, filled by one untimed call first): a feasible plan (40 kg, 140 °C, 20 s hold)
   and the default plans of 40 kg under 84 °C and 140 °C (60 s requested, careful motion on), cut short
   by the winding: the longest-hold search runs. Reported per solver: wall time, achieved hold, and the
   work of all solves (iterations; DDP: backward and forward passes, multiplier updates); DDP also with
   careful motion off (what careful motion costs).

Every problem is the lift's default transcription (``LiftSettings``: careful motion on).

    python benchmarks/bench_lift_ocp.py [--repeats 5] [--quick] [--plans-only]
"""
from __future__ import annotations

import argparse
import logging
import statistics
import time

from _common import write
from _ocp_bench import SCENARIO, SCENARIO_S, lift_problem, nlp_warm_start, row, timed_solves
from thermo_ddp.tasks.limits import DEFAULT_HOLD_S
from thermo_ddp.tasks.motion import MotionQuality
from thermo_ddp.solvers import WarmStart
from thermo_ddp.tasks.lift import LiftSettings, binding_constraints, initial_guess, make_solver, plan_lift

KNOTS = (100, 200, 400, 800)
LIMITS_C = {"limit_inactive_140c": 140.0, "limit_active_94c": 94.0}
SOLVERS = ("ddp", "ipopt", "fatrop")
PLANS = {"feasible_40kg_140c_hold20s": (40.0, 140.0, 20.0), "default_40kg_84c": (40.0, 84.0, DEFAULT_HOLD_S),
         "default_40kg_140c": (40.0, 140.0, DEFAULT_HOLD_S)}


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
        warm_start = WarmStart(previous.xs, previous.us) if name == "ddp" else nlp_warm_start(previous)
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
    """Whole plan_lift calls per solver (and DDP without careful motion); the ratio IPOPT / DDP of wall and
    solver time, the achieved holds' difference in knots."""
    out = {"payload_kg": payload_kg, "limit_c": limit_c, "hold_s": hold_s}
    for label, name, careful in (("ddp", "ddp", True), ("ipopt", "ipopt", True), ("ddp_careful_off", "ddp", False)):
        walls, plan = [], None
        for _ in range(repeats):
            start = time.perf_counter()
            plan = plan_lift(payload_kg, limit_c, hold_s, solver=name, careful_motion=careful)
            walls.append(time.perf_counter() - start)
        m: MotionQuality = plan.motion
        out[label] = {"wall_median_s": statistics.median(walls), "wall_min_s": min(walls), "repeats": repeats,
                      "solve_s": plan.solver["total_solve_s"], "solves": plan.solver["solves"],
                      "probes": plan.solver["probes"],
                      "status": plan.status, "achieved_hold_s": plan.achieved_hold_s, "work": plan.solver["work"],
                      "iterations_last": plan.solver["iterations"], "cost": plan.solver["cost"],
                      "forward_passes_per_iteration": (plan.solver["work"]["forward_passes"]
                                                       / max(plan.solver["work"]["iterations"], 1)
                                                       if "forward_passes" in plan.solver["work"] else None),
                      "max_violation": plan.solver["max_constraint_violation"],
                      "motion": {"reversals": m.reversals, "max_speed_near_stop_rad_s": m.max_speed_near_stop_rad_s,
                                 "final_speed_rad_s": m.final_speed_rad_s, "inside_range": m.inside_range,
                                 "max_acceleration_rad_s2": m.max_acceleration_rad_s2}}
        print(f"  plan_lift {payload_kg:g} kg {limit_c:g} °C hold {hold_s:g} s {label:>15}: "
              f"{out[label]['wall_median_s']:.3f} s wall, {out[label]['solve_s']:.3f} s in {plan.solver['solves']} "
              f"solve(s), {plan.status}, hold {plan.achieved_hold_s:.1f} s, work {plan.solver['work']}", flush=True)
    out["ipopt_over_ddp_wall"] = out["ipopt"]["wall_median_s"] / out["ddp"]["wall_median_s"]
    out["ipopt_over_ddp_wall_min"] = out["ipopt"]["wall_min_s"] / out["ddp"]["wall_min_s"]
    out["ipopt_over_ddp_solve"] = out["ipopt"]["solve_s"] / out["ddp"]["solve_s"]
    out["careful_over_careful_off_ddp_wall"] = out["ddp"]["wall_median_s"] / out["ddp_careful_off"]["wall_median_s"]
    dt = LiftSettings().dt_s
    out["hold_knots_ddp_minus_ipopt"] = round((out["ddp"]["achieved_hold_s"] - out["ipopt"]["achieved_hold_s"]) / dt)
    return out


def run(repeats: int, quick: bool, plans_only: bool = False) -> dict:
    knots = KNOTS
    cases = {}
    for label, limit_c in ({} if plans_only else LIMITS_C).items():
        print(f"lift OCP, {label}", flush=True)
        cases[label] = {str(n): bench_knots(n, limit_c, repeats) for n in knots}
        for kind in ("cold", "warm"):
            t = {n: cases[label][str(n)]["ddp"][kind]["wall_median_s"] for n in knots}
            cases[label][f"ddp_{kind}_time_ratio_800_over_100"] = t[800] / t[100]
    for args in PLANS.values():  # untimed: fills DDP's on-disk code cache for every horizon, careful or not
        for careful in (True, False):
            plan_lift(*args, solver="ddp", careful_motion=careful)
    plans = {label: bench_plan(*args, repeats=1 if quick else max(2, repeats // 2)) for label, args in PLANS.items()}
    return {"description": "elbow + thermal lift OCP (careful motion on), DDP (full second order, codegen) vs IPOPT "
                           "vs fatrop; median wall time of solve(); plan_lift whole calls",
            "scenario": {**SCENARIO, "duration_s": SCENARIO_S, "dt_s": "20 s / N",
                         "integrator": LiftSettings().integrator},
            "limits_c": LIMITS_C, "repeats": repeats, "lift": cases, "plan_lift": plans}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="2 repeats, one plan_lift call per case")
    parser.add_argument("--plans-only", action="store_true",
                        help="only part 2 (whole plan_lift calls), written to results/lift_ocp_plans.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    result = run(2 if args.quick else args.repeats, args.quick, args.plans_only)
    write("lift_ocp_plans" if args.plans_only else "lift_ocp", result)


if __name__ == "__main__":
    main()
