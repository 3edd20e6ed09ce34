"""How a joint moves, as a careful operator checks it (:class:`MotionQuality`)."""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class MotionQuality:
    """What a careful operator checks on a joint's motion: how often it reverses (speeds under
    ``still_rad_s`` ignored), how fast it moves within ``near_rad`` of a stop, whether it ends at rest and
    inside its range, and its largest acceleration."""

    reversals: int
    max_speed_near_stop_rad_s: float
    final_speed_rad_s: float
    max_acceleration_rad_s2: float
    inside_range: bool

    @classmethod
    def of(cls, time_s, q, v, lower_rad: float, upper_rad: float, near_rad: float = 0.1,
           still_rad_s: float = 0.02) -> "MotionQuality":
        q, v, t = (np.asarray(a, float).ravel() for a in (q, v, time_s))
        signs = np.sign(v[np.abs(v) > still_rad_s])
        near = (q > upper_rad - near_rad) | (q < lower_rad + near_rad)
        return cls(int(np.count_nonzero(signs[1:] != signs[:-1])),
                   float(np.abs(v[near]).max()) if near.any() else 0.0, float(abs(v[-1])),
                   float(np.abs(np.diff(v) / np.diff(t)).max()),
                   bool(np.all((q >= lower_rad - 1e-9) & (q <= upper_rad + 1e-9))))

