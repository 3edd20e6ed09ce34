"""One warm MPC step of the elbow + thermal lift, N = 200 (dt = 0.1 s): DDP vs IPOPT (and fatrop).

The solver-level step on the controller's problem (no controller loop logic from thermo_ddp.mpc): the lift of
bench_lift_ocp (40 kg, 20 s scenario) with careful motion on (the controller's default) and off, transcribed as
the receding-horizon controller does (mpc.controller.controller_ocp: the winding limit and the hold band never on
the measured x_0, mpc.controller.free_present; the limit's soft back-off band; careful motion's rows soft), with
the lift's integrator (rk4_4, as the earlier figures) and the controller's own (rk4: cases ``*_rk4``), under
140 °C (limit inactive) and 94 °C (limit active in every prediction: it binds near the end of the hold, inside
the 200-knot horizon).
Closed loop over ``--steps`` steps from the start: the plant is the model's own step with DDP's first current,
then a velocity disturbance (1e-2 rad/s, seeded); at each step every solver solves the same problem (the
measured state, the per-knot reference moved on by one knot, its last knot repeated), warm-started from its
own previous solution shifted by one knot. DDP's first plan: the rungs of the controller's start
(tasks.attempts.SolverLadder) at ``COLD_ITERATIONS`` (at the period's 50, careful motion at 94 °C found none);
then DDP with the controller's warm start (trajectories, AL multipliers and penalty, ``shifted_warm_start``)
and settings (``mpc_ddp_settings``); IPOPT with primal and dual (warm_start_init_point), the stage blocks of
its multipliers shifted the same way; fatrop with the primal only.
Each step's solve is repeated ``--repeats`` times (median); reported: median and worst step over the loop,
iterations, DDP's passes per step, the ratio IPOPT / DDP, and DDP's first current and cost against IPOPT's.

    python benchmarks/bench_mpc_step.py [--steps 30] [--repeats 3] [--quick]
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics

import numpy as np

from _common import write
from _ocp_bench import lift_problem, shifted_nlp_warm_start, timed_cpu
from thermo_ddp.tasks.lift import LiftSettings, initial_guess, make_solver
from thermo_ddp.mpc import MPCSettings
from thermo_ddp.mpc.controller import controller_ocp, free_present, mpc_ddp_settings, shifted_warm_start
from thermo_ddp.tasks.attempts import SolverLadder

KNOTS = 200
LIMITS_C = {"limit_inactive_140c": 140.0, "limit_active_94c": 94.0}
CAREFUL = {"careful": True, "plain": False}  # careful motion on (the controller's default) or off
CONTROLLER = MPCSettings()
# The lift's integrator (rk4_4: the earlier figures) and the controller's own (ControllerSettings.integrator, rk4)
INTEGRATORS = {"": LiftSettings().integrator, "_rk4": CONTROLLER.controller.integrator}
SOLVERS = ("ddp", "ipopt", "fatrop")
PASSES = ("backward_passes", "forward_passes", "gradient_passes", "multiplier_updates")
VELOCITY_DISTURBANCE = 1e-2  # rad/s, standard deviation
COLD_ITERATIONS = 200  # DDP's first plan (untimed; made before moving): the re-solves' settings, this iteration cap


def controller_problem(limit_c: float, careful: bool, integrator: str):
    """The bench's lift as the controller transcribes it (no row on x_0, soft back-off, soft motion rows)."""
    lp = lift_problem(KNOTS, limit_c, careful_motion=careful, integrator=integrator)
    return dataclasses.replace(lp, problem=controller_ocp(lp.problem, CONTROLLER))


def warm_start(name: str, result, problem):
    if name == "ddp":  # the controller's
        return shifted_warm_start(result, problem, 1, CONTROLLER.controller.warm_penalty_max)
    return shifted_nlp_warm_start(result, problem, shift=1)


