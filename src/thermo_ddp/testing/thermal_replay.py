"""An independent thermal replay of a plan: the oracle of the robust lift's tests and benchmark.

The contract's networks (one_node, two_node, two_node_drive; seed report eqs. 3, 5-8) written out by hand
in numpy from parameter files, integrated by scipy's adaptive ``solve_ivp`` (RK45, tight tolerances) on
the plan's currents (held over each step) and speeds (linear between knots): no code shared with the
planner's network builder (:mod:`thermo_ddp.model.thermal`) or its RK4 step. Many motors of one network
are integrated at once (numpy arrays over the motors). A motor starts from given temperatures, from its
own equilibrium at rest (no current, no motion: the drive's idle heat), or with some nodes measured and
the others at its equilibrium given them.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from ..model.parameters import JointParameters


class _Networks:
    """M motors of one contract network as arrays over the motors."""

    def __init__(self, motors: list[JointParameters]):
        th = [m.thermal for m in motors]
        model = th[0].model
        if any(t.model != model for t in th):
            raise ValueError("every motor of one replay needs the same thermal model")

        def arr(key, section="thermal"):
            return np.array([(m.thermal[key] if section == "thermal" else getattr(m.motor, key)) for m in motors])

        if model == "one_node":
            self.nodes, caps = ("winding",), [arr("capacity_j_per_k")]
            self.links, self.ambient = [], [("winding", arr("resistance_k_per_w"))]
        else:
            self.nodes = ("winding", "casing") + (("drive",) if model == "two_node_drive" else ())
            caps = [arr("winding_capacity_j_per_k"), arr("casing_capacity_j_per_k")]
            self.links = [("winding", "casing", arr("winding_casing_k_per_w"))]
            self.ambient = [("casing", arr("casing_ambient_k_per_w"))]
        if model == "two_node_drive":
            caps.append(arr("drive_capacity_j_per_k"))
            self.links.append(("drive", "casing", arr("drive_casing_k_per_w")))
            self.ambient.append(("drive", arr("drive_ambient_k_per_w")))
        self.caps = np.column_stack(caps)
        self.ambient_c = np.array([t.ambient_c for t in th])
        self.m = {k: arr(k, "motor") for k in ("resistance_ohm", "copper_alpha_per_k", "resistance_ref_c",
                                               "viscous_friction_nm_s_per_rad", "coulomb_friction_nm",
                                               "coulomb_smoothing_rad_s")}
        self.t = {k: arr(k) for k in ("drive_idle_w", "drive_loss_w_per_a2", "friction_heating_fraction",
                                      "friction_heat_linear_w_s_per_rad", "friction_heat_quadratic_w_s2_per_rad2",
                                      "iron_loss_w", "iron_loss_ref_speed_rad_s", "iron_loss_speed_exponent")}
        self.drive = self.nodes.index("drive" if "drive" in self.nodes else th[0].sensor_node)
        self.friction_node = self.nodes.index(th[0].friction_node)
        self.casing = self.nodes.index("casing" if "casing" in self.nodes else "winding")

    def heat_w(self, temps: np.ndarray, current_a: float, speed: float) -> np.ndarray:
        """(M, nodes) heat: copper R(T) i^2, drive idle + k i^2, friction and iron losses."""
        m, t = self.m, self.t
        q = np.zeros_like(temps)
        q[:, 0] += m["resistance_ohm"] * (1 + m["copper_alpha_per_k"] * (temps[:, 0] - m["resistance_ref_c"])) * current_a ** 2
        q[:, self.drive] += t["drive_idle_w"] + t["drive_loss_w_per_a2"] * current_a ** 2
        friction_w = (m["viscous_friction_nm_s_per_rad"] * speed
                      + m["coulomb_friction_nm"] * np.tanh(speed / m["coulomb_smoothing_rad_s"])) * speed
        q[:, self.casing] += t["friction_heating_fraction"] * friction_w
        q[:, self.friction_node] += t["friction_heat_linear_w_s_per_rad"] * abs(speed) \
            + t["friction_heat_quadratic_w_s2_per_rad2"] * speed ** 2
        q[:, 0] += t["iron_loss_w"] * (abs(speed) / t["iron_loss_ref_speed_rad_s"]) ** t["iron_loss_speed_exponent"]
        return q

    def rhs(self, temps: np.ndarray, current_a: float, speed: float) -> np.ndarray:
        """dT/dt (M, nodes)."""
        flow = np.zeros_like(temps)
        for a, b, r in self.links:
            ia, ib = self.nodes.index(a), self.nodes.index(b)
            f = (temps[:, ia] - temps[:, ib]) / r
            flow[:, ia] -= f
            flow[:, ib] += f
        for a, r in self.ambient:
            ia = self.nodes.index(a)
            flow[:, ia] -= (temps[:, ia] - self.ambient_c) / r
        return (flow + self.heat_w(temps, current_a, speed)) / self.caps

    def idle(self, measured: dict[str, float] | None = None) -> np.ndarray:
        """(M, nodes) equilibrium at rest (linear in T without current); ``measured``: those nodes held at
        the given temperatures, the others at their equilibrium given them."""
        n, count = len(self.nodes), self.caps.shape[0]
        b = self.rhs(np.zeros((count, n)), 0.0, 0.0)
        a = np.stack([self.rhs(np.tile(e, (count, 1)), 0.0, 0.0) - b for e in np.eye(n)], axis=-1)
        fixed = [self.nodes.index(k) for k in (measured or {})]
        free = [i for i in range(n) if i not in fixed]
        out = np.zeros((count, n))
        out[:, fixed] = [measured[self.nodes[i]] for i in fixed] if fixed else 0.0
        rhs = -(b[:, free] + np.einsum("mij,mj->mi", a[:, free][:, :, fixed], out[:, fixed]))
        out[:, free] = np.linalg.solve(a[:, free][:, :, free], rhs[..., None])[..., 0]
        return out


def idle_temperatures(params: JointParameters, measured: dict[str, float] | None = None) -> np.ndarray:
    """Every node's equilibrium at rest of one motor; ``measured`` (``{"casing": 43.0}``): those nodes held at
    the given temperatures, the others at their equilibrium given them."""
    return _Networks([params]).idle(measured)[0]


def replay_winding_c(motors, time_s, current_a, velocity_rad_s, start_c=None) -> np.ndarray:
    """The winding temperature at ``time_s`` (M, N+1) of each motor of ``motors`` (parameter sets of one
    network; one set gives (N+1,)) driven by ``current_a`` (N,) held over each step and ``velocity_rad_s``
    (N+1,), from ``start_c``: every node (an array, the network's order: winding, casing, drive), some
    measured nodes by name (a dict, ``{"casing": 43.0}``: the others at each motor's equilibrium at rest given
    them) or, when None, each motor's own equilibrium at rest."""
    single = isinstance(motors, JointParameters)
    net = _Networks([motors] if single else list(motors))
    count, n = net.caps.shape
    t, i, v = (np.asarray(a, float).ravel() for a in (time_s, current_a, velocity_rad_s))

    def f(time, y):
        k = min(max(int(np.searchsorted(t, time, side="right")) - 1, 0), i.size - 1)
        return net.rhs(y.reshape(count, n), i[k], float(np.interp(time, t, v))).ravel()

    if start_c is None or isinstance(start_c, dict):
        start = net.idle(start_c)
    else:
        start = np.tile(np.asarray(start_c, float), (count, 1))
    sol = solve_ivp(f, (t[0], t[-1]), start.ravel(), method="RK45", t_eval=t, rtol=1e-8, atol=1e-8,
                    max_step=float(np.min(np.diff(t))) / 2)
    if not sol.success:
        raise RuntimeError(f"independent replay failed: {sol.message}")
    winding = sol.y[0::n]
    return winding[0] if single else winding
