"""The competing explanations of a thermal diagnosis that a designed experiment is to tell apart.

From a :class:`~thermo_ddp.diagnose.thermal.ThermalDiagnosis`, each undetermined heat term (an item of
``not_determinable``) becomes a *target* with its *rivals*: models that explain the recordings (fitted on
them, or silent on them) but predict differently elsewhere.  The reference is the diagnosis's chosen fit.

- a heat term the data could not test (no motion: ``friction_heating``, ``iron_losses``): the chosen fit
  plus that term at the parameter file's start value (friction heat = the file's friction power);
- a heat term the diagnosis could not settle (equivalent sets, parameters not identifiable, one speed):
  the fitted term sets that toggle it, or trade it for the heat it is confused with
  (:data:`CONFUSED`: a running loss against the drive's steady heat), all fitted by the diagnosis, that the
  recordings do not reject (:data:`RIVAL_RMSE_FACTOR`);
- every explanation with friction heat also as a purely linear and a purely quadratic law in the speed, equal
  at the data's median moving speed;
- the richest explanation (the most heat terms) with each value of a target term raised by
  :data:`PERTURBATION`: separating it from the explanation is measuring that value to the diagnosis's
  precision (a finite-difference sensitivity: the design then also excites what each value does).

Other items (a casing node, the copper's temperature coefficient) need measurements a current and motion
programme does not give (a winding thermometer, the motor voltage): they are listed as not targeted.
"""
from __future__ import annotations

import dataclasses
from typing import Mapping

import numpy as np

from ..diagnose._thermal_terms import MOVING_RAD_S, ONE_SPEED_SPREAD, SPEED_TERMS, term_keys
from ..identify.thermal import (FRICTION_KEYS, IRON_KEY, SENSOR_DRIVE_KEYS, ThermalModel, canonical_terms,
                                default_fixed, network_model, start_values, structure_name)

HEAT_TERMS = ("friction_heating", "drive_heating", "iron_losses")
CONFUSED = {"friction_heating": ("drive_heating",), "drive_heating": ("friction_heating",),
            "iron_losses": ("friction_heating",)}
# A fitted set whose RMSE exceeds the chosen one's by this factor is rejected by the recordings already (the misfit of a
# missing heat source is tens of noise levels, a tie is within a few per cent): not a rival.
RIVAL_RMSE_FACTOR = 1.5
PERTURBATION = 0.5         # a named parameter is identifiable within +-50 % (the diagnosis's rule)
UNSEEN_SPEED_RAD_S = 1.0   # where a friction heat never seen is split into its two laws (a typical joint speed)
_HEAT_KEYS = FRICTION_KEYS + SENSOR_DRIVE_KEYS + (IRON_KEY,)


@dataclasses.dataclass(frozen=True)
class Rival:
    """One explanation: a term set and its values (parameter-file keys)."""

    label: str
    terms: tuple[str, ...]
    values: Mapping[str, float]
    derived: bool = False   # a law or a perturbed value of another explanation (not an explanation of its own)


@dataclasses.dataclass(frozen=True)
class Target:
    """An undetermined item (``term``), why, and the rivals of the reference that would settle it."""

    term: str
    reason: str
    rivals: tuple[Rival, ...]


