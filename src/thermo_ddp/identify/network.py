"""A general thermal network as identification sees it: nodes, links and heat sources whose values are
named by their dotted path in the parameter file (``thermal.node.tooth.capacity_j_per_k``,
``thermal.link.winding-tooth.resistance_k_per_w``, ``thermal.source.iron_losses.power_w``), so a fit, its
95 % intervals (``[uncertainty]``) and the alternatives a diagnosis writes all speak the file's keys.

:meth:`NetworkSpec.thermal_network` turns a spec (numbers or CasADi symbols) into the package's one
:class:`~thermo_ddp.model.thermal.ThermalNetwork`: simulation, identification, observer and planner share it.

Heat sources (``kind``; each split over nodes by share, shares summing to 1):

=================  ===============================================  ======================================
kind               heat                                             values
=================  ===============================================  ======================================
copper             R(T_winding) i^2 (report eqs. 3, 5)              none (the motor's resistance)
iron_losses        P_ref (|w| / w_ref)^n, n in 1-2.5: hysteresis    ``power_w``, ``speed_exponent``,
                   (n ~ 1) and eddy currents (n ~ 2) of the         ``ref_speed_rad_s`` (fixed)
                   laminations (Bertotti's loss separation)
friction_heating   c1 |w| + c2 w^2 (joint-side w)                   ``linear_w_s_per_rad``,
                                                                    ``quadratic_w_s2_per_rad2``
drive_heating      idle + k i^2                                     ``idle_w``, ``loss_w_per_a2``
constant           P                                                ``power_w``
=================  ===============================================  ======================================
"""
from __future__ import annotations

import dataclasses
from typing import Mapping

import casadi as ca

from ..model.thermal import AMBIENT, HeatSource, Link, ThermalNetwork, feature_key

SOURCE_KINDS = ("copper", "iron_losses", "friction_heating", "drive_heating", "constant")
# The values of each kind the fit may free, and their physical ranges' kind: "power" (>= 0, W scale),
# "exponent" (Bertotti: 1 hysteresis ... 2 eddy currents, up to 2.5 with excess losses).
SOURCE_VALUES = {"copper": (), "iron_losses": ("power_w", "speed_exponent"),
                 "friction_heating": ("linear_w_s_per_rad", "quadratic_w_s2_per_rad2"),
                 "drive_heating": ("idle_w", "loss_w_per_a2"), "constant": ("power_w",)}
IRON_EXPONENT_RANGE = (1.0, 2.5)
# Held speed features the identification grid provides: interval means of |w|^e at these exponents; an
# iron loss of exponent n between two of them is their linear interpolation (exact at the lattice points).
SPEED_EXPONENTS = (1.0, 1.5, 2.0, 2.5)


@dataclasses.dataclass(frozen=True)
class SourceSpec:
    """A heat source of ``kind`` split over nodes (``split``: node -> share) with its ``values``."""

    kind: str
    split: Mapping[str, float]
    values: Mapping[str, object] = dataclasses.field(default_factory=dict)

    def path(self, name: str) -> str:
        return f"thermal.source.{self.kind}.{name}"


def link_name(a: str, b: str) -> str:
    return f"{a}-{b}"


