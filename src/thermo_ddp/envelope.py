"""Where a parameter file holds: the operating envelope of recordings (``[envelope]`` of the file) and the
check of new recordings against it.

The quantities (:data:`~thermo_ddp.model.catalogue.ENVELOPE_QUANTITIES`): ``current_a`` and
``speed_rad_s`` as magnitudes (|current_a|, |velocity|), ``ambient_c``, ``temperature_c`` (the
measured sensor) and ``room_c`` (the second boundary) as recorded.  A quantity a recording does not carry is left out.  ``identify`` and
``diagnose`` write :func:`envelope_of` their recordings into the file; ``validate`` checks a recording
against it (:func:`check_envelope`): a quantity is outside when its range here reaches beyond the
identified range by more than ``tolerance`` of that range's width (sensor noise and the last samples
of a stretch are not a new regime).
"""
from __future__ import annotations

import dataclasses
from typing import Mapping, Sequence

import numpy as np

from .model.catalogue import ENVELOPE_QUANTITIES
from .recordings import Recording

TOLERANCE = 0.05  # of the identified range's width; see the module docstring


def _quantities(rec: Recording) -> dict[str, np.ndarray]:
    signals = {"current_a": None if rec.current_a is None else np.abs(rec.current_a),
               "speed_rad_s": None if rec.velocity is None else np.abs(rec.velocity),
               "ambient_c": rec.ambient_c, "temperature_c": rec.temperature_c, "room_c": rec.room_c}
    return {k: v for k, v in signals.items() if v is not None}


def envelope_of(recordings: Sequence[Recording]) -> dict[str, tuple[float, float]]:
    """The range of every envelope quantity over ``recordings`` (``[envelope]`` of a file written from
    them); quantities none of them carries are left out."""
    ranges: dict[str, list[float]] = {}
    for rec in recordings:
        for name, values in _quantities(rec).items():
            lo, hi = ranges.get(name, (np.inf, -np.inf))
            ranges[name] = [min(lo, float(values.min())), max(hi, float(values.max()))]
    return {name: (ranges[name][0], ranges[name][1]) for name in ENVELOPE_QUANTITIES if name in ranges}


@dataclasses.dataclass(frozen=True)
class QuantityCheck:
    """One quantity: the range identified and the range here; ``below_by`` / ``above_by`` how far here
    reaches beyond it (0 inside), in the quantity's unit."""

    name: str
    identified: tuple[float, float]
    here: tuple[float, float]
    tolerance: float

    @property
    def below_by(self) -> float:
        return max(0.0, self.identified[0] - self.here[0])

    @property
    def above_by(self) -> float:
        return max(0.0, self.here[1] - self.identified[1])

    @property
    def outside(self) -> bool:
        slack = self.tolerance * (self.identified[1] - self.identified[0])
        return max(self.below_by, self.above_by) > slack

    def describe(self) -> str:
        unit = ENVELOPE_QUANTITIES[self.name]
        delta = "K" if unit == "°C" else unit
        side = (f"{self.above_by:.3g} {delta} above" if self.above_by >= self.below_by
                else f"{self.below_by:.3g} {delta} below")
        return (f"{self.name} {self.here[0]:.4g}..{self.here[1]:.4g} {unit}, {side} the identified "
                f"{self.identified[0]:.4g}..{self.identified[1]:.4g} {unit}")

    def to_dict(self) -> dict:
        return {"identified": list(self.identified), "here": list(self.here), "outside": self.outside,
                "below_by": self.below_by, "above_by": self.above_by}


@dataclasses.dataclass(frozen=True)
class EnvelopeCheck:
    """Recordings against a file's ``[envelope]`` (``known`` False: the file has none)."""

    quantities: tuple[QuantityCheck, ...]
    known: bool

    @property
    def outside(self) -> bool:
        return any(q.outside for q in self.quantities)

    @property
    def message(self) -> str:
        if not self.known:
            return "the file has no [envelope]: where its values were identified is unknown"
        outside = [q.describe() for q in self.quantities if q.outside]
        if not outside:
            return "inside the envelope the file was identified on"
        return "used where it was never identified: " + "; ".join(outside)

    def to_dict(self) -> dict:
        """The Validate JSON's ``envelope``: ``{"outside", "quantities": {name: {"identified", "here", ...}},
        "known"}`` (``known`` false: the file has no [envelope], so ``outside`` false says nothing)."""
        return {"outside": self.outside, "quantities": {q.name: q.to_dict() for q in self.quantities},
                "known": self.known}


def check_envelope(identified: Mapping[str, tuple[float, float]], recordings: Sequence[Recording],
                   tolerance: float = TOLERANCE) -> EnvelopeCheck:
    """Each quantity of the file's envelope that the recordings carry, identified range against theirs."""
    here = envelope_of(recordings)
    checks = tuple(QuantityCheck(name, tuple(identified[name]), here[name], tolerance)
                   for name in ENVELOPE_QUANTITIES if name in identified and name in here)
    return EnvelopeCheck(checks, bool(identified))
