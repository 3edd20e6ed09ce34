"""Thermal diagnosis of recordings with several sensors (or of a ``model = "network"`` file): the network
grows (:mod:`~thermo_ddp.diagnose.growth`) and the result speaks the diagnosis JSON of the contract, with
per-sensor errors, the grown network, and a parameter file that says what was learned and where it holds
(``[uncertainty]``, ``[envelope]``, ``[[alternatives]]``).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from tqdm import tqdm

from .._figures import new_figure
from ..model.network_spec import ROOM, NetworkSpec
from ..identify.network import FIXED_VALUES, values_of
from ..identify.network_fit import NetworkFit
from ..model.catalogue import SOURCE_KINDS
from ..identify.thermal_data import ThermalGrid, mean_room_c
from ..model.parameters import JointParameters, ThermalParameters
from ._thermal_localise import noise_model
from ._thermal_terms import beyond_envelope
from ._thermal_result import ThermalOutcome
from .growth import GROWTH_TERMS, HEAT_KINDS, Addition, GrowthSettings, Grower, Step, subset_fit
from .localise import ResidualSeries
from .selection import nested_test

LIMIT_NODE = "winding"
HELD_OUT = ("leave_one_segment_out: each segment (recording or stretch between gaps) predicted from its first "
            "readings by a fit of the others; RMSE of the winding")


def residual_noise(grids: Sequence[ThermalGrid], window_s: float):
    """``fit -> {sensor: sigma}``: the high-passed residual noise of each sensor (as the one-sensor diagnosis)."""
    def noise(fit: NetworkFit) -> dict[str, float]:
        out = {}
        for node in fit.per_sensor():
            parts = [noise_model(ResidualSeries(g.name, g.time_s, fit.residuals[(g.name, node)],
                                                np.full(len(g), "any")), window_s).sigma_c ** 2
                     for g in grids if (g.name, node) in fit.residuals]
            out[node] = max(math.sqrt(float(np.mean(parts))), fit.noise_c[node])
        return out
    return noise


@dataclasses.dataclass(frozen=True)
class NetworkDiagnosis(ThermalOutcome):
    """Result of :func:`diagnose_network`; ``to_dict()`` is the contract's diagnosis JSON."""

    baseline: NetworkFit
    final: NetworkFit
    steps: tuple[Step, ...]
    alternatives: tuple[dict, ...] = ()
    validation: tuple[float, float] | None = None  # held-out winding RMSE: baseline, final
    residual_sigma: dict = dataclasses.field(default_factory=dict)
    rows: dict = dataclasses.field(default_factory=dict)
    envelope: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)  # what the recordings cover

    @property
    def missing_physics(self) -> list[str]:
        return [s.addition.term for s in self.steps]

    def step_report(self, step: Step, before: NetworkFit) -> dict:
        fit, test = step.fit, step.test
        new = {p: v for p, v in fit.values.items() if p not in before.values}
        evidence = f"{step.addition.label}: winding RMSE {before.rmse():.3g} -> {fit.rmse():.3g} K"
        if test is None:
            evidence += (f" (the recordings measure it: placed where it fits best of {step.tried} places; "
                         "not a hypothesis, not tested)")
        else:
            evidence += (f", noise-weighted RMSE -{100 * test.rmse_drop:.0f}%, likelihood ratio {test.statistic:.1f} "
                         f"on {test.df} df, p = {test.p_value:.2g} ({step.tried} additions tried, Bonferroni; "
                         f"effective samples n/tau = {test.large.n / test.large.tau:.0f})")
        if step.held_out is not None:
            evidence += f"; leaving one segment out: {step.held_out}"
        unc = fit.uncertainty()
        return {"term": step.addition.term, "where": step.addition.where, "evidence": evidence, "parameters": new,
                "rmse": fit.rmse(), "per_sensor": fit.per_sensor(),
                "p_value": test.p_value if test is not None else None,
                "effect_k": float(np.sqrt(np.mean(np.concatenate([fit.simulated[g.name][0] - before.simulated[g.name][0]
                                                                  for g in self.grids]) ** 2))),
                "ci95": {p: unc[p] for p in new if p in unc}, "collinear_with": []}

    def not_determinable(self) -> list[dict]:
        out = []
        beyond, speeds = beyond_envelope(self.envelope)
        for p, (lo, hi) in self.final.undetermined().items():
            if not p.endswith("_w_s_per_rad"):
                out.append({"term": p, "reason": f"95 % interval {lo:.3g} to {hi:.3g}: not pinned down by these data",
                            "experiment": beyond})
        for alt in self.alternatives:
            out.append({"term": "+".join(alt["terms"]), "reason": f"fits as well as the chosen source (winding RMSE "
                        f"{alt['rmse']:.3g} K): written as an alternative", "experiment": "the same currents at two or "
                        f"more speeds{speeds} until the temperatures settle: a speed-dependent loss changes, a constant "
                        "does not"})
        return out

    def network_section(self) -> dict:
        """The final network as the file's [thermal] section; with links to the room and no ``room_c`` in the
        file, the recordings' mean room temperature as ``room_c``."""
        room = self.params.thermal.room_c
        if room is None and any(ROOM in k.between for k in self.final.spec.links):
            room = mean_room_c(self.grids)
        return network_section(self.final.spec, self.params.thermal.ambient_c, self.final.sensor, room)

    def parameter_file(self) -> dict | None:
        """The improved file: the grown network with [uncertainty], [covariance], [envelope] and [[alternatives]]."""
        if not self.final.success:
            return None
        data = self.params.to_dict()
        data["thermal"] = self.network_section()
        data["uncertainty"] = self.final.uncertainty()
        data.pop("covariance", None)
        if self.final.covariance() is not None:
            data["covariance"] = self.final.covariance().to_dict()
        data["envelope"] = {k: list(v) for k, v in self.envelope.items()}
        if self.alternatives:
            data["alternatives"] = [{"terms": a["terms"], **a["values"]} for a in self.alternatives]
        where = ", ".join(self.recordings)
        data["sources"] = {k: v for k, v in data["sources"].items() if k not in ("capacity_j_per_k", "resistance_k_per_w")}
        data["sources"]["thermal"] = f"network grown and identified by thermo-ddp diagnose from {where}"
        return data

    def to_dict(self) -> dict:
        befores = [self.baseline] + [s.fit for s in self.steps[:-1]]
        out = {"success": self.success, "status": self.status, "message": self.message, "physics": "thermal",
               "recordings": list(self.recordings), "rows": dict(self.rows),
               "baseline": _summary(self.baseline), "mismatches": [],
               "missing_physics": [self.step_report(s, b) for s, b in zip(self.steps, befores)],
               "not_determinable": self.not_determinable(), "final": _summary(self.final),
               "network": self.network_section(),
               "noise": {"sensor_c": dict(self.final.noise_c), "residual_c": dict(self.residual_sigma)},
               "alternatives": list(self.alternatives), "unexplained": [], "validation": None,
               "parameter_file": self.parameter_file()}
        if self.validation is not None:
            out["validation"] = {"method": HELD_OUT, "rmse_before": self.validation[0], "rmse_after": self.validation[1]}
        return out

    def report(self) -> str:
        lines = [f"thermal diagnosis of {', '.join(self.recordings)}: {self.status} ({self.message})",
                 f"baseline {_describe(self.baseline.spec)}: winding rmse {self.baseline.rmse():.3g} K"]
        for entry in self.to_dict()["missing_physics"]:
            lines.append(f"  + {entry['evidence']}")
        lines += [f"  alternative: {'+'.join(a['terms'])} (winding rmse {a['rmse']:.3g} K)" for a in self.alternatives]
        lines.append(f"final {_describe(self.final.spec)}: " + ", ".join(
            f"{n} {r:.3g} K ({r / self.residual_sigma.get(n, math.inf):.1f} x noise)"
            for n, r in self.final.per_sensor().items()))
        if self.validation is not None:
            lines.append(f"held out (winding): {self.validation[0]:.3g} -> {self.validation[1]:.3g} K")
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 3) -> Path:
        """Every sensor measured and simulated (baseline dashed, final solid), per recording."""
        grids = self.grids[:max_recordings]
        fig, axes = new_figure(1, len(grids), figsize=(8 * len(grids), 5), squeeze=False)
        for ax, grid in zip(axes[0], grids):
            for node, measured in grid.sensors.items():
                line = ax.plot(grid.time_s, measured, ".", ms=1.5, label=f"{node} recorded")[0]
                for fit, style in ((self.baseline, "--"), (self.final, "-")):
                    if node in fit.spec.node_names:
                        ax.plot(grid.time_s, fit.simulated[grid.name][fit.spec.node_names.index(node)], style,
                                color=line.get_color(), lw=1.0)
            ax.set(title=f"{grid.name}: {self.status} (dashed: baseline, solid: final)", xlabel="time [s]",
                   ylabel="temperature [°C]")
            ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        return Path(path)


