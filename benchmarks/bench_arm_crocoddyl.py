"""The unconstrained Talos left arm (rigid body only): our DDP against crocoddyl's SolverFDDP.

Both sides: the same URDF (example-robot-data 6 talos_reduced.urdf from this venv), the same reduced
model (every other joint locked at the angle thermo_ddp.model.arm.build_arm locks it, armature N^2 B_m from
models/*.toml), 1 joint (elbow) and 7 joints, N = 100, dt = 0.01 s, the same integrator: crocoddyl's
IntegratedActionModelEuler, i.e. semi-implicit Euler v+ = v + dt a, q+ = q + dt v+ (written here in
CasADi with analytic Jacobians from thermo_ddp.model.rigid_body), state and control costs only
(crocoddyl ResidualModelState / ResidualModelControl; no frame costs), the same initial guess
(x0 at every knot, zero torques). Before timing, one rollout of random torques and its cost are
compared between the two sides. Ours: DDPSolver, Gauss-Newton (as FDDP), compiled C backend.

crocoddyl cannot share the project venv (it pins example-robot-data 5), so its side runs in
.venv-croco (created here on first use with the pins of requirements-croco.txt; or set
$CROCODDYL_PYTHON) as a subprocess (_croco_side.py) that prints JSON.

    python benchmarks/bench_arm_crocoddyl.py [--repeats 7] [--quick]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np

from _common import write
from thermo_ddp.model.actuated import load_model
from thermo_ddp.model.arm import ELBOW, LEFT_ARM, robots_dir
from thermo_ddp.ocp import Cost, OptimalControlProblem
from thermo_ddp.model.rigid_body import RigidBodyDynamics
from thermo_ddp.solvers import DDPSettings, DDPSolver

HERE = Path(__file__).resolve().parent
CROCO_VENV = HERE.parent / ".venv-croco"
N, DT = 100, 0.01
W_STATE, W_CONTROL, W_TERMINAL = 1.0, 1e-3, 100.0
TARGET_RAD = {"arm_left_1_joint": 0.4, "arm_left_2_joint": 0.3, "arm_left_3_joint": 0.2, "arm_left_4_joint": -0.8,
              "arm_left_5_joint": 0.2, "arm_left_6_joint": 0.1, "arm_left_7_joint": 0.1}
CASES = {"1_joint": (ELBOW,), "7_joints": LEFT_ARM}
TH_STOP = 1e-9  # crocoddyl's default stopping threshold


def croco_python() -> str:
    """$CROCODDYL_PYTHON, else .venv-croco (created with the pinned requirements when missing)."""
    if os.environ.get("CROCODDYL_PYTHON"):
        return os.environ["CROCODDYL_PYTHON"]
    python = CROCO_VENV / "bin" / "python"
    if not python.exists():
        print(f"creating {CROCO_VENV} (crocoddyl, pinned in requirements-croco.txt)", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(CROCO_VENV)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "-r", str(HERE / "requirements-croco.txt")],
                       check=True)
    return str(python)


def run_croco(spec: dict) -> dict:
    done = subprocess.run([croco_python(), str(HERE / "_croco_side.py")], input=json.dumps(spec), text=True,
                          capture_output=True)
    if done.returncode:
        raise RuntimeError(f"crocoddyl side failed:\n{done.stderr}")
    return json.loads(done.stdout)


def arm_ocp(joints) -> tuple[OptimalControlProblem, dict]:
    """Our problem and the spec that rebuilds the identical one in crocoddyl."""
    arm = load_model(joints).arm  # reduced Talos, armature from models/*.toml, no payload
    model, nq = arm.model, arm.nv
    rbd = RigidBodyDynamics(model)
    x, u, p = ca.SX.sym("x", 2 * nq), ca.SX.sym("tau", nq), ca.SX.sym("p", 0)
    q, v = x[:nq], x[nq:]
    acc, da_dq, da_dv, minv = rbd.aba_derivatives(q, v, u)
    v_next = v + DT * acc
    x_next = ca.vertcat(q + DT * v_next, v_next)
    eye = ca.SX.eye(nq)
    dv_dx = ca.horzcat(DT * da_dq, eye + DT * da_dv)  # d v_next / d x
    A = ca.vertcat(ca.horzcat(eye, ca.SX.zeros(nq, nq)) + DT * dv_dx, dv_dx)
    B = ca.vertcat(DT * DT * minv, DT * minv)
    names = ["x", "u", "p"]
    step = ca.Function("semi_implicit_euler", [x, u, p], [x_next], names, ["x_next"])
    jac = ca.Function("semi_implicit_euler_jacobians", [x, u, p], [x_next, A, B], names, ["x_next", "A", "B"])
    x0 = np.zeros(2 * nq)
    target = np.concatenate([[TARGET_RAD[j] for j in arm.joints], np.zeros(nq)])
    costs = [Cost("state", W_STATE * DT, ca.Function("r", [x, u], [x - target], ["x", "u"], ["r"])),
             Cost("control", W_CONTROL * DT, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))]
    terminal = [Cost("terminal_state", W_TERMINAL, ca.Function("r", [x], [x - target], ["x"], ["r"]))]
    problem = OptimalControlProblem(step, N, costs, terminal, name=f"talos_arm_{nq}", dynamics_jacobians=jac)
    spec = {"urdf": str(robots_dir() / arm.settings.robot), "locked_joints": dict(arm.locked_joints),
            "joints": list(arm.joints), "armature": {j: float(model.armature[i]) for i, j in enumerate(arm.joints)},
            "dt": DT, "N": N, "x0": x0.tolist(), "x_ref": target.tolist(), "w_state": W_STATE,
            "w_control": W_CONTROL, "w_terminal": W_TERMINAL, "th_stop": TH_STOP}
    return problem, spec


def check_same_problem(problem: OptimalControlProblem, solver: DDPSolver, spec: dict) -> dict:
    """Roll out the same random torques on both sides; compare states and total cost."""
    rng = np.random.default_rng(1)
    us = 5.0 * rng.standard_normal((N, problem.nu))
    x0 = np.asarray(spec["x0"])
    xs = np.vstack([x0, np.array(problem.dynamics.mapaccum(N)(x0, us.T, np.zeros((0, N)))).T])
    ours_cost = solver.backend.evaluate(xs, us, np.zeros((N + 1, 0)))[0]
    theirs = run_croco({**spec, "mode": "check", "us": us.tolist()})
    diff = float(np.max(np.abs(np.asarray(theirs["xs"]) - xs)))
    out = {"rollout_max_abs_diff": diff, "rollout_max_abs_state": float(np.max(np.abs(xs))),
           "cost_ours": ours_cost, "cost_crocoddyl": theirs["cost"],
           "cost_rel_diff": abs(ours_cost - theirs["cost"]) / abs(theirs["cost"])}
    if diff > 1e-8 * max(1.0, out["rollout_max_abs_state"]) or out["cost_rel_diff"] > 1e-10:
        raise RuntimeError(f"the two sides do not compute the same problem: {out}")
    return out


def bench_ours(problem: OptimalControlProblem, solver: DDPSolver, x0, repeats: int, number: int) -> dict:
    walls, res = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        res = solver.solve(x0)
        walls.append(time.perf_counter() - start)
    solve = {"wall_median_s": statistics.median(walls), "wall_min_s": min(walls), "repeats": repeats,
             "iterations": int(res.iterations), "cost": float(res.cost), "status": res.status,
             "stationarity": float(res.history["stationarity"][-1])}
    solve["per_iteration_s"] = solve["wall_median_s"] / max(solve["iterations"], 1)
    # one iteration from the same initial guess as crocoddyl's: backward (with derivatives) + forward pass
    be, P = solver.backend, np.zeros((N + 1, 0))
    X, U = np.tile(x0, (N + 1, 1)), np.zeros((N, problem.nu))
    lam, lamN, C = np.zeros((N, 0)), np.zeros(0), be.evaluate(X, U, P)[3]
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(number):
            policy = be.backward(X, U, P, lam, lamN, C, 1.0, 0.0)[0]
            be.forward(X, U, P, policy, C, 1.0)
        samples.append((time.perf_counter() - start) / number)
    return {"build_s": solver.build_s, "solve": solve,
            "iteration": {"median_s": statistics.median(samples), "min_s": min(samples), "number": number}}


def bench_case(joints, repeats: int, number: int) -> dict:
    problem, spec = arm_ocp(joints)
    solver = DDPSolver(problem, DDPSettings(backend="codegen", max_iterations=500))
    check = check_same_problem(problem, solver, spec)
    ours = bench_ours(problem, solver, np.asarray(spec["x0"]), repeats, number)
    theirs = run_croco({**spec, "mode": "bench", "repeats": repeats, "number": number, "max_iterations": 500})
    out = {"nx": problem.nx, "nu": problem.nu, "check": check, "ours": ours, "crocoddyl": theirs,
           "iteration_ours_over_crocoddyl": ours["iteration"]["median_s"] / theirs["iteration"]["median_s"],
           "solve_ours_over_crocoddyl": ours["solve"]["wall_median_s"] / theirs["solve"]["wall_median_s"],
           "per_iteration_in_solve_ours_over_crocoddyl":
               ours["solve"]["per_iteration_s"] / theirs["solve"]["per_iteration_s"],
           "cost_rel_diff": abs(ours["solve"]["cost"] - theirs["solve"]["cost"]) / abs(theirs["solve"]["cost"])}
    print(f"  {problem.nu} joint(s): iteration ours {1e3 * ours['iteration']['median_s']:.3f} ms, crocoddyl "
          f"{1e3 * theirs['iteration']['median_s']:.3f} ms (ratio {out['iteration_ours_over_crocoddyl']:.2f}); "
          f"solve ours {1e3 * ours['solve']['wall_median_s']:.2f} ms / {ours['solve']['iterations']} it, crocoddyl "
          f"{1e3 * theirs['solve']['wall_median_s']:.2f} ms / {theirs['solve']['iterations']} it; "
          f"rollout diff {check['rollout_max_abs_diff']:.1e}", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="3 repeats of 5 iterations")
    args = parser.parse_args()
    repeats, number = (3, 5) if args.quick else (args.repeats, 20)
    cases = {label: bench_case(joints, repeats, number) for label, joints in CASES.items()}
    write("arm_crocoddyl", {"description": "unconstrained Talos arm, N=100, dt=0.01 s, semi-implicit Euler, "
                                           "state + control cost: DDPSolver (Gauss-Newton, codegen) vs crocoddyl "
                                           "SolverFDDP (nthreads=1); medians", "casadi": ca.__version__,
                            "cases": cases})


if __name__ == "__main__":
    main()