@dataclasses.dataclass(frozen=True)
class Explanations:
    """The reference (index 0 of :attr:`rivals`), the targets, the items not targeted (with why), and the
    common structure every explanation is simulated in (:attr:`model`; :meth:`theta` gives its values)."""

    reference: Rival
    targets: tuple[Target, ...]
    untargeted: tuple[dict, ...]
    model: ThermalModel

    @property
    def rivals(self) -> tuple[Rival, ...]:
        """The reference, then every distinct rival of the targets."""
        out = [self.reference]
        for t in self.targets:
            out += [r for r in t.rivals if r.label not in {o.label for o in out}]
        return tuple(out)

    def subset(self, keep) -> "Explanations":
        """Only the explanations at the indices ``keep`` (of :attr:`rivals`; 0, the reference, always kept); a
        target left without rivals is not targeted."""
        kept = {self.rivals[k].label for k in keep}
        targets, untargeted = [], list(self.untargeted)
        for t in self.targets:
            rivals = tuple(r for r in t.rivals if r.label in kept)
            if rivals:
                targets.append(dataclasses.replace(t, rivals=rivals))
            else:
                untargeted.append({"term": t.term, "reason": "its rivals predict what the reference predicts under "
                                                             "any programme within the limits"})
        return dataclasses.replace(self, targets=tuple(targets), untargeted=tuple(untargeted))

    @property
    def richest(self) -> Rival:
        """The explanation with the most heat terms (the first such): whose values the experiment must pin down."""
        return max((r for r in self.rivals if not r.derived), key=lambda r: len(set(r.terms) & set(HEAT_TERMS)))

    def target_keys(self) -> np.ndarray:
        """Mask over the common structure's free keys: the values of the target terms (in the richest explanation)."""
        keys = {k for t in self.targets for k in term_keys(t.term, self.richest.terms)}
        return np.array([k in keys for k in self.model.keys])

    def index(self, rival: Rival) -> int:
        return [r.label for r in self.rivals].index(rival.label)

    def theta(self, rival: Rival) -> np.ndarray:
        """The rival's values of the common structure's free keys; a heat it lacks is 0."""
        fallback = start_values(self.model.params, self.model.terms)
        out = []
        for key in self.model.keys:
            if key in rival.values:
                out.append(rival.values[key])
            elif key in _HEAT_KEYS:
                out.append(0.0)
            else:
                out.append(self.reference.values.get(key, fallback[key]))
        return np.array(out, float)


def _rival(terms, values: Mapping[str, float]) -> Rival:
    ordered = canonical_terms("one_node", terms)
    return Rival(structure_name(ordered), ordered, {k: float(v) for k, v in values.items()})


def _median_speed(diagnosis) -> float:
    speeds = np.abs(np.concatenate([g.velocity for g in diagnosis.grids if g.has_velocity] or [np.zeros(0)]))
    moving = speeds[speeds > MOVING_RAD_S]
    return float(np.median(moving)) if moving.size else 0.0


def _friction_laws(rival: Rival, speed: float) -> list[Rival]:
    """A rival's friction heat at ``speed`` as a purely linear and a purely quadratic law."""
    c1, c2 = (rival.values[k] for k in FRICTION_KEYS)
    heat = c1 * speed + c2 * speed ** 2
    if not heat > 0:
        return []
    base, name = dict(rival.values), rival.label
    return [Rival(f"{name} (linear in speed)", rival.terms,
                  base | {FRICTION_KEYS[0]: heat / speed, FRICTION_KEYS[1]: 0.0}, True),
            Rival(f"{name} (quadratic in speed)", rival.terms,
                  base | {FRICTION_KEYS[0]: 0.0, FRICTION_KEYS[1]: heat / speed ** 2}, True)]


def _fitted_rivals(diagnosis, term: str) -> list[Rival]:
    """Fitted sets that toggle ``term`` or trade it for a heat it is confused with (same nodes as chosen) and
    that the recordings do not reject (RMSE within :data:`RIVAL_RMSE_FACTOR` of the chosen fit's)."""
    chosen, fits = diagnosis.final_terms, diagnosis.fits
    sets = [chosen ^ {term}, *((chosen - {term}) | {p} for p in CONFUSED[term]),
            *(chosen | {term, p} for p in CONFUSED[term])]
    out = []
    for terms in dict.fromkeys(s for s in sets if s != chosen):
        fit = fits.get(terms)
        if (fit is not None and fit.success and network_model(terms) == network_model(chosen)
                and fit.rmse <= RIVAL_RMSE_FACTOR * diagnosis.final_fit.rmse):
            out.append(_rival(fit.terms, fit.parameters))
    return out


