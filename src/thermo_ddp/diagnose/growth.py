"""A thermal network that grows: nodes, links and heat sources added one at a time, each on evidence.

Start: the parameter file's network with its capacities, resistances and source values free.  A recording
column ``node_<x>_c`` naming a node the network lacks is not an error: the node is added first (it is
measured, so it is not a hypothesis), at the place that fits best: on a node's path to the sink, or beside a
node with its own path to the sink.  Then, step by step, every allowed addition is fitted from the current
values (every sensor at once, each weighted by its noise, :func:`~thermo_ddp.identify.network_fit.fit_network`):

- ``sink_node``: an unmeasured node between a node and the sink (the heat path has a second time constant);
- ``source_node``: an unmeasured node beside a node, linked to the sink, that hosts a heat source (a rotor
  heated by its own losses, seen by the stator through the air gap);
- a heat source of a kind the motor can have (``[hardware] heat_sources``): ``iron_losses``
  P_ref (|w| / w_ref)^n with n fitted in 1-2.5, ``friction_heating``, ``drive_heating``, ``constant``,
  at one node, or a source already there spread to one more node (its shares fitted); ``ac_copper``
  k R(T_w) i^2 (|w| / w_ref)^2 where the copper heat is, with the copper's split;
- ``room_link``: a link from a node to the room, when the recordings give the room's temperature
  (``room_c``: a second boundary besides the coolant's ``ambient_c``).

An addition is accepted by today's statistics (:mod:`~thermo_ddp.diagnose.selection`): the nested
likelihood-ratio test with the sample size corrected for the residual autocorrelation, Bonferroni over the
additions tried at that step, and a relative drop of the noise-weighted RMSE of at least ``min_rmse_drop``;
among the accepted ones that the test cannot tell from the best, a heat source listed earlier in
``heat_sources`` goes first; that one is then judged leaving one segment out (with several segments): it is withdrawn when
the held-out RMSE of the limit node (the winding) is higher with it than without, beyond the noise of one
reading.  Growth stops when every sensor's RMSE is within ``max_noise_ratio`` of its residual noise (``ok``)
or when nothing allowed helps (``model_does_not_fit``, honestly).  Heat sources of another kind that fit
as well as the chosen one (the nested test cannot tell them apart) are the file's ``[[alternatives]]``.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Callable, Sequence

import numpy as np

from ..identify.network import (IRON_EXPONENT_RANGE, capacity, free_paths, link, sink_links, with_node,
                                with_source)
from ..identify.network_fit import Free, NetworkFit, fit_network, sensor_noise
from ..identify.thermal_data import ThermalGrid
from ..model.catalogue import SOURCE_KINDS
from ..model.network_spec import AMBIENT, ROOM, LinkSpec, NetworkSpec, SourceSpec
from ..model.parameters import JointParameters
from .selection import HeldOutCheck, NestedTest, SubsetFit, SubsetSettings, nested_test

log = logging.getLogger(__name__)

GROWTH_TERMS = ("sensor_node", "sink_node", "source_node", "room_link")
# Physical ranges of the values a growth frees: capacities within 1/1000 to 10 times the file's whole
# capacity (a node is a part of this motor, not a second coolant); a liquid-cooled housing (1e-4 K/W) to
# a part in still air (100 K/W).
CAPACITY_SHARE = (1e-3, 10.0)
RESISTANCE_RANGE = (1e-4, 100.0)
HEAT_KINDS = tuple(k for k in SOURCE_KINDS if k != "copper")
COPPER_BOUND = ("ac_copper",)  # heat in the copper itself: placed with the copper's split, never elsewhere
AC_FACTOR_RANGE = (0.0, 10.0)  # the catalogue's ac_copper_factor


@dataclasses.dataclass(frozen=True)
class Addition:
    """One candidate: its ``term`` (a growth term or a heat-source kind), where, and the grown network."""

    term: str
    where: str
    spec: NetworkSpec

    @property
    def label(self) -> str:
        return f"{self.term} at {self.where}"


@dataclasses.dataclass(frozen=True)
class Step:
    """An accepted addition with its fit, its test against the network before it, and its held-out check."""

    addition: Addition
    fit: NetworkFit
    test: NestedTest | None
    held_out: HeldOutCheck | None = None
    tried: int = 1


def subset_fit(fit: NetworkFit, terms: frozenset = frozenset()) -> SubsetFit:
    return SubsetFit(terms, fit.rss, fit.n, len(fit.free), fit.tau, fit.success, fit.message)


@dataclasses.dataclass(frozen=True)
class Ranges:
    """Physical ranges of the values a fit frees (module constants; heat bounded by the motor's rating)."""

    capacity_j_per_k: tuple[float, float]
    heat_max_w: float
    current_nominal_a: float

    def free(self, path: str) -> Free:
        name = path.rsplit(".", 1)[1]
        if name == "capacity_j_per_k":
            return Free(path, *self.capacity_j_per_k)
        if name == "resistance_k_per_w":
            return Free(path, *RESISTANCE_RANGE)
        if name == "speed_exponent":
            return Free(path, *IRON_EXPONENT_RANGE, log=False)
        if name == "factor":
            return Free(path, *AC_FACTOR_RANGE, log=False)
        if name == "loss_w_per_a2":
            return Free(path, 0.0, self.heat_max_w / self.current_nominal_a ** 2, log=False)
        if ".split." in path:
            return Free(path, 0.0, 1.0, log=False)
        if name in ("linear_w_s_per_rad", "quadratic_w_s2_per_rad2"):
            return Free(path, 0.0, math.inf, log=False)
        return Free(path, 0.0, self.heat_max_w, log=False)

    def all(self, spec: NetworkSpec) -> tuple[Free, ...]:
        return tuple(self.free(p) for p in free_paths(spec))


def node_placements(spec: NetworkSpec, node: str) -> list[tuple[str, NetworkSpec]]:
    """``node`` on each node's path to the sink (the link split in two), or beside each node with its own
    path to the sink; start values: half the node's capacity, the path's resistance shared."""
    out = []
    mean_r = float(np.mean([float(k.resistance_k_per_w) for k in sink_links(spec)]))
    for a in spec.node_names:
        cap = 0.5 * capacity(spec, a)
        sink = link(spec, a, AMBIENT)
        if sink is not None:
            r = float(sink.resistance_k_per_w)
            out.append((f"between {a} and {AMBIENT}",
                        with_node(spec, node, cap, {(a, node): r / 2, (node, AMBIENT): r / 2}, drop=sink)))
        out.append((f"beside {a}", with_node(spec, node, cap, {(a, node): mean_r, (node, AMBIENT): 2 * mean_r})))
    return out


def _start_values(kind: str, heat_w: float, ref_speed: float) -> dict[str, float]:
    return {"iron_losses": {"power_w": heat_w, "speed_exponent": 1.5, "ref_speed_rad_s": ref_speed},
            "friction_heating": {"linear_w_s_per_rad": heat_w / ref_speed / 2,
                                 "quadratic_w_s2_per_rad2": heat_w / ref_speed ** 2 / 2},
            "drive_heating": {"idle_w": heat_w, "loss_w_per_a2": 0.0},
            "constant": {"power_w": heat_w},
            "ac_copper": {"factor": 0.1, "ref_speed_rad_s": ref_speed}}[kind]


def room_links(spec: NetworkSpec) -> list[Addition]:
    """A link to the room from each node that has none (start: three times the mean sink resistance)."""
    r = 3.0 * float(np.mean([float(k.resistance_k_per_w) for k in sink_links(spec)]))
    return [Addition("room_link", node, dataclasses.replace(spec, links=spec.links + (LinkSpec((node, ROOM), r),)))
            for node in spec.node_names if link(spec, node, ROOM) is None]


def copper_bound(spec: NetworkSpec, kind: str, heat_w: float, ref_speed: float) -> list[Addition]:
    """``kind`` (a loss of the copper itself) with the copper's split."""
    copper = next((s for s in spec.sources if s.kind == "copper"), None)
    if copper is None or kind in spec.kinds:
        return []
    src = SourceSpec(kind, dict(copper.split), _start_values(kind, heat_w, ref_speed))
    return [Addition(kind, "+".join(copper.split), with_source(spec, src))]


def additions(spec: NetworkSpec, kinds: Sequence[str], heat_w: float, ref_speed: float,
              room: bool = False) -> list[Addition]:
    """Every allowed addition to ``spec`` (module docstring); ``room``: the recordings give the room's
    temperature."""
    out = [a for kind in kinds if kind in COPPER_BOUND for a in copper_bound(spec, kind, heat_w, ref_speed)]
    out += room_links(spec) if room else []
    kinds = [k for k in kinds if k in HEAT_KINDS and k not in COPPER_BOUND]
    for kind in (k for k in kinds if k not in spec.kinds):
        for node in spec.node_names:
            src = SourceSpec(kind, {node: 1.0}, _start_values(kind, heat_w, ref_speed))
            out.append(Addition(kind, node, with_source(spec, src)))
    for src in (s for s in spec.sources if s.kind in kinds):
        for node in (n for n in spec.node_names if n not in src.split):
            split = {n: 0.7 * share for n, share in src.split.items()} | {node: 0.3}
            out.append(Addition(src.kind, f"{node} (spread)", with_source(spec, dataclasses.replace(src, split=split))))
    hidden = f"node{len(spec.nodes)}"
    for where, grown in node_placements(spec, hidden):
        if where.startswith("between"):
            out.append(Addition("sink_node", f"{hidden} {where}", grown))
            continue
        for kind in kinds:
            src = SourceSpec(kind, {hidden: 1.0}, _start_values(kind, heat_w, ref_speed))
            out.append(Addition("source_node", f"{hidden} {where} hosting {kind}", with_source(grown, src)))
    return out


@dataclasses.dataclass(frozen=True)
class GrowthSettings:
    """``selection``: level and effect size of the nested tests; ``max_noise_ratio``: a sensor is explained
    when its RMSE is within this many residual-noise standard deviations; ``max_steps``: additions at most;
    ``screen_nfev``: optimiser evaluations of each addition tried (from the current values); ``max_nfev``: of
    the accepted one, refitted."""

    selection: SubsetSettings = SubsetSettings()
    max_noise_ratio: float = 3.0
    max_steps: int = 6
    screen_nfev: int = 25
    max_nfev: int = 80


class Grower:
    """Grows a network on ``grids`` (see the module docstring); ``residual_noise(fit) -> {node: sigma}``
    is the noise each sensor's residual is judged against."""

    def __init__(self, params: JointParameters, grids: Sequence[ThermalGrid], kinds: Sequence[str],
                 settings: GrowthSettings, residual_noise: Callable[[NetworkFit], dict], progress=None):
        self.params, self.grids, self.kinds, self.settings = params, list(grids), tuple(kinds), settings
        self.residual_noise, self.progress = residual_noise, progress
        self.sensor = params.thermal.sensor_node
        m, whole = params.motor, sum(float(n.capacity_j_per_k) for n in params.thermal.general.nodes)
        self.heat_max_w = max(100.0, 5.0 * m.resistance_ohm * m.current_nominal_a ** 2)
        self.ranges = Ranges((CAPACITY_SHARE[0] * whole, CAPACITY_SHARE[1] * whole), self.heat_max_w,
                             m.current_nominal_a)
        speeds = np.abs(np.concatenate([g.velocity for g in grids]))
        self.ref_speed = max(float(np.percentile(speeds, 95)), 1e-3)
        self.room = all(g.has_room for g in grids)
        sensors = dict.fromkeys(n for g in grids for n in g.sensors)
        self.noise = {n: sensor_noise(grids, n) for n in sensors}
        self._folds: dict[str, list[np.ndarray]] = {}

    def fit(self, spec: NetworkSpec, weights: Sequence[float] | None = None, screen: bool = False) -> NetworkFit:
        nfev = self.settings.screen_nfev if screen else self.settings.max_nfev
        fit = fit_network(self.params, spec, self.sensor, self.ranges.all(spec), self.grids, weights=weights,
                          noise=self.noise, max_nfev=nfev)
        if self.progress is not None:
            self.progress.update(1)
        return fit

    def explained(self, fit: NetworkFit) -> bool:
        sigma = self.residual_noise(fit)
        return all(fit.rmse(n) <= self.settings.max_noise_ratio * sigma[n] for n in fit.per_sensor())

    def place_sensors(self, spec: NetworkSpec) -> tuple[NetworkSpec, NetworkFit, list[Step]]:
        """Add a node for every measured node the network lacks, each where it fits best."""
        steps, fit = [], self.fit(spec)
        for node in self.noise:
            if node in spec.node_names:
                continue
            tried = [(where, self.fit(grown)) for where, grown in node_placements(spec, node)]
            where, fit = min(tried, key=lambda t: (not t[1].success, t[1].rss))
            spec = fit.spec
            steps.append(Step(Addition("sensor_node", f"{node} {where}", spec), fit, None, tried=len(tried)))
        return spec, fit, steps

    def step(self, fit: NetworkFit) -> tuple[Step | None, list[tuple[Addition, NetworkFit]]]:
        """Fit every addition to ``fit``'s network; the best one that passes the tests (None if none)."""
        tried = []
        for addition in additions(fit.spec, self.kinds, 0.1 * self.heat_max_w, self.ref_speed, self.room):
            new = self.fit(addition.spec, screen=True)
            if new.success:
                tried.append((dataclasses.replace(addition, spec=new.spec), new))
        base, s = subset_fit(fit), self.settings.selection
        tests = [(a, f, nested_test(base, subset_fit(f, frozenset({a.term})))) for a, f in tried]
        passing = [t for t in tests if t[2].significant(s.alpha, len(tests), s.min_rmse_drop)]
        for addition, new, test in self.preferred(passing, len(tests)):
            new = min((new, self.fit(new.spec)), key=lambda f: (not f.success, f.rss))
            test = nested_test(base, subset_fit(new, frozenset({addition.term})))
            check = self.held_out(addition.term, new.spec, fit.spec) if len(self.grids) > 1 else None
            if check is None or not check.withdraws:
                return Step(addition, new, test, check, len(tests)), tried
            log.info("%s withdrawn: %s", addition.label, check)
        return None, tried

    def preferred(self, passing: list, n_tests: int) -> list:
        """Passing additions, best first: among those the nested test cannot tell from the best fit, the heat
        source listed first in the motor's ``heat_sources`` (the file's order says what this motor has
        most), then the smallest residual."""
        if not passing:
            return []
        s = self.settings.selection
        best = min(passing, key=lambda t: t[1].rss)
        rank = {kind: k for k, kind in enumerate(self.kinds)}

        def tied(t) -> bool:
            return t is best or not nested_test(subset_fit(t[1]), subset_fit(best[1], frozenset({"best"}))).significant(
                s.alpha, n_tests, s.min_rmse_drop)
        return sorted(passing, key=lambda t: (not tied(t), rank.get(t[0].term, len(rank)), t[1].rss))

    def folds(self, spec: NetworkSpec) -> list[np.ndarray]:
        """Leave one segment out: the limit node's residual of each segment predicted by a fit of the others."""
        key = repr(spec)
        if key not in self._folds:
            out = []
            for r, grid in enumerate(self.grids):
                held = self.fit(spec, [float(k != r) for k in range(len(self.grids))])
                res = held.residuals.get((grid.name, "winding"))
                out.append(res if held.success and res is not None else np.array([np.inf]))
            self._folds[key] = out
        return self._folds[key]

    def held_out_rmse(self, spec: NetworkSpec) -> float:
        return float(np.sqrt(np.mean(np.concatenate(self.folds(spec)) ** 2)))

    def held_out(self, term: str, with_term: NetworkSpec, without: NetworkSpec) -> HeldOutCheck:
        scores = (self.held_out_rmse(with_term), self.held_out_rmse(without))
        if not all(map(math.isfinite, scores)):
            return HeldOutCheck(term, undecided="a fit of the other segments did not converge")
        return HeldOutCheck(term, *scores, self.noise.get("winding", 0.0), tuple(g.name for g in self.grids))

    def grow(self, spec: NetworkSpec) -> tuple[list[Step], NetworkFit, list[list[tuple[Addition, NetworkFit]]]]:
        """Place the sensors, then add until explained or nothing helps: (steps, final fit, every step's tries)."""
        spec, fit, steps = self.place_sensors(spec)
        tries = []
        while not self.explained(fit) and len(steps) < self.settings.max_steps:
            step, tried = self.step(fit)
            tries.append(tried)
            if step is None:
                break
            steps.append(step)
            fit = step.fit
        return steps, fit, tries
