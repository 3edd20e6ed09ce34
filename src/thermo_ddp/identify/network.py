"""A general thermal network as identification sees it: the file's
:class:`~thermo_ddp.model.network_spec.NetworkSpec` whose values are named by their dotted path
(``thermal.node.tooth.capacity_j_per_k``, ``thermal.link.winding-tooth.resistance_k_per_w``,
``thermal.source.iron_losses.power_w``), so a fit, its 95 % intervals (``[uncertainty]``) and the
alternatives a diagnosis writes all speak the file's keys.

The network identification integrates is the package's one network
(:func:`~thermo_ddp.model.thermal.heat_sources` of each source) with one difference: an iron loss
P (|w| / w_ref)^n whose exponent n is a free symbol is driven by the interval mean of (|w| / w_ref)^n
(:func:`iron_feature`), not by the n-th power of the mean speed: the grid holds the means of |w|^e at
:data:`SPEED_EXPONENTS` and n between two of them interpolates linearly (exact at the lattice points).
"""
from __future__ import annotations

import dataclasses
from typing import Mapping

import casadi as ca

from ..model.network_spec import AMBIENT, LinkSpec, NetworkSpec, NodeSpec, SourceSpec
from ..model.thermal import HeatSource, Link, ThermalNetwork, feature_key, heat_sources

PREFIX = "thermal."
IRON_EXPONENT_RANGE = (1.0, 2.5)  # catalogue's iron_loss_speed_exponent: hysteresis (1) to eddy and excess (2.5)
SPEED_EXPONENTS = (1.0, 1.5, 2.0, 2.5)
# Exactly on a lattice exponent the hat functions have no slope (|x|' = 0 at 0): a fit started there would
# never move n.  Shifting n by 1e-9 changes the driver by a relative 1e-9 at most.
KINK_SHIFT = 1e-9
TINY = 1e-12  # keeps log(0) finite at rest: the interpolated driver is then ~1e-12, a heat of nothing
FIXED_VALUES = ("ref_speed_rad_s", "motor_fraction")  # source values a fit never frees


def free_paths(spec: NetworkSpec) -> tuple[str, ...]:
    """Every capacity, resistance and source value of ``spec`` a fit may free (not fixed values), and the
    shares of a split over several nodes but the first (whose share is the rest, :func:`with_values`)."""
    firsts = {f"source.{s.label}.split.{next(iter(s.split))}" for s in spec.sources}
    return tuple(PREFIX + tail for tail in spec.paths() if tail not in firsts
                 and tail.rsplit(".", 1)[1] not in FIXED_VALUES)


def values_of(spec: NetworkSpec) -> dict[str, object]:
    return {PREFIX + tail: v for tail, v in spec.paths().items()}


def with_values(spec: NetworkSpec, values: Mapping[str, object]) -> NetworkSpec:
    """``spec`` with the values at ``values``' paths; the first node of each split takes the share the
    others leave (shares sum to 1 for numbers and symbols alike)."""
    spec = spec.with_values({p[len(PREFIX):]: v for p, v in values.items()})
    rest = {}
    for s in spec.sources:
        first, *others = s.split
        if others:
            rest[f"source.{s.label}.split.{first}"] = 1 - sum(s.split[n] for n in others)
    return spec.with_values(rest) if rest else spec


def iron_feature_key(label: str) -> str:
    return f"iron_speed_ratio[{label}]"


def iron_feature(held: Mapping[str, object], exponent, ref_speed_rad_s):
    """Held mean of (|w| / w_ref)^n from the held means m_e of (|w| / w_ref)^e at :data:`SPEED_EXPONENTS`:
    geometric interpolation between the two lattice exponents around n, m_lo^(1 - a) m_hi^a, exact for a
    speed held constant over the interval (``exponent`` may be a CasADi symbol)."""
    log_mean = 0
    spacing = SPEED_EXPONENTS[1] - SPEED_EXPONENTS[0]
    exponent = exponent + KINK_SHIFT
    for e in SPEED_EXPONENTS:
        weight = ca.fmax(0, 1 - ca.fabs(exponent - e) / spacing)
        log_mean = log_mean + weight * ca.log(held[feature_key("speed_abs_rad_s", e)] / ref_speed_rad_s ** e + TINY)
    return ca.exp(log_mean)


def identification_network(spec: NetworkSpec, sensor: str) -> ThermalNetwork:
    """The package's network of ``spec``; iron losses driven by :func:`iron_feature_key` (module docstring)."""
    sources = []
    for src in spec.sources:
        for h in heat_sources(src):
            if src.kind == "iron_losses":
                h = HeatSource(h.node, iron_feature_key(src.label), h.gain, kind=h.kind, term=h.term)
            sources.append(h)
    links = tuple(Link(*k.between, k.resistance_k_per_w) for k in spec.links)
    return ThermalNetwork(spec.node_names, tuple(n.capacity_j_per_k for n in spec.nodes), links, tuple(sources),
                          sensor_node=sensor)


def iron_features(spec: NetworkSpec, held: Mapping[str, object]) -> dict[str, object]:
    """The held iron-loss drivers of ``spec``'s iron sources (keys :func:`iron_feature_key`)."""
    return {iron_feature_key(s.label): iron_feature(held, s["speed_exponent"], s["ref_speed_rad_s"])
            for s in spec.sources if s.kind == "iron_losses"}


# ----------------------------------------------------------------------------- growing a spec
def capacity(spec: NetworkSpec, node: str) -> float:
    return float(next(n.capacity_j_per_k for n in spec.nodes if n.name == node))


def link(spec: NetworkSpec, a: str, b: str) -> LinkSpec | None:
    return next((k for k in spec.links if set(k.between) == {a, b}), None)


def with_node(spec: NetworkSpec, node: str, capacity_j_per_k: float, links: Mapping[tuple[str, str], float],
              drop: LinkSpec | None = None) -> NetworkSpec:
    """``spec`` with ``node``, its ``links`` (pair -> resistance), without the link ``drop``."""
    kept = tuple(k for k in spec.links if k is not drop)
    return dataclasses.replace(spec, nodes=spec.nodes + (NodeSpec(node, capacity_j_per_k),),
                               links=kept + tuple(LinkSpec(pair, r) for pair, r in links.items()))


def with_source(spec: NetworkSpec, source: SourceSpec) -> NetworkSpec:
    """``spec`` with ``source`` instead of any source of the same label."""
    others = tuple(s for s in spec.sources if s.label != source.label)
    return dataclasses.replace(spec, sources=others + (source,))


def sink_links(spec: NetworkSpec) -> tuple[LinkSpec, ...]:
    return tuple(k for k in spec.links if AMBIENT in k.between)