def _settled(diagnosis, term: str) -> bool:
    """A named term whose values the recordings pin down, seen at several speeds if it grows with the speed: its
    note can only be the held-out judgement (no experiment of current and motion changes which segments judge)."""
    fit = diagnosis.final_fit
    if term not in diagnosis.missing_physics or not all(fit.identifiable(k) for k in term_keys(term, fit.terms)):
        return False
    speeds = np.abs(np.concatenate([g.velocity for g in diagnosis.grids if g.has_velocity] or [np.zeros(0)]))
    moving = speeds[speeds > MOVING_RAD_S]
    return term not in SPEED_TERMS or (moving.size > 1 and np.percentile(moving, 95) > ONE_SPEED_SPREAD
                                       * np.percentile(moving, 5))


def _target(diagnosis, item: dict, reference: Rival) -> Target | None:
    term, chosen = item["term"], diagnosis.final_terms
    if term not in HEAT_TERMS or _settled(diagnosis, term):
        return None
    if term not in diagnosis.fits.get(chosen | {term}, diagnosis.final_fit).terms:  # never fitted: no motion
        start = start_values(diagnosis.params, canonical_terms("one_node", chosen | {term}))
        rivals = [_rival(chosen | {term}, dict(reference.values) | {k: start[k] for k in term_keys(term, ())})]
    else:
        rivals = _fitted_rivals(diagnosis, term)
    # every explanation with friction heat also as its two laws at the data's speed: only two speeds tell them apart
    speed = _median_speed(diagnosis) or UNSEEN_SPEED_RAD_S
    rivals += [law for r in [reference, *rivals] if "friction_heating" in r.terms for law in _friction_laws(r, speed)]
    return Target(term, item["reason"], tuple(rivals)) if rivals else None


def _perturbed(target: Target, richest: Rival, free: tuple[str, ...]) -> Target:
    """``target`` with the richest explanation's values of its term (those ``free`` in the common structure) each
    raised by :data:`PERTURBATION`: telling them apart is seeing that value to the precision the diagnosis asks
    of a named parameter."""
    keys = [k for k in term_keys(target.term, richest.terms) if k in free and richest.values.get(k, 0.0) > 0]
    extra = tuple(Rival(f"{richest.label} ({k} +{100 * PERTURBATION:.0f} %)", richest.terms,
                        dict(richest.values) | {k: richest.values[k] * (1 + PERTURBATION)}, True) for k in keys)
    return dataclasses.replace(target, rivals=target.rivals + extra)


def explanations(diagnosis) -> Explanations:
    """The reference, targets and untargeted items of a one-sensor thermal diagnosis (module docstring)."""
    fit = diagnosis.final_fit
    reference = _rival(fit.terms, fit.parameters)
    targets, untargeted, seen = [], [], set()
    for item in diagnosis.not_determinable:
        if item["term"] in seen:
            continue
        seen.add(item["term"])
        target = _target(diagnosis, item, reference)
        if target is None and _settled(diagnosis, item["term"]):
            untargeted.append({"term": item["term"], "reason": "named, its values identifiable: " + item["reason"]})
        elif target is None:
            untargeted.append({"term": item["term"], "reason": "a current and motion programme cannot settle it "
                                                             f"(needs: {item['experiment']})"})
        else:
            targets.append(target)
    union = set(reference.terms).union(*(r.terms for t in targets for r in t.rivals))
    expl = Explanations(reference, tuple(targets), tuple(untargeted), _common_model(diagnosis.params, union))
    richest = expl.richest
    return dataclasses.replace(expl, targets=tuple(_perturbed(t, richest, expl.model.keys)
                                                   if t.term in richest.terms else t for t in targets))


def _common_model(params, terms) -> ThermalModel:
    ordered = canonical_terms("one_node", terms)
    values = start_values(params, ordered)
    return ThermalModel(params, ordered, {k: values[k] for k in default_fixed(ordered)})
