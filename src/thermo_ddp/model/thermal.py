"""Lumped thermal networks: nodes with heat capacities, thermal resistances between nodes
(or to ambient), and named heat sources injected at nodes (seed report eqs. 6-8).

A network is data: adding a node, a link or a heat source needs no new code. Values may be
floats or CasADi symbols, so identification differentiates the same expressions the planner uses.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import casadi as ca
import numpy as np

from . import motor
from .parameters import ThermalParameters

AMBIENT = "ambient"


@dataclass(frozen=True)
class Link:
    """A thermal resistance between two nodes (``b`` may be ``"ambient"``)."""

    a: str
    b: str
    resistance_k_per_w: object


@dataclass(frozen=True)
class HeatSource:
    """Power ``gain * power[name] + constant_w`` injected at ``node``.

    ``name`` refers to a loss computed elsewhere (``joule_w``, ``friction_w``, ``current_sq_a2``).
    """

    node: str
    name: str | None
    gain: object = 1.0
    constant_w: object = 0.0


@dataclass(frozen=True)
class ThermalNetwork:
    nodes: tuple[str, ...]
    capacities_j_per_k: tuple[object, ...]
    links: tuple[Link, ...]
    sources: tuple[HeatSource, ...]
    sensor_node: str
    limit_node: str = "winding"

    def __post_init__(self):
        known = set(self.nodes) | {AMBIENT}
        for link in self.links:
            if link.a not in known or link.b not in known:
                raise ValueError(f"thermal link {link.a}-{link.b}: unknown node (nodes: {self.nodes})")
        for src in self.sources:
            if src.node not in self.nodes:
                raise ValueError(f"heat source {src.name!r}: unknown node {src.node!r}")
        if self.sensor_node not in self.nodes or self.limit_node not in self.nodes:
            raise ValueError("sensor_node and limit_node must be nodes of the network")

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"{n}_c" for n in self.nodes)

    def index(self, node: str) -> int:
        return self.nodes.index(node)

    def rhs(self, temperatures_c, powers: Mapping[str, object], ambient_c):
        """dT/dt of every node, as a CasADi expression (or numbers)."""
        t = {n: temperatures_c[i] for i, n in enumerate(self.nodes)}
        t[AMBIENT] = ambient_c
        heat = {n: 0 for n in self.nodes}
        for link in self.links:
            flow = (t[link.a] - t[link.b]) / link.resistance_k_per_w
            heat[link.a] = heat[link.a] - flow
            if link.b != AMBIENT:
                heat[link.b] = heat[link.b] + flow
        for src in self.sources:
            inject = src.constant_w + (src.gain * powers[src.name] if src.name else 0)
            heat[src.node] = heat[src.node] + inject
        return ca.vertcat(*[heat[n] / c for n, c in zip(self.nodes, self.capacities_j_per_k)])

    def function(self, source_names: tuple[str, ...]) -> ca.Function:
        """Named CasADi function ``thermal_rhs(temperatures_c, powers_w, ambient_c) -> dtemperatures_c_dt``."""
        temps = ca.SX.sym("temperatures_c", len(self.nodes))
        powers = ca.SX.sym("powers_w", len(source_names))
        ambient = ca.SX.sym("ambient_c")
        rhs = self.rhs(temps, {n: powers[i] for i, n in enumerate(source_names)}, ambient)
        return ca.Function("thermal_rhs", [temps, powers, ambient], [rhs],
                           ["temperatures_c", "powers_w", "ambient_c"], ["dtemperatures_c_dt"])

    def steady_state(self, powers: Mapping[str, float], ambient_c: float) -> np.ndarray:
        """Equilibrium temperatures for constant losses (the network is linear in T)."""
        temps = ca.SX.sym("temperatures_c", len(self.nodes))
        rhs = self.rhs(temps, powers, ambient_c)
        f = ca.Function("steady", [temps], [ca.jacobian(rhs, temps), rhs])
        a, b = (np.array(m, dtype=float) for m in f(np.zeros(len(self.nodes))))
        return np.linalg.solve(a, -b.ravel())


def joint_heat_rhs(network: ThermalNetwork, motor_params, temperatures_c, current_a, velocity_rad_s, ambient_c):
    """dT/dt of one joint's network heated by its motor's losses (R(T) at the limit node, the winding).

    The one place where motor losses meet a thermal network: the model, the whole-arm hold, the
    observer and identification all call it (``motor_params`` may hold CasADi symbols)."""
    winding_c = temperatures_c[network.index(network.limit_node)]
    losses = motor.losses_w(motor_params, current_a, velocity_rad_s, winding_c)
    return network.rhs(temperatures_c, losses, ambient_c)


def network_from_parameters(th: ThermalParameters) -> ThermalNetwork:
    """The contract's three networks: one node (eq. 7), winding/casing (eq. 6), and a drive node."""
    fric = th["friction_heating_fraction"]
    if th.model == "one_node":
        return ThermalNetwork(
            nodes=("winding",), capacities_j_per_k=(th["capacity_j_per_k"],),
            links=(Link("winding", AMBIENT, th["resistance_k_per_w"]),),
            sources=(HeatSource("winding", "joule_w"), HeatSource("winding", "friction_w", fric)),
            sensor_node="winding")
    nodes = ("winding", "casing")
    caps = (th["winding_capacity_j_per_k"], th["casing_capacity_j_per_k"])
    links = (Link("winding", "casing", th["winding_casing_k_per_w"]),
             Link("casing", AMBIENT, th["casing_ambient_k_per_w"]))
    sources = (HeatSource("winding", "joule_w"), HeatSource("casing", "friction_w", fric))
    if th.model == "two_node_drive":
        nodes += ("drive",)
        caps += (th["drive_capacity_j_per_k"],)
        links += (Link("drive", "casing", th["drive_casing_k_per_w"]),
                  Link("drive", AMBIENT, th["drive_ambient_k_per_w"]))
        sources += (HeatSource("drive", "current_sq_a2", th["drive_loss_w_per_a2"], th["drive_idle_w"]),)
    return ThermalNetwork(nodes, caps, links, sources, sensor_node="casing")