def network_section(spec: NetworkSpec, ambient_c: float, sensor: str, room_c: float | None = None) -> dict:
    """The file's [thermal] section of a network (``model = "network"``)."""
    return ThermalParameters("network", ambient_c, {}, sensor, network=spec, room_c=room_c).to_dict()


def _describe(spec: NetworkSpec) -> str:
    return (f"network of {len(spec.nodes)} node(s) ({', '.join(spec.node_names)}; heat: "
            f"{', '.join(s.label for s in spec.sources)})")


def _summary(fit: NetworkFit) -> dict:
    return {"model": _describe(fit.spec), "rmse": fit.rmse(LIMIT_NODE), "per_sensor": fit.per_sensor(),
            "parameters": fit.values, "success": fit.success, "status": fit.status}


def alternatives(steps: Sequence[Step], tries: Sequence[Sequence[tuple[Addition, NetworkFit]]],
                 settings: GrowthSettings, final: NetworkSpec) -> tuple[dict, ...]:
    """Heat sources of another kind that the nested test cannot tell from a chosen one, with their values; not
    of a kind the ``final`` network has (a later step chose it: it is no alternative, and its values, written
    over the file's own source of that kind, would not be the network that was fitted)."""
    out = []
    tested = [s for s in steps if s.test is not None]
    for step, tried in zip(tested, tries):
        if step.addition.term not in HEAT_KINDS or step.addition.where.endswith("(spread)"):
            continue
        chosen = step.fit
        for addition, fit in tried:
            if addition.term == step.addition.term or addition.term in GROWTH_TERMS or addition.term in final.kinds:
                continue
            test = nested_test(subset_fit(fit), subset_fit(chosen, frozenset({"chosen"})))
            if not test.significant(settings.selection.alpha, len(tried), settings.selection.min_rmse_drop):
                values = {p: float(v) for p, v in values_of(fit.spec).items()
                          if p.startswith(f"thermal.source.{addition.term}.")}
                values |= {f"thermal.source.{step.addition.term}.{k}": 0.0 for k in SOURCE_KINDS[step.addition.term]
                           if k not in FIXED_VALUES and k != "speed_exponent"}  # the chosen source's heat off
                out.append({"terms": [addition.term], "instead_of": [step.addition.term], "where": addition.where,
                            "rmse": fit.rmse(), "values": values})
    best: dict[str, dict] = {}
    for alt in out:  # one per kind: its best placement
        if alt["terms"][0] not in best or alt["rmse"] < best[alt["terms"][0]]["rmse"]:
            best[alt["terms"][0]] = alt
    return tuple(best.values())


