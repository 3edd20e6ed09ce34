"""A general thermal network in the parameter file (``[thermal] model = "network"``): nodes, links and
heat sources as data, read and checked here; and the one map of the three legacy models
(``one_node``, ``two_node``, ``two_node_drive`` and their optional heat keys) to that general form.

The file (docs/architecture.md, "Parameter file: a general network")::

    [[thermal.node]]     name = "winding", capacity_j_per_k = 1500.0
    [[thermal.link]]     between = ["winding", "ambient"], resistance_k_per_w = 0.08
    [[thermal.source]]   kind = "iron_losses", split = { tooth = 0.6, yoke = 0.4 },
                         power_w = 300.0, ref_speed_rad_s = 576.0, speed_exponent = 1.6

Each value has a dotted path (``thermal.node.winding.capacity_j_per_k``,
``thermal.link.winding-tooth.resistance_k_per_w``, ``thermal.source.iron_losses.power_w``,
``thermal.source.iron_losses.split.tooth``): ``[uncertainty]`` and ``[[alternatives]]`` name values by it
and identification substitutes symbols by it (:meth:`NetworkSpec.with_values`).  A source is named by its
``name`` (default: its kind); names are unique.  Values may be CasADi symbols once read.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

from ..errors import InputError
from .catalogue import (HEAT_SOURCE_KINDS, LIMIT_NODE, SHARE_SUM_TOLERANCE, SOURCE_KINDS, checked_value,
                        source_value_default)

AMBIENT = "ambient"
# A second boundary: the room around a liquid-cooled motor (its temperature: a recording's ``room_c``, else
# ``[thermal] room_c``, else the ambient).  A link to it is the ``room_link`` term.
ROOM = "room"
BOUNDARIES = (AMBIENT, ROOM)


@dataclass(frozen=True)
class NodeSpec:
    name: str
    capacity_j_per_k: object


@dataclass(frozen=True)
class LinkSpec:
    """A thermal resistance between two nodes; the second may be a boundary (``"ambient"``, ``"room"``)."""

    between: tuple[str, str]
    resistance_k_per_w: object

    @property
    def key(self) -> str:
        return "-".join(self.between)


@dataclass(frozen=True)
class SourceSpec:
    """Heat of one ``kind`` shared among nodes (``split``: node -> share, shares sum to 1); ``values``
    holds the kind's values given in the file (absent ones read as their catalogue defaults)."""

    kind: str
    split: Mapping[str, object]
    values: Mapping[str, object]
    name: str | None = None

    @property
    def label(self) -> str:
        return self.name or self.kind

    def __getitem__(self, key: str):
        return self.values[key] if key in self.values else source_value_default(self.kind, key)

    def to_dict(self) -> dict[str, Any]:
        named = {"name": self.name} if self.name else {}
        return {"kind": self.kind, **named, "split": dict(self.split), **self.values}