def mpc_loop(limit_c: float, careful: bool, integrator: str, steps: int, repeats: int) -> dict:
    lp = controller_problem(limit_c, careful, integrator)
    solvers = {name: make_solver(lp, name) for name in SOLVERS}
    solvers["ddp"] = make_solver(lp, "ddp", mpc_ddp_settings(CONTROLLER.controller.max_iterations))  # the controller's
    lp = dataclasses.replace(lp, params=free_present(lp.params, lp.problem.parameters))
    first = {name: s.solve(lp.x0, lp.params, initial_guess(lp)) for name, s in solvers.items() if name != "ddp"}
    ladder = SolverLadder(lp.problem, make_solver(lp, "ddp", mpc_ddp_settings(COLD_ITERATIONS)))
    first["ddp"] = ladder.solve(lp, initial_guess(lp), reference=False).result
    long_params = np.vstack([lp.params, np.repeat(lp.params[-1:], steps, axis=0)])
    rng = np.random.default_rng(0)
    step = lp.problem.functions.step
    winding = lp.model.node_indices("winding")
    x, prev = lp.x0, first
    per_step = {name: [] for name in SOLVERS}
    active_steps = 0
    for j in range(1, steps + 1):
        x = np.asarray(step(x, prev["ddp"].us[0], long_params[j - 1])).ravel()
        x[1] += VELOCITY_DISTURBANCE * rng.standard_normal()
        params = free_present(long_params[j: j + KNOTS + 1], lp.problem.parameters)  # as the controller's window
        now = {}
        for name, solver in solvers.items():
            warm = warm_start(name, prev[name], lp.problem)
            if j == 1:
                solver.solve(x, params, warm)  # untimed: IPOPT builds its dual-warm-start instance here
            result, timing = timed_cpu(lambda: solver.solve(x, params, warm), repeats)
            per_step[name].append({**timing, "iterations": int(result.iterations), "status": result.status,
                                   "cost": float(result.cost), "first_current_a": float(result.us[0, 0]),
                                   "max_violation": float(result.max_constraint_violation),
                                   **{k: result.info[k] for k in PASSES if k in result.info}})
            now[name] = result
        if np.max(now["ddp"].xs[:, winding]) >= limit_c - 1e-2:  # at the planning limit (or in the soft band)
            active_steps += 1
        prev = now
    out = {"steps": steps, "repeats": repeats, "integrator": integrator,
           "winding_limit_binding_in_prediction_steps": active_steps}
    for name in SOLVERS:
        rows = per_step[name]
        walls = [r["wall_median_s"] for r in rows]
        out[name] = {"cold_first_s": first[name].solve_s, "cold_first_iterations": int(first[name].iterations),
                     "warm_step_median_s": statistics.median(walls), "warm_step_max_s": max(walls),
                     "warm_step_solver_median_s": statistics.median(r["solver_median_s"] for r in rows),
                     "warm_step_cpu_median_s": statistics.median(r["cpu_median_s"] for r in rows),
                     "iterations_median": statistics.median(r["iterations"] for r in rows),
                     "iterations_max": max(r["iterations"] for r in rows),
                     "all_converged": all(r["status"] == "converged" for r in rows),
                     "max_violation": max(r["max_violation"] for r in rows), "per_step": rows}
    ddp = out["ddp"]["warm_step_median_s"]
    for name in SOLVERS[1:]:
        out[f"{name}_over_ddp_median"] = out[name]["warm_step_median_s"] / ddp
    costs = np.array([[r["cost"] for r in per_step[name]] for name in SOLVERS])
    out["cost_rel_diff_ddp_vs_ipopt_max"] = float(np.max(np.abs(costs[0] - costs[1]) / np.abs(costs[1])))
    currents = np.array([[r["first_current_a"] for r in per_step[name]] for name in SOLVERS[:2]])
    out["first_current_diff_ddp_vs_ipopt_max_a"] = float(np.max(np.abs(currents[0] - currents[1])))
    out["ddp"]["passes_mean"] = {k: float(np.mean([r[k] for r in per_step["ddp"]])) for k in PASSES}
    worst, ipopt = out["ddp"]["warm_step_max_s"], out["ipopt"]
    print(f"  {integrator}, careful motion {'on' if careful else 'off'}, limit {limit_c:g} °C: DDP warm step median "
          f"{1e3 * ddp:.2f} ms (max {1e3 * worst:.2f} ms, "
          f"{out['ddp']['iterations_median']:g} it), IPOPT {1e3 * ipopt['warm_step_median_s']:.1f} ms "
          f"({ipopt['iterations_median']:g} it), ratio {out['ipopt_over_ddp_median']:.1f}", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="10 steps, one solve each")
    args = parser.parse_args()
    steps, repeats = (10, 1) if args.quick else (args.steps, args.repeats)
    cases = {f"{motion}_{label}{tag}": mpc_loop(limit_c, careful, integrator, steps, repeats)
             for tag, integrator in INTEGRATORS.items()
             for motion, careful in CAREFUL.items() for label, limit_c in LIMITS_C.items()}
    write("mpc_step", {"description": "one warm MPC step (shifted by one knot), elbow + thermal lift, N=200, "
                                      "dt=0.1 s, the controller's problem with careful motion on and off: DDP vs IPOPT vs "
                                      "fatrop, medians over a closed loop",
                       "knots": KNOTS, "integrator": LiftSettings().integrator,
                       "controller_integrator": CONTROLLER.controller.integrator, "cases": cases})


if __name__ == "__main__":
    main()