def diagnose_network(params: JointParameters, grids: Sequence[ThermalGrid], *, settings: GrowthSettings | None = None,
                     window_s: float = 120.0, progress: bool | None = None, rows: dict | None = None,
                     envelope: Mapping[str, tuple[float, float]] | None = None) -> NetworkDiagnosis:
    """Grow the file's network on ``grids`` (every sensor) and judge the result (module docstring);
    ``progress``: a tqdm bar over the fits (None: only on a terminal)."""
    settings = settings or GrowthSettings()
    spec = params.thermal.general
    with tqdm(desc="network growth fits", unit="fit", disable=None if progress is None else not progress) as bar:
        grower = Grower(params, grids, params.scope.allowed_sources, settings, residual_noise(grids, window_s), bar)
        baseline = grower.fit(spec)
        steps, final, tries = grower.grow(spec)
        validation = None
        if len(grids) > 1:
            validation = (grower.held_out_rmse(baseline.spec), grower.held_out_rmse(final.spec))
    sigma = grower.residual_noise(final)
    explained = grower.explained(final)
    worst = max(final.per_sensor(), key=lambda n: final.rmse(n) / sigma[n])
    message = (f"{_describe(final.spec)}: winding rmse {final.rmse():.3g} K; worst sensor {worst} "
               f"{final.rmse(worst):.3g} K = {final.rmse(worst) / sigma[worst]:.1f} x its residual noise")
    if not explained:
        message += (f" (> {settings.max_noise_ratio:g}): no allowed addition (node, link or heat source of "
                    f"{', '.join(grower.kinds)}) explains what is left")
    return NetworkDiagnosis(tuple(g.name for g in grids), params, tuple(grids), explained and final.success,
                            "ok" if explained and final.success else "model_does_not_fit", message, baseline, final,
                            tuple(steps), alternatives(steps, tries, settings, final.spec), validation, sigma, rows or {},
                            envelope or {})
