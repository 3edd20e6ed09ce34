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
    """Power ``gain * power[name] ** exponent + constant_w`` injected at ``node``.

    ``name`` refers to a loss or loss driver of ``motor.losses_w`` (``joule_w``, ``friction_w``,
    ``current_sq_a2``, ``speed_abs_rad_s``); ``exponent`` is a number. A caller that holds inputs
    over an interval may pass the interval mean of ``power[name] ** exponent`` under :attr:`feature`.
    """

    node: str
    name: str | None
    gain: object = 1.0
    constant_w: object = 0.0
    exponent: float = 1.0

    @property
    def feature(self) -> str | None:
        return None if self.name is None else feature_key(self.name, self.exponent)

    def power_w(self, powers: Mapping[str, object]):
        if self.name is None:
            return self.constant_w
        return self.constant_w + self.gain * feature_value(powers, self.name, self.exponent)


def feature_key(name: str, exponent: float = 1.0) -> str:
    """Key of a source's driver ``power[name] ** exponent``: ``name``, or e.g. ``speed_abs_rad_s^2``."""
    return name if exponent == 1 else f"{name}^{exponent:g}"


def feature_value(powers: Mapping[str, object], name: str, exponent: float = 1.0):
    """``powers[name] ** exponent``, or its held mean when ``powers`` has it under :func:`feature_key`."""
    key = feature_key(name, exponent)
    return powers[key] if key in powers else motor.driver_power(powers[name], exponent)


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
            heat[src.node] = heat[src.node] + src.power_w(powers)
        return ca.vertcat(*[heat[n] / c for n, c in zip(self.nodes, self.capacities_j_per_k)])

    def steady_state(self, powers: Mapping[str, float], ambient_c: float) -> np.ndarray:
        """Equilibrium temperatures for constant losses (the network is linear in T)."""
        temps = ca.SX.sym("temperatures_c", len(self.nodes))
        rhs = self.rhs(temps, powers, ambient_c)
        f = ca.Function("steady", [temps], [ca.jacobian(rhs, temps), rhs])
        a, b = (np.array(m, dtype=float) for m in f(np.zeros(len(self.nodes))))
        return np.linalg.solve(a, -b.ravel())


def joint_heat_rhs(network: ThermalNetwork, motor_params, temperatures_c, current_a, velocity_rad_s, ambient_c,
                   held: Mapping[str, object] | None = None):
    """dT/dt of one joint's network heated by its motor's losses (R(T) at the limit node, the winding).

    The one place where motor losses meet a thermal network: the model, the whole-arm hold, the
    observer and identification all call it (``motor_params`` may hold CasADi symbols). ``held``
    replaces losses by their means over a zero-order-hold interval (keys: ``HeatSource.feature``;
    the mean friction power of an interval is not the friction power of its mean speed)."""
    winding_c = temperatures_c[network.index(network.limit_node)]
    losses = motor.losses_w(motor_params, current_a, velocity_rad_s, winding_c) | dict(held or {})
    return network.rhs(temperatures_c, losses, ambient_c)


def network_from_parameters(th: ThermalParameters) -> ThermalNetwork:
    """The contract's three networks: one node (eq. 7), winding/casing (eq. 6), and a drive node, with
    the heat sources of the file: Joule heat in the winding; ``friction_heating_fraction`` of the
    friction power in the casing (the winding of a one-node network); friction heat
    c1 |v| + c2 v^2 at ``friction_heat_node``; iron losses P_Fe (|v| / v_ref)^k in the winding; the
    drive's idle and i^2 losses in the drive node, or without one in the sensor node. Values may be
    CasADi symbols; sources whose gain is a literal zero are left out."""
    if th.model == "one_node":
        nodes, caps = ("winding",), (th["capacity_j_per_k"],)
        links = (Link("winding", AMBIENT, th["resistance_k_per_w"]),)
    else:
        nodes = ("winding", "casing")
        caps = (th["winding_capacity_j_per_k"], th["casing_capacity_j_per_k"])
        links = (Link("winding", "casing", th["winding_casing_k_per_w"]),
                 Link("casing", AMBIENT, th["casing_ambient_k_per_w"]))
    if th.model == "two_node_drive":
        nodes += ("drive",)
        caps += (th["drive_capacity_j_per_k"],)
        links += (Link("drive", "casing", th["drive_casing_k_per_w"]),
                  Link("drive", AMBIENT, th["drive_ambient_k_per_w"]))
    drive_node = "drive" if "drive" in nodes else th.sensor_node
    exponent = float(th["iron_loss_speed_exponent"])
    sources = (HeatSource("winding", "joule_w"),
               HeatSource("winding" if th.model == "one_node" else "casing", "friction_w",
                          th["friction_heating_fraction"]),
               HeatSource(th.friction_node, "speed_abs_rad_s", th["friction_heat_linear_w_s_per_rad"]),
               HeatSource(th.friction_node, "speed_abs_rad_s", th["friction_heat_quadratic_w_s2_per_rad2"],
                          exponent=2.0),
               HeatSource("winding", "speed_abs_rad_s", th["iron_loss_w"] / th["iron_loss_ref_speed_rad_s"] ** exponent,
                          exponent=exponent),
               HeatSource(drive_node, "current_sq_a2", th["drive_loss_w_per_a2"], th["drive_idle_w"]))
    sources = tuple(s for s in sources if not (_zero(s.gain) and _zero(s.constant_w)))
    return ThermalNetwork(nodes, caps, links, sources, sensor_node=th.sensor_node)


def _zero(value) -> bool:
    return isinstance(value, (int, float)) and value == 0


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