@dataclass(frozen=True)
class NetworkSpec:
    nodes: tuple[NodeSpec, ...]
    links: tuple[LinkSpec, ...]
    sources: tuple[SourceSpec, ...]

    @property
    def node_names(self) -> tuple[str, ...]:
        return tuple(n.name for n in self.nodes)

    @property
    def kinds(self) -> tuple[str, ...]:
        """The heat-source kinds present, each once."""
        return tuple(dict.fromkeys(s.kind for s in self.sources))

    def to_dict(self) -> dict[str, Any]:
        return {"node": [{"name": n.name, "capacity_j_per_k": n.capacity_j_per_k} for n in self.nodes],
                "link": [{"between": list(k.between), "resistance_k_per_w": k.resistance_k_per_w} for k in self.links],
                "source": [s.to_dict() for s in self.sources]}

    def paths(self) -> dict[str, object]:
        """Every value of the file by its dotted path below ``thermal.`` (source values given, not defaults)."""
        out = {f"node.{n.name}.capacity_j_per_k": n.capacity_j_per_k for n in self.nodes}
        out |= {f"link.{k.key}.resistance_k_per_w": k.resistance_k_per_w for k in self.links}
        for s in self.sources:
            out |= {f"source.{s.label}.{key}": value for key, value in s.values.items()}
            out |= {f"source.{s.label}.split.{node}": share for node, share in s.split.items()}
        return out

    def value(self, tail: str):
        """The value at ``tail`` (a dotted path below ``thermal.``; a link either way round); KeyError when
        nothing is there."""
        part, _, rest = tail.partition(".")
        name, _, key = rest.partition(".")
        link = _find_link(self.links, name) if part == "link" and key == "resistance_k_per_w" else None
        return link.resistance_k_per_w if link is not None else self.paths()[tail]

    def with_values(self, values: Mapping[str, object]) -> "NetworkSpec":
        """A copy with the values at the dotted paths (below ``thermal.``) replaced, unchecked (symbols
        allowed).  A path ``source.<kind>.<key>`` or ``source.<kind>.split.<node>`` of a source the
        network lacks adds that source (an alternative explanation); check the result by reading it."""
        spec = self
        for tail, value in values.items():
            spec = spec._with_value(tail, value)
        return spec

    def _with_value(self, tail: str, value) -> "NetworkSpec":
        part, _, rest = tail.partition(".")
        name, _, key = rest.partition(".")
        if part == "node" and key == "capacity_j_per_k" and name in self.node_names:
            nodes = tuple(dataclasses.replace(n, capacity_j_per_k=value) if n.name == name else n for n in self.nodes)
            return dataclasses.replace(self, nodes=nodes)
        if part == "link" and key == "resistance_k_per_w":
            link = _find_link(self.links, name)
            if link is not None:
                links = tuple(dataclasses.replace(k, resistance_k_per_w=value) if k is link else k for k in self.links)
                return dataclasses.replace(self, links=links)
        if part == "source":
            return self._with_source_value(name, key, value)
        raise KeyError(tail)

    def _with_source_value(self, label: str, key: str, value) -> "NetworkSpec":
        sources = list(self.sources)
        index = next((k for k, s in enumerate(sources) if s.label == label), None)
        if index is None:
            if label not in SOURCE_KINDS:
                raise KeyError(f"source.{label}")
            sources.append(SourceSpec(label, {}, {}))
            index = len(sources) - 1
        src = sources[index]
        if key.startswith("split."):
            src = dataclasses.replace(src, split={**src.split, key[len("split."):]: value})
        elif key in SOURCE_KINDS[src.kind]:
            src = dataclasses.replace(src, values={**src.values, key: value})
        else:
            raise KeyError(f"source.{label}.{key}")
        sources[index] = src
        return dataclasses.replace(self, sources=tuple(sources))


def _find_link(links, key: str) -> LinkSpec | None:
    """The link named ``a-b`` (either order)."""
    a, _, b = key.partition("-")
    return next((k for k in links if set(k.between) == {a, b} and len({a, b}) == 2), None)


