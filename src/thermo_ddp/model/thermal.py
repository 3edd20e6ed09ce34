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
from .network_spec import AMBIENT, BOUNDARIES, ROOM, LinkSpec, NetworkSpec, NodeSpec, SourceSpec, literal_zero
from .parameters import ThermalParameters


@dataclass(frozen=True)
class Link:
    """A thermal resistance between two nodes (``b`` may be ``"ambient"``)."""

    a: str
    b: str
    resistance_k_per_w: object


@dataclass(frozen=True)
class HeatSource:
    """Power ``constant_w + gain * power[name] ** exponent / reference ** reference_exponent`` injected at
    ``node`` (``reference_exponent`` None: ``exponent``).

    ``name`` refers to a loss or loss driver of ``motor.losses_w`` (``joule_w``, ``ac_joule_w``,
    ``friction_w``, ``current_sq_a2``, ``speed_abs_rad_s``), None for a constant.  A caller that holds inputs over an
    interval may pass the interval mean of ``power[name] ** exponent`` under :attr:`feature` (a numeric
    exponent).  ``kind`` is the file's heat-source kind (``copper``, ``iron_losses``, ...) and ``term``
    the file's source name (None: its kind), so that a numeric network can be written back as a file
    (:func:`thermal_parameters_from_network`); both None for a source the file format does not know.
    """

    node: str
    name: str | None
    gain: object = 1.0
    constant_w: object = 0.0
    exponent: object = 1.0
    reference: object = 1.0
    kind: str | None = None
    term: str | None = None
    reference_exponent: object = None

    @property
    def feature(self) -> str | None:
        numeric = isinstance(self.exponent, (int, float))
        return None if self.name is None or not numeric else feature_key(self.name, self.exponent)

    def power_w(self, powers: Mapping[str, object]):
        if self.name is None:
            return self.constant_w
        driver = powers[self.feature] if self.feature in powers else _power(powers[self.name], self.exponent)
        if not (isinstance(self.reference, (int, float)) and self.reference == 1):
            driver = driver / self.reference ** (self.exponent if self.reference_exponent is None
                                                 else self.reference_exponent)
        return self.constant_w + self.gain * driver


def _power(x, exponent):
    """``x ** exponent`` of a non-negative driver: :func:`motor.driver_power` (finite derivatives at rest);
    with a symbolic exponent 0 where x = 0, so that its derivative in the exponent (x^n log x) is 0 there,
    not NaN (a motor at rest)."""
    if isinstance(exponent, (int, float)):
        return motor.driver_power(x, exponent)
    return ca.if_else(x > 0, x ** exponent, 0)


def feature_key(name: str, exponent: float = 1.0) -> str:
    """Key of a source's driver ``power[name] ** exponent``: ``name``, or e.g. ``speed_abs_rad_s^2``."""
    return name if exponent == 1 else f"{name}^{exponent:g}"


def feature_value(powers: Mapping[str, object], name: str, exponent: float = 1.0):
    """``powers[name] ** exponent``, or its held mean when ``powers`` has it under :func:`feature_key`."""
    key = feature_key(name, exponent)
    return powers[key] if key in powers else _power(powers[name], exponent)


