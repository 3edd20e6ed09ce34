"""Benchmark the DDP backends (codegen C, CasADi VM, numpy) against IPOPT.

Cases (medians over repeated runs, written to benchmarks/results/ddp_backends.json):
1. mpc: warm MPC re-solves of the 5-state thermal pendulum toy (thermo_ddp.testing.thermal_pendulum, also used by
   tests/test_ddp_vs_ipopt.py; n_thermal=3), N=200, winding limit and voltage limit active; closed loop over
   ``--mpc-steps`` steps, each warm-started from the shifted previous solution; IPOPT is
   warm-started the same way (primal + dual). Ratio ipopt / ddp per step.
   mpc_severe: the same with a limit so tight that the lift stops short.
2. scaling: one backward + forward pass of the same problem for N = 100..800 (codegen).
3. arm: unconstrained 7-DOF Talos left arm (example-robot-data URDF talos_left_arm.urdf,
   CasADi ABA from thermo_ddp.model.rigid_body), nx=14, nu=7, N=100, RK4: time per iteration (one backward and
   one forward pass) per backend. (crocoddyl on the same arm: bench_arm_crocoddyl.py.)

Usage: python benchmarks/bench_ddp_backends.py [--quick]
"""
from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np

from _common import write
from thermo_ddp.testing.thermal_pendulum import T_AMB, thermal_pendulum
from thermo_ddp.ocp import Cost, OptimalControlProblem
from thermo_ddp.solvers import DDPSettings, DDPSolver, IpoptSolver, WarmStart

X0 = np.array([0.0, 0.0, T_AMB + 5.0, T_AMB + 5.0, T_AMB + 5.0])
LIMIT_C = 32.5  # winding limit active during the hold, goal still reached
SEVERE_C = 32.0  # limit so tight that the lift stops short (two local optima)


def median_time(fun, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fun()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def mpc_loop(solver, problem, params, steps, warm_kind):
    """Closed loop on the model itself with a small disturbance; returns per-step results."""
    first = solver.solve(X0, params)
    plant = problem.functions.step
    x, prev, out = X0.copy(), first, []
    rng = np.random.default_rng(0)
    for _ in range(steps):
        x = np.asarray(plant(x, prev.us[0], params[0])).ravel() + 1e-3 * rng.standard_normal(x.size) * [1, 1, 0, 0, 0]
        warm = WarmStart.from_result(prev, shift=1)
        if warm_kind == "ipopt":
            warm = WarmStart(warm.xs, warm.us, prev.multipliers)  # IPOPT duals (not shifted)
        prev = solver.solve(x, params, warm_start=warm)
        out.append(prev)
    return first, out


def bench_mpc(steps, quick, limit_c=LIMIT_C):
    N = 200
    problem = thermal_pendulum(horizon=N, t_max=limit_c, n_thermal=3)
    params = np.full((N + 1, 1), 2.0)
    report = {"problem": "thermal pendulum toy, nx=5, nu=1, N=200, RK4 dt=0.02",
              "limit_c": limit_c, "steps": steps, "runs": {}}
    ipopt = IpoptSolver(problem)
    first, runs = mpc_loop(ipopt, problem, params, steps, "ipopt")
    ipopt_cold = first
    ip_med = float(np.median([r.solve_s for r in runs]))
    report["runs"]["ipopt"] = {"cold_s": first.solve_s, "warm_median_s": ip_med,
                               "warm_median_iterations": float(np.median([r.iterations for r in runs])),
                               "all_success": all(r.success for r in runs)}
    backends = ["codegen", "casadi"] + ([] if quick else ["numpy"])
    for backend in backends:
        for full in (True, False):
            solver = DDPSolver(problem, DDPSettings(backend=backend, full_second_order=full))
            n = steps if backend != "numpy" else min(steps, 3)
            first, runs = mpc_loop(solver, problem, params, n, "ddp")
            med = float(np.median([r.solve_s for r in runs]))
            cold_gap = abs(first.cost - ipopt_cold.cost) / ipopt_cold.cost
            report["runs"][f"ddp_{backend}_{'full' if full else 'gn'}"] = {
                "build_s": solver.build_s, "cold_s": first.solve_s, "cold_iterations": first.iterations,
                "cold_success": first.success, "cold_cost_rel_diff_vs_ipopt": cold_gap,
                "warm_median_s": med, "warm_max_s": float(np.max([r.solve_s for r in runs])),
                "warm_median_iterations": float(np.median([r.iterations for r in runs])),
                "all_success": all(r.success for r in runs), "speedup_vs_ipopt_warm": ip_med / med,
                "winding_max_c": float(max(r.xs[:, 2].max() for r in runs))}
    return report


def bench_scaling(repeats):
    out = {}
    for N in (100, 200, 400, 800):
        problem = thermal_pendulum(horizon=N, t_max=LIMIT_C, n_thermal=3)
        solver = DDPSolver(problem, DDPSettings(backend="codegen", full_second_order=True))
        params = np.full((N + 1, 1), 2.0)
        X, U = np.tile(X0, (N + 1, 1)), np.full((N, 1), 1.0)
        lam, lamN, C = np.zeros((N, 3)), np.zeros(1), np.zeros((N, 5))
        be = solver.backend
        policy = be.backward(X, U, params, lam, lamN, C, 10.0, 0.0)[0]
        t_b = median_time(lambda: be.backward(X, U, params, lam, lamN, C, 10.0, 0.0), repeats)
        t_f = median_time(lambda: be.forward(X, U, params, policy, C, 1.0), repeats)
        out[str(N)] = {"backward_s": t_b, "forward_s": t_f, "iteration_s": t_b + t_f}
    out["ratio_800_over_100"] = out["800"]["iteration_s"] / out["100"]["iteration_s"]
    return out


def arm_urdf() -> str:
    from thermo_ddp.model.arm import robots_dir

    return str(robots_dir() / "talos_data/robots/talos_left_arm.urdf")


def arm_problem(N=100, dt=0.01, analytic=True):
    """Talos left arm, RK4; with ``analytic`` the step Jacobians come from the ABA derivative
    identity (thermo_ddp.model.rigid_body) through the RK4 stages, as the project's models provide."""
    import pinocchio as pin
    from thermo_ddp.model.integrators import rk4_step, rk4_step_jacobians
    from thermo_ddp.model.rigid_body import RigidBodyDynamics

    model = pin.buildModelFromUrdf(arm_urdf())
    rbd = RigidBodyDynamics(model)
    nq = model.nq
    x, u, p = ca.SX.sym("x", 2 * nq), ca.SX.sym("u", nq), ca.SX.sym("p", 0)
    acc, da_dq, da_dv, minv = rbd.aba_derivatives(x[:nq], x[nq:], u)
    zeros, eye = ca.SX.zeros(nq, nq), ca.SX.eye(nq)
    ode = ca.Function("ode", [x, u, p], [ca.vertcat(x[nq:], acc)], ["x", "u", "p"], ["xdot"])
    ode_jac = ca.Function("ode_jac", [x, u, p], [ca.vertcat(x[nq:], acc), ca.blockcat([[zeros, eye], [da_dq, da_dv]]),
                                                 ca.vertcat(zeros, minv)], ["x", "u", "p"], ["xdot", "A", "B"])
    step = rk4_step(ode, dt)
    jacobians = rk4_step_jacobians(ode_jac, dt) if analytic else None
    target = np.concatenate([np.full(nq, 0.3), np.zeros(nq)])
    costs = [Cost("state", 1.0, ca.Function("r", [x, u], [x - target], ["x", "u"], ["r"])),
             Cost("control", 1e-3, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))]
    terminal = [Cost("terminal", 100.0, ca.Function("r", [x], [x - target], ["x"], ["r"]))]
    return OptimalControlProblem(step, N, costs, terminal, name="talos_arm", dynamics_jacobians=jacobians), model


