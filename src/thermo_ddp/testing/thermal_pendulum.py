"""A small example of the OCP API: the "thermal pendulum", used by the solver tests and benchmarks.

A 1-DOF pendulum driven by a current u, torque = k u - m g l sin(q) - b v, and a winding temperature
(one node, or winding -> casing -> ambient with a drive heating the casing). Constraints: winding
T <= t_max, voltage |R(T) u + kb v| <= Vmax, box |u| <= umax. Goal: track the angle given as the
per-knot parameter.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..ocp import Constraint, Cost, OptimalControlProblem

# toy constants (SI); chosen so the limits bite within a 2 s horizon
MASS, LENGTH, GRAV, DAMP = 1.0, 0.5, 9.81, 0.1
INERTIA = MASS * LENGTH ** 2 + 0.05
K_TORQUE, K_BEMF = 2.0, 2.0
R0, ALPHA_CU, T_AMB, R_TH, CAP = 1.0, 0.00393, 25.0, 2.0, 0.5
U_MAX, V_MAX = 4.0, 6.0


def thermal_pendulum(horizon=100, dt=0.02, t_max=80.0, n_thermal=1):
    """OCP of the toy; states [q, v, T_winding (, T_casing, T_drive)], control current u, RK4 step."""
    nx = 2 + n_thermal
    x, u, p = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("p")
    q, v, tw = x[0], x[1], x[2]
    resistance = R0 * (1 + ALPHA_CU * (tw - T_AMB))
    acc = (K_TORQUE * u - MASS * GRAV * LENGTH * ca.sin(q) - DAMP * v) / INERTIA
    if n_thermal == 1:
        temps = [(resistance * u ** 2 - (tw - T_AMB) / R_TH) / CAP]
    else:
        tc, td = x[3], x[4]
        temps = [(resistance * u ** 2 - (tw - tc) / 0.5) / CAP,
                 ((tw - tc) / 0.5 + (td - tc) / 2.0 - (tc - T_AMB) / 1.5) / 20.0,
                 (0.5 + 0.05 * u ** 2 - (td - tc) / 2.0) / 5.0]
    ode = ca.Function("ode", [x, u], [ca.vertcat(v, acc, *temps)], ["x", "u"], ["xdot"])
    k1 = ode(x, u)
    k2 = ode(x + dt / 2 * k1, u)
    k3 = ode(x + dt / 2 * k2, u)
    k4 = ode(x + dt * k3, u)
    step = ca.Function("step", [x, u, p], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)], ["x", "u", "p"], ["x_next"])
    voltage = resistance * u + K_BEMF * v
    costs = [Cost("goal", 10.0, ca.Function("r", [x, u, p], [q - p], ["x", "u", "p"], ["r"])),
             Cost("velocity", 0.1, ca.Function("r", [x, u, p], [v], ["x", "u", "p"], ["r"])),
             Cost("current", 0.05, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))]
    terminal = [Cost("goal_end", [100.0, 10.0], ca.Function("r", [x, p], [ca.vertcat(q - p, v)], ["x", "p"], ["r"]))]
    constraints = [Constraint("winding", ca.Function("g", [x, u], [tw - t_max], ["x", "u"], ["g"])),
                   Constraint("voltage", ca.Function("g", [x, u], [ca.vertcat(voltage - V_MAX, -voltage - V_MAX)],
                                                     ["x", "u"], ["g"]))]
    terminal_constraints = [Constraint("winding_end", ca.Function("g", [x, p], [tw - t_max], ["x", "p"], ["g"]))]
    return OptimalControlProblem(step, horizon, costs, terminal, constraints, terminal_constraints,
                                 u_lb=[-U_MAX], u_ub=[U_MAX], name="thermal_pendulum")


def x0_of(n_thermal: int = 1) -> np.ndarray:
    """Start at rest, hanging, every thermal node 5 K above ambient."""
    return np.array([0.0, 0.0] + [T_AMB + 5.0] * n_thermal)