@dataclass(frozen=True)
class ThermalNetwork:
    """A lumped network: ``nodes`` with heat capacities (J/K), thermal resistances between them or to
    ambient (``links``), heat ``sources`` injected at nodes, the node the sensor measures (``sensor_node``)
    and the node the temperature limit applies to (``limit_node``). Its state is one temperature per node,
    in °C, in the order of ``nodes`` (:attr:`state_names`).  ``room_c``: the temperature of the second
    boundary (``"room"``) when a caller gives none (None: the ambient's)."""

    nodes: tuple[str, ...]
    capacities_j_per_k: tuple[object, ...]
    links: tuple[Link, ...]
    sources: tuple[HeatSource, ...]
    sensor_node: str
    limit_node: str = "winding"
    room_c: object = None

    def __post_init__(self):
        known = set(self.nodes) | set(BOUNDARIES)
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

    def rhs(self, temperatures_c, powers: Mapping[str, object], ambient_c, room_c=None):
        """dT/dt of every node, as a CasADi expression (or numbers); ``room_c`` None: :attr:`room_c`."""
        t = {n: temperatures_c[i] for i, n in enumerate(self.nodes)}
        t[AMBIENT] = ambient_c
        t[ROOM] = next(r for r in (room_c, self.room_c, ambient_c) if r is not None)
        heat = {n: 0 for n in self.nodes}
        for link in self.links:
            flow = (t[link.a] - t[link.b]) / link.resistance_k_per_w
            heat[link.a] = heat[link.a] - flow
            if link.b not in BOUNDARIES:
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
                   held: Mapping[str, object] | None = None, room_c=None):
    """dT/dt of one joint's network heated by its motor's losses (R(T) at the limit node, the winding).

    The one place where motor losses meet a thermal network: the model, the whole-arm hold, the
    observer and identification all call it (``motor_params`` may hold CasADi symbols). ``held``
    replaces losses by their means over a zero-order-hold interval (keys: ``HeatSource.feature``;
    the mean friction power of an interval is not the friction power of its mean speed); ``room_c``: the
    room's temperature (None: the network's)."""
    winding_c = temperatures_c[network.index(network.limit_node)]
    losses = motor.losses_w(motor_params, current_a, velocity_rad_s, winding_c, held)
    return network.rhs(temperatures_c, losses, ambient_c, room_c)


@dataclass(frozen=True)
class Driver:
    """One term of a heat-source kind: ``gain_key``'s value times the driver ``name`` (``None``: a gain of
    1), raised to ``exponent`` (a number, or the kind's value key that holds it), plus ``constant_key``'s
    value; :data:`REFERENCE` names the value the driver is divided by, raised to ``reference_exponent``
    (None: ``exponent``)."""

    gain_key: str | None
    name: str | None
    exponent: float | str = 1.0
    constant_key: str | None = None
    reference_exponent: float | None = None


# The powers of the file's heat-source kinds (catalogue.SOURCE_KINDS), term by term; written once.
DRIVERS: dict[str, tuple[Driver, ...]] = {
    "copper": (Driver(None, "joule_w"),),                                        # R(T_w) i^2
    "iron_losses": (Driver("power_w", "speed_abs_rad_s", "speed_exponent"),),    # P (|w| / w_ref)^n
    "friction_heating": (Driver("linear_w_s_per_rad", "speed_abs_rad_s"),        # c1 |w| + c2 w^2
                         Driver("quadratic_w_s2_per_rad2", "speed_abs_rad_s", 2.0),
                         Driver("motor_fraction", "friction_w")),                # + f tau_f(w) w
    "drive_heating": (Driver("loss_w_per_a2", "current_sq_a2", 1.0, "idle_w"),),  # P_idle + k i^2
    "constant": (Driver(None, None, 1.0, "power_w"),),
    "ac_copper": (Driver("factor", "ac_joule_w", 1.0, reference_exponent=2.0),),  # k R(T_w) i^2 (w / w_ref)^2
}
REFERENCE = {"iron_losses": "ref_speed_rad_s", "ac_copper": "ref_speed_rad_s"}
_WHOLE = "<whole>"  # the gain of a term without a value of its own (copper: all of R i^2)


def heat_sources(spec: SourceSpec) -> tuple[HeatSource, ...]:
    """The heat sources of one file source: each of its kind's terms at each node of its split, scaled
    by the node's share; terms whose gain and constant are literal zeros are left out."""
    out = []
    for d in DRIVERS[spec.kind]:
        exponent = spec[d.exponent] if isinstance(d.exponent, str) else d.exponent
        reference = spec[REFERENCE[spec.kind]] if spec.kind in REFERENCE else 1.0
        for node, share in spec.split.items():
            gain = 0.0 if d.name is None else share * (1.0 if d.gain_key is None else spec[d.gain_key])
            constant = 0.0 if d.constant_key is None else share * spec[d.constant_key]
            if not (literal_zero(gain) and literal_zero(constant)):
                out.append(HeatSource(node, d.name, gain, constant, exponent, reference, spec.kind, spec.name,
                                      d.reference_exponent))
    return tuple(out)