@dataclasses.dataclass(frozen=True)
class NetworkSpec:
    """Nodes with capacities, links with resistances (``b`` may be ``"ambient"``), sources, and the node
    the recording's ``temperature_c`` measures.  Values may be numbers or CasADi symbols."""

    nodes: tuple[str, ...]
    capacities: Mapping[str, object]
    links: tuple[tuple[str, str], ...]
    resistances: Mapping[str, object]
    sources: tuple[SourceSpec, ...]
    sensor: str = "winding"

    # ------------------------------------------------------------------ values by path
    def values(self) -> dict[str, object]:
        """Every value by its dotted path (capacities, resistances, source values)."""
        out = {f"thermal.node.{n}.capacity_j_per_k": self.capacities[n] for n in self.nodes}
        out |= {f"thermal.link.{link_name(*k)}.resistance_k_per_w": self.resistances[link_name(*k)]
                for k in self.links}
        for src in self.sources:
            out |= {src.path(k): v for k, v in src.values.items()}
        return out

    def with_values(self, values: Mapping[str, object]) -> "NetworkSpec":
        """The same structure with the values at ``values``' paths replaced."""
        caps = {n: values.get(f"thermal.node.{n}.capacity_j_per_k", c) for n, c in self.capacities.items()}
        res = {k: values.get(f"thermal.link.{k}.resistance_k_per_w", r) for k, r in self.resistances.items()}
        sources = tuple(dataclasses.replace(s, values={k: values.get(s.path(k), v) for k, v in s.values.items()})
                        for s in self.sources)
        return dataclasses.replace(self, capacities=caps, resistances=res, sources=sources)

    def source(self, kind: str) -> SourceSpec | None:
        return next((s for s in self.sources if s.kind == kind), None)

    def neighbours(self, node: str) -> tuple[str, ...]:
        return tuple(b if a == node else a for a, b in self.links if node in (a, b))

    # ------------------------------------------------------------------ the model's network
    def thermal_network(self, symbolic_iron: bool = False) -> ThermalNetwork:
        """The package's :class:`ThermalNetwork`.  ``symbolic_iron``: the iron loss's driver is the held
        feature :func:`iron_feature_key` (identification, where the exponent may be a symbol) instead of
        ``speed_abs_rad_s ** n`` (a number: simulation and planning)."""
        links = tuple(Link(a, b, self.resistances[link_name(a, b)]) for a, b in self.links)
        sources = tuple(h for k, s in enumerate(self.sources) for h in _heat(s, k, symbolic_iron))
        return ThermalNetwork(tuple(self.nodes), tuple(self.capacities[n] for n in self.nodes), links, sources,
                              sensor_node=self.sensor)


def iron_feature_key(index: int) -> str:
    return f"iron_speed_ratio#{index}"


def iron_feature(held: Mapping[str, object], exponent, ref_speed_rad_s: float):
    """Held mean of (|w| / w_ref)^n from the held means of |w|^e at :data:`SPEED_EXPONENTS` (hat-function
    interpolation in n; ``exponent`` may be a CasADi symbol)."""
    out = 0
    spacing = SPEED_EXPONENTS[1] - SPEED_EXPONENTS[0]
    for e in SPEED_EXPONENTS:
        weight = ca.fmax(0, 1 - ca.fabs(exponent - e) / spacing)
        out = out + weight * held[feature_key("speed_abs_rad_s", e)] / ref_speed_rad_s ** e
    return out


def _heat(src: SourceSpec, index: int, symbolic_iron: bool) -> list[HeatSource]:
    """One :class:`HeatSource` per node of ``src``'s split (see the module table)."""
    v, out = src.values, []
    for node, share in src.split.items():
        if src.kind == "copper":
            out.append(HeatSource(node, "joule_w", share))
        elif src.kind == "iron_losses" and symbolic_iron:
            out.append(HeatSource(node, iron_feature_key(index), share * v["power_w"]))
        elif src.kind == "iron_losses":
            n = float(v["speed_exponent"])
            out.append(HeatSource(node, "speed_abs_rad_s", share * v["power_w"] / v["ref_speed_rad_s"] ** n,
                                  exponent=n))
        elif src.kind == "friction_heating":
            out += [HeatSource(node, "speed_abs_rad_s", share * v["linear_w_s_per_rad"]),
                    HeatSource(node, "speed_abs_rad_s", share * v["quadratic_w_s2_per_rad2"], exponent=2.0)]
        elif src.kind == "drive_heating":
            out.append(HeatSource(node, "current_sq_a2", share * v["loss_w_per_a2"], share * v["idle_w"]))
        else:
            out.append(HeatSource(node, None, constant_w=share * v["power_w"]))
    return out


def one_node_spec(capacity_j_per_k: float, resistance_k_per_w: float) -> NetworkSpec:
    """The contract's one-node network (eq. 7) with copper losses: the start of every growth."""
    return NetworkSpec(("winding",), {"winding": capacity_j_per_k}, (("winding", AMBIENT),),
                       {link_name("winding", AMBIENT): resistance_k_per_w}, (SourceSpec("copper", {"winding": 1.0}),))