# ----------------------------------------------------------------------------- reading and checking
def _table_list(source: str, sec: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    items = sec.get(key, [])
    if not isinstance(items, list) or not all(isinstance(t, Mapping) for t in items):
        raise InputError(source, f"thermal.{key}", repr(items), f"expected [[thermal.{key}]] tables")
    return items


def _only_keys(source: str, where: str, table: Mapping[str, Any], known: tuple[str, ...]) -> None:
    for key in table:
        if key not in known:
            raise InputError(source, f"{where}.{key}", table[key], f"unknown key (typo?); known: {', '.join(known)}")


def check_node_name(source: str, where: str, name: Any) -> str:
    """``name`` when it is a valid node name (an identifier other than a boundary's); InputError otherwise."""
    if not isinstance(name, str) or not name.isidentifier() or name in BOUNDARIES:
        raise InputError(source, where, repr(name), "a node name is a valid identifier (letters, digits, _; not "
                         f"starting with a digit) other than {' or '.join(map(repr, BOUNDARIES))}")
    return name


def _read_nodes(source: str, sec: Mapping[str, Any]) -> tuple[NodeSpec, ...]:
    nodes = []
    for k, table in enumerate(_table_list(source, sec, "node")):
        _only_keys(source, f"thermal.node[{k}]", table, ("name", "capacity_j_per_k"))
        name = check_node_name(source, f"thermal.node[{k}].name", table.get("name"))
        if name in (n.name for n in nodes):
            raise InputError(source, f"thermal.node[{k}].name", name, "a node appears twice")
        if "capacity_j_per_k" not in table:
            raise InputError(source, f"thermal.node.{name}.capacity_j_per_k", "<missing>", "required key missing")
        nodes.append(NodeSpec(name, checked_value(source, f"thermal.node.{name}.capacity_j_per_k", "capacity_j_per_k",
                                                  table["capacity_j_per_k"])))
    if LIMIT_NODE not in (n.name for n in nodes):
        raise InputError(source, "thermal.node", ", ".join(n.name for n in nodes) or "none",
                         f"a network needs a {LIMIT_NODE!r} node (the winding limit applies to it)")
    return tuple(nodes)


def _read_links(source: str, sec: Mapping[str, Any], nodes: tuple[str, ...]) -> tuple[LinkSpec, ...]:
    links: list[LinkSpec] = []
    for k, table in enumerate(_table_list(source, sec, "link")):
        _only_keys(source, f"thermal.link[{k}]", table, ("between", "resistance_k_per_w"))
        pair = table.get("between")
        if (not isinstance(pair, list) or len(pair) != 2 or pair[0] == pair[1]
                or not all(p in (*nodes, *BOUNDARIES) for p in pair) or pair[0] in BOUNDARIES):
            raise InputError(source, f"thermal.link[{k}].between", repr(pair),
                             f"expected [node, node or {' or '.join(map(repr, BOUNDARIES))}], two different nodes "
                             f"of {', '.join(nodes)}")
        key = "-".join(pair)
        if _find_link(links, key) is not None:
            raise InputError(source, f"thermal.link[{k}].between", repr(pair), "these nodes are linked twice")
        if "resistance_k_per_w" not in table:
            raise InputError(source, f"thermal.link.{key}.resistance_k_per_w", "<missing>", "required key missing")
        links.append(LinkSpec(tuple(pair), checked_value(source, f"thermal.link.{key}.resistance_k_per_w",
                                                         "resistance_k_per_w", table["resistance_k_per_w"])))
    _check_grounded(source, nodes, links)
    return tuple(links)


def _check_grounded(source: str, nodes: tuple[str, ...], links) -> None:
    """Every node reaches a boundary through links: a floating node has no sink, and no steady state."""
    reached, frontier = set(BOUNDARIES), list(BOUNDARIES)
    while frontier:
        here = frontier.pop()
        for link in links:
            if here in link.between:
                other = link.between[1 - link.between.index(here)]
                if other not in reached:
                    reached.add(other)
                    frontier.append(other)
    floating = [n for n in nodes if n not in reached]
    if floating:
        raise InputError(source, "thermal.link", ", ".join(floating), "floating: not connected to ambient (or the room) through "
                         "links (its heat has no way out); add a link")


def _read_split(source: str, where: str, split: Any, nodes: tuple[str, ...]) -> dict[str, float]:
    if not isinstance(split, Mapping) or not split:
        raise InputError(source, where, repr(split), "expected { node = share, ... } (shares sum to 1)")
    shares = {}
    for node, share in split.items():
        if node not in nodes:
            raise InputError(source, f"{where}.{node}", share, f"no such node; nodes: {', '.join(nodes)}")
        shares[node] = checked_value(source, f"{where}.{node}", "share", share)
    total = sum(shares.values())
    if abs(total - 1.0) > SHARE_SUM_TOLERANCE:
        raise InputError(source, where, repr(dict(split)), f"shares sum to {total:g}, not 1")
    return shares


def _read_source(source: str, k: int, table: Mapping[str, Any], nodes: tuple[str, ...]) -> SourceSpec:
    kind = table.get("kind")
    if kind not in SOURCE_KINDS:
        raise InputError(source, f"thermal.source[{k}].kind", repr(kind), f"expected one of {', '.join(HEAT_SOURCE_KINDS)}")
    name = table.get("name")
    if name is not None and (not isinstance(name, str) or not name.isidentifier()):
        raise InputError(source, f"thermal.source[{k}].name", repr(name), "a source name is a valid identifier")
    label = name or kind
    _only_keys(source, f"thermal.source.{label}", table, ("kind", "name", "split", *SOURCE_KINDS[kind]))
    split = _read_split(source, f"thermal.source.{label}.split", table.get("split"), nodes)
    values = {key: checked_value(source, f"thermal.source.{label}.{key}", catalogue, table[key])
              for key, catalogue in SOURCE_KINDS[kind].items() if key in table}
    return SourceSpec(kind, split, values, name)


def read_network(source: str, sec: Mapping[str, Any]) -> NetworkSpec:
    """The ``node``, ``link`` and ``source`` tables of a ``model = "network"`` [thermal] section, checked:
    node names are identifiers, ``winding`` exists, every node reaches ambient, every share is in 0..1
    and a source's shares sum to 1, every value within its catalogue bound.  InputError otherwise."""
    nodes = _read_nodes(source, sec)
    names = tuple(n.name for n in nodes)
    links = _read_links(source, sec, names)
    sources = tuple(_read_source(source, k, t, names) for k, t in enumerate(_table_list(source, sec, "source")))
    labels = [s.label for s in sources]
    for label in labels:
        if labels.count(label) > 1:
            raise InputError(source, "thermal.source", label, "two sources with this name: give each a distinct name")
    return NetworkSpec(nodes, links, sources)


# ----------------------------------------------------------------------------- the legacy models
def general_network(th) -> NetworkSpec:
    """The one map of a legacy ``[thermal]`` (``one_node``, ``two_node``, ``two_node_drive`` with their
    optional heat keys; ``th`` a :class:`~thermo_ddp.model.parameters.ThermalParameters`) to the general
    form: winding (+ casing, + drive) nodes and their links; copper heat in the winding; the motor's
    friction power ``friction_heating_fraction`` in the casing (the winding of a one-node network);
    friction heat c1 |v| + c2 v^2 at ``friction_heat_node``; iron losses in the winding; the drive's
    losses in the drive node, or without one in the sensor node.  Values may be CasADi symbols;
    a source whose values are all literal zeros is left out."""
    if th.model == "one_node":
        nodes = (NodeSpec("winding", th["capacity_j_per_k"]),)
        links = (LinkSpec(("winding", AMBIENT), th["resistance_k_per_w"]),)
    else:
        nodes = (NodeSpec("winding", th["winding_capacity_j_per_k"]), NodeSpec("casing", th["casing_capacity_j_per_k"]))
        links = (LinkSpec(("winding", "casing"), th["winding_casing_k_per_w"]),
                 LinkSpec(("casing", AMBIENT), th["casing_ambient_k_per_w"]))
    if th.model == "two_node_drive":
        nodes += (NodeSpec("drive", th["drive_capacity_j_per_k"]),)
        links += (LinkSpec(("drive", "casing"), th["drive_casing_k_per_w"]),
                  LinkSpec(("drive", AMBIENT), th["drive_ambient_k_per_w"]))
    return NetworkSpec(nodes, links, (SourceSpec("copper", {"winding": 1.0}, {}), *_legacy_heat(th, nodes)))


def _legacy_heat(th, nodes: tuple[NodeSpec, ...]) -> tuple[SourceSpec, ...]:
    """The optional heat keys of a legacy [thermal] as sources (literal zeros left out)."""
    def given(kind: str, keys: tuple[str, ...], node: str, name: str | None = None) -> tuple[SourceSpec, ...]:
        values = {key: th[SOURCE_KINDS[kind][key]] for key in keys}
        heat = [v for key, v in values.items() if key not in ("ref_speed_rad_s", "speed_exponent")]
        return () if all(literal_zero(v) for v in heat) else (SourceSpec(kind, {node: 1.0}, values, name),)

    fraction_node = "winding" if th.model == "one_node" else "casing"
    friction = given("friction_heating", ("linear_w_s_per_rad", "quadratic_w_s2_per_rad2"), th.friction_node)
    motor = given("friction_heating", ("motor_fraction",), fraction_node, "motor_friction_heating" if friction else None)
    if friction and motor and th.friction_node == fraction_node:  # one source, one split
        friction = (dataclasses.replace(friction[0], values={**friction[0].values, **motor[0].values}),)
        motor = ()
    drive_node = "drive" if "drive" in (n.name for n in nodes) else th.sensor_node
    return (*motor, *friction,
            *given("iron_losses", ("power_w", "ref_speed_rad_s", "speed_exponent"), "winding"),
            *given("drive_heating", ("idle_w", "loss_w_per_a2"), drive_node))


def literal_zero(value) -> bool:
    return isinstance(value, (int, float)) and value == 0