def network_from_parameters(th: ThermalParameters) -> ThermalNetwork:
    """The one ``ThermalNetwork`` of a [thermal] section: a general network as written, a legacy model
    (one node, eq. 7; winding/casing, eq. 6; with a drive node) through its general form
    (:func:`~thermo_ddp.model.network_spec.general_network`).  Values may be CasADi symbols."""
    spec = th.general
    links = tuple(Link(*k.between, k.resistance_k_per_w) for k in spec.links)
    sources = tuple(h for s in spec.sources for h in heat_sources(s))
    return ThermalNetwork(spec.node_names, tuple(n.capacity_j_per_k for n in spec.nodes), links, sources,
                          sensor_node=th.sensor_node, room_c=th.room_c)


def thermal_parameters_from_network(network: ThermalNetwork, ambient_c: float,
                                    sensor: str | None = None) -> ThermalParameters:
    """The inverse of :func:`network_from_parameters` for a numeric network: a ``model = "network"``
    section (``sensor``: by default the network's sensor node).  Every heat source must carry its
    ``kind`` (and, when one kind appears twice, its ``term``); ValueError when a source cannot be
    written (no kind, a split that differs between the terms of one source, copper heat that is not R i^2)."""
    nodes = tuple(NodeSpec(n, float(c)) for n, c in zip(network.nodes, network.capacities_j_per_k))
    links = tuple(LinkSpec((k.a, k.b), float(k.resistance_k_per_w)) for k in network.links)
    groups: dict[str, list[HeatSource]] = {}
    for src in network.sources:
        if src.kind not in DRIVERS:
            raise ValueError(f"heat source {src.name!r} at {src.node!r} has no file kind: it cannot be written")
        groups.setdefault(src.term or src.kind, []).append(src)
    sources = tuple(_source_spec(label, group) for label, group in groups.items())
    spec = NetworkSpec(nodes, links, sources)
    room = None if network.room_c is None else float(network.room_c)
    return ThermalParameters("network", float(ambient_c), {}, sensor or network.sensor_node, network=spec, room_c=room)


def _source_spec(label: str, group: list[HeatSource]) -> SourceSpec:
    """One file source from its heat sources (the inverse of :func:`heat_sources`)."""
    kind = group[0].kind
    amounts: dict[str, dict[str, float]] = {}
    values: dict[str, float] = {}
    for d in DRIVERS[kind]:
        for h in group:
            if h.name != d.name or (isinstance(d.exponent, float) and h.name is not None and h.exponent != d.exponent):
                continue
            if d.name is not None:
                key = d.gain_key or _WHOLE
                amounts.setdefault(key, {}).setdefault(h.node, 0.0)
                amounts[key][h.node] += float(h.gain)
            if d.constant_key is not None:
                amounts.setdefault(d.constant_key, {}).setdefault(h.node, 0.0)
                amounts[d.constant_key][h.node] += float(h.constant_w)
            if isinstance(d.exponent, str):
                values[d.exponent] = float(h.exponent)
            if kind in REFERENCE:
                values[REFERENCE[kind]] = float(h.reference)
    totals = {key: sum(per.values()) for key, per in amounts.items()}
    base = next((key for key, total in totals.items() if total != 0), None)
    if base is None:
        raise ValueError(f"heat source {label!r}: no heat to write")
    split = {node: amount / totals[base] for node, amount in amounts[base].items()}
    for key, per in amounts.items():
        if any(abs(a - split.get(n, 0.0) * totals[key]) > 1e-12 * (abs(totals[key]) + 1) for n, a in per.items()):
            raise ValueError(f"heat source {label!r}: its terms are split differently; write them as two sources")
    if _WHOLE in totals and abs(totals[_WHOLE] - 1) > 1e-12:
        raise ValueError(f"heat source {label!r}: copper heat is R i^2 in total, here {totals[_WHOLE]:g} of it")
    values |= {key: total for key, total in totals.items() if key != _WHOLE}
    return SourceSpec(kind, split, values, None if label == kind else label)


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
