"""The crocoddyl side of bench_arm_crocoddyl.py; runs in the separate crocoddyl venv (no thermo_ddp there).

Reads one JSON spec on stdin (URDF path, locked joints and angles, armature, dt, N, x0, target,
weights, mode) and prints one JSON object:
- mode "check": the rollout of the given controls and the problem's total cost on it;
- mode "bench": SolverFDDP to convergence (median wall time of ``solve``, iterations, cost) and the
  time of one iteration (computeDirection + tryStep(1), i.e. derivatives, backward and forward pass).
The model is rebuilt exactly as thermo_ddp.model.arm.build_arm does (reduced model, then armature).
"""
from __future__ import annotations

import json
import statistics
import sys
import time

import crocoddyl
import numpy as np
import pinocchio as pin


def reduced_model(spec: dict) -> pin.Model:
    full = pin.buildModelFromUrdf(spec["urdf"])
    q_lock = pin.neutral(full)
    for name, angle in spec["locked_joints"].items():
        q_lock[full.joints[full.getJointId(name)].idx_q] = angle
    model = pin.buildReducedModel(full, [full.getJointId(n) for n in spec["locked_joints"]], q_lock)
    for name, value in spec["armature"].items():
        model.armature[model.getJointId(name) - 1] = value
    if list(model.names[1:]) != spec["joints"]:
        raise SystemExit(f"reduced model joints {list(model.names[1:])} != {spec['joints']}")
    return model


def shooting_problem(spec: dict) -> crocoddyl.ShootingProblem:
    """Semi-implicit Euler (IntegratedActionModelEuler) of free forward dynamics, full actuation;
    cost dt * (w_x/2 |x - x_ref|^2 + w_u/2 |u|^2) per knot, w_T/2 |x_N - x_ref|^2 at the end."""
    model = reduced_model(spec)
    state = crocoddyl.StateMultibody(model)
    actuation = crocoddyl.ActuationModelFull(state)
    target = np.asarray(spec["x_ref"])

    def action(w_x: float, w_u: float, dt: float):
        costs = crocoddyl.CostModelSum(state, actuation.nu)
        costs.addCost("state", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelState(state, target,
                                                                                              actuation.nu)), w_x)
        if w_u:
            costs.addCost("control", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(
                state, actuation.nu)), w_u)
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs)
        return crocoddyl.IntegratedActionModelEuler(dam, dt)

    running = action(spec["w_state"], spec["w_control"], spec["dt"])
    problem = crocoddyl.ShootingProblem(np.asarray(spec["x0"]), [running] * spec["N"],
                                        action(spec["w_terminal"], 0.0, 0.0))
    problem.nthreads = 1  # our DDP is single-threaded
    return problem


def check(spec: dict) -> dict:
    problem = shooting_problem(spec)
    us = [np.asarray(u) for u in spec["us"]]
    xs = problem.rollout(us)
    return {"xs": [x.tolist() for x in xs], "cost": float(problem.calc(xs, us))}


def initial_guess(spec: dict):
    x0 = np.asarray(spec["x0"])
    nu = len(spec["joints"])
    return [x0.copy() for _ in range(spec["N"] + 1)], [np.zeros(nu) for _ in range(spec["N"])]


def bench(spec: dict) -> dict:
    problem = shooting_problem(spec)
    walls, solver = [], None
    for _ in range(spec["repeats"]):
        solver = crocoddyl.SolverFDDP(problem)
        solver.th_stop = spec["th_stop"]
        xs, us = initial_guess(spec)
        start = time.perf_counter()
        solver.solve(xs, us, spec["max_iterations"], False)
        walls.append(time.perf_counter() - start)
    solve = {"wall_median_s": statistics.median(walls), "wall_min_s": min(walls), "repeats": spec["repeats"],
             "iterations": int(solver.iter), "cost": float(solver.cost), "stop": float(solver.stop),
             "converged": bool(solver.stop <= spec["th_stop"])}
    solve["per_iteration_s"] = solve["wall_median_s"] / max(solve["iterations"], 1)
    # one iteration from the initial guess, repeated: calcDiff + backward pass, then the forward pass
    it_solver = crocoddyl.SolverFDDP(problem)
    xs, us = initial_guess(spec)
    it_solver.setCandidate(xs, us, False)
    it_solver.computeDirection(True)
    samples = []
    for _ in range(spec["repeats"]):
        start = time.perf_counter()
        for _ in range(spec["number"]):
            it_solver.computeDirection(True)
            it_solver.tryStep(1.0)
        samples.append((time.perf_counter() - start) / spec["number"])
    iteration = {"median_s": statistics.median(samples), "min_s": min(samples), "number": spec["number"]}
    return {"version": crocoddyl.__version__, "pinocchio": pin.__version__, "numpy": np.__version__,
            "solve": solve, "iteration": iteration}


if __name__ == "__main__":
    spec = json.load(sys.stdin)
    print(json.dumps(check(spec) if spec["mode"] == "check" else bench(spec)))
