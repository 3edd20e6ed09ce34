"""An independent thermal replay of a plan: the oracle of the robust lift's tests and benchmark.

The contract's networks (one_node, two_node, two_node_drive; seed report eqs. 3, 5-8) written out by hand
in numpy from a parameter file, integrated by scipy's adaptive ``solve_ivp`` (RK45, tight tolerances) on
the plan's currents (held over each step) and speeds (linear between knots): no code shared with the
planner's network builder (:mod:`thermo_ddp.model.thermal`) or its RK4 step. A motor starts from given
(measured) temperatures, or from its own equilibrium at rest (no current, no motion: the drive's idle heat).
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from ..model.parameters import JointParameters


def _network(params: JointParameters):
    """(capacities (n,), conductance matrix G (n, n) with the ambient on the diagonal, g_amb (n,), nodes)."""
    th = params.thermal
    if th.model == "one_node":
        return np.array([th["capacity_j_per_k"]]), [], [("winding", th["resistance_k_per_w"])], ("winding",)
    nodes = ("winding", "casing") + (("drive",) if th.model == "two_node_drive" else ())
    caps = [th["winding_capacity_j_per_k"], th["casing_capacity_j_per_k"]]
    links = [("winding", "casing", th["winding_casing_k_per_w"])]
    ambient = [("casing", th["casing_ambient_k_per_w"])]
    if th.model == "two_node_drive":
        caps.append(th["drive_capacity_j_per_k"])
        links.append(("drive", "casing", th["drive_casing_k_per_w"]))
        ambient.append(("drive", th["drive_ambient_k_per_w"]))
    return np.array(caps), links, ambient, nodes


def _heat_w(params: JointParameters, nodes, temps, current_a: float, speed: float) -> np.ndarray:
    """Heat into each node: copper (R(T) i^2), drive (idle + k i^2), friction and iron losses."""
    m, th = params.motor, params.thermal
    q = np.zeros(len(nodes))
    w = nodes.index("winding")
    q[w] += m.resistance_ohm * (1 + m.copper_alpha_per_k * (temps[w] - m.resistance_ref_c)) * current_a ** 2
    drive = nodes.index("drive") if "drive" in nodes else nodes.index(th.sensor_node)
    q[drive] += th["drive_idle_w"] + th["drive_loss_w_per_a2"] * current_a ** 2
    friction_w = (m.viscous_friction_nm_s_per_rad * speed
                  + m.coulomb_friction_nm * np.tanh(speed / m.coulomb_smoothing_rad_s)) * speed
    q[nodes.index("casing") if "casing" in nodes else w] += th["friction_heating_fraction"] * friction_w
    q[nodes.index(th.friction_node)] += (th["friction_heat_linear_w_s_per_rad"] * abs(speed)
                                         + th["friction_heat_quadratic_w_s2_per_rad2"] * speed ** 2)
    q[w] += th["iron_loss_w"] * (abs(speed) / th["iron_loss_ref_speed_rad_s"]) ** th["iron_loss_speed_exponent"]
    return q


def _rhs(params: JointParameters):
    caps, links, ambient, nodes = _network(params)
    amb_c = params.thermal.ambient_c

    def rhs(temps, current_a, speed):
        flow = np.zeros(len(nodes))
        for a, b, r in links:
            f = (temps[nodes.index(a)] - temps[nodes.index(b)]) / r
            flow[nodes.index(a)] -= f
            flow[nodes.index(b)] += f
        for a, r in ambient:
            flow[nodes.index(a)] -= (temps[nodes.index(a)] - amb_c) / r
        return (flow + _heat_w(params, nodes, temps, current_a, speed)) / caps

    return rhs, nodes


def idle_temperatures(params: JointParameters) -> np.ndarray:
    """Every node's equilibrium at rest (the network is linear in T without current)."""
    rhs, nodes = _rhs(params)
    b = rhs(np.zeros(len(nodes)), 0.0, 0.0)
    a = np.column_stack([rhs(e, 0.0, 0.0) - b for e in np.eye(len(nodes))])
    return np.linalg.solve(a, -b)


def replay_winding_c(params: JointParameters, time_s, current_a, velocity_rad_s, start_c=None) -> np.ndarray:
    """The winding temperature at ``time_s`` (N+1,) of the motor ``params`` driven by ``current_a`` (N,)
    held over each step and ``velocity_rad_s`` (N+1,), from ``start_c`` (every node, the network's order:
    winding, casing, drive) or, when None, its equilibrium at rest."""
    rhs, nodes = _rhs(params)
    t, i, v = (np.asarray(a, float).ravel() for a in (time_s, current_a, velocity_rad_s))

    def f(time, temps):
        k = min(int(np.searchsorted(t, time, side="right")) - 1, i.size - 1)
        return rhs(temps, i[max(k, 0)], float(np.interp(time, t, v)))

    sol = solve_ivp(f, (t[0], t[-1]), idle_temperatures(params) if start_c is None else start_c, method="RK45", t_eval=t, rtol=1e-8, atol=1e-8,
                    max_step=float(np.min(np.diff(t))) / 2)
    if not sol.success:
        raise RuntimeError(f"independent replay failed: {sol.message}")
    return sol.y[nodes.index("winding")]