def bench_arm(repeats, quick):
    problem, model = arm_problem()
    nx, N = problem.nx, problem.horizon
    x0 = np.zeros(nx)
    out = {"problem": "talos_arm 7-DOF, nx=14, nu=7, N=100, RK4 dt=0.01, unconstrained Gauss-Newton"}
    for backend in ["codegen", "casadi"] + ([] if quick else ["numpy"]):
        solver = DDPSolver(problem, DDPSettings(backend=backend, max_iterations=50))
        res = solver.solve(x0)
        be = solver.backend
        X, U, P = res.xs, res.us, np.zeros((N + 1, 0))
        lam, lamN, C = np.zeros((N, 0)), np.zeros(0), np.zeros((N, nx))
        policy = be.backward(X, U, P, lam, lamN, C, 10.0, 0.0)[0]
        reps = repeats if backend != "numpy" else 2
        t_b = median_time(lambda: be.backward(X, U, P, lam, lamN, C, 10.0, 0.0), reps)
        t_f = median_time(lambda: be.forward(X, U, P, policy, C, 1.0), reps)
        out[backend] = {"build_s": solver.build_s, "backward_s": t_b, "forward_s": t_f, "iteration_s": t_b + t_f,
                        "solve_s": res.solve_s, "iterations": res.iterations, "status": res.status, "cost": res.cost}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mpc-steps", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--quick", action="store_true", help="skip the slow numpy backend")
    args = ap.parse_args()
    result = {"casadi": ca.__version__, "cases": {}}
    result["cases"]["mpc"] = bench_mpc(args.mpc_steps, args.quick)
    result["cases"]["mpc_severe"] = bench_mpc(args.mpc_steps, True, SEVERE_C)
    result["cases"]["scaling"] = bench_scaling(args.repeats)
    result["cases"]["arm"] = bench_arm(args.repeats, args.quick)
    write("ddp_backends", result)


if __name__ == "__main__":
    main()