@dataclass(frozen=True)
class FirstOrderResponse:
    """Eq. (8): one-node response to a constant current ``i``: gain, time constant, runaway."""

    gain_k: float
    time_constant_s: float
    runaway_current_a: float

    @property
    def runaway(self) -> bool:
        return not np.isfinite(self.time_constant_s)


def one_node_response(resistance_ohm: float, resistance_ref_c: float, alpha_per_k: float,
                      capacity_j_per_k: float, resistance_k_per_w: float, ambient_c: float,
                      current_a: float) -> FirstOrderResponse:
    """Closed form of eq. (8) with R referred to ``resistance_ref_c`` (R_TA when it equals ambient).

    C dT/dt = R_ref(1 + a(T - T_ref)) i^2 - (T - T_A)/R_th is linear in T; its pole is
    (1 - R_ref a R_th i^2)/(C R_th), unstable (thermal runaway) for i^2 >= 1/(R_ref a R_th).
    """
    r_amb = resistance_ohm * (1 + alpha_per_k * (ambient_c - resistance_ref_c))
    margin = 1 - resistance_ohm * alpha_per_k * resistance_k_per_w * current_a ** 2
    runaway_i = (1 / (resistance_ohm * alpha_per_k * resistance_k_per_w)) ** 0.5 if alpha_per_k > 0 else np.inf
    if margin <= 0:
        return FirstOrderResponse(np.inf, np.inf, runaway_i)
    return FirstOrderResponse(r_amb * resistance_k_per_w * current_a ** 2 / margin,
                              capacity_j_per_k * resistance_k_per_w / margin, runaway_i)
