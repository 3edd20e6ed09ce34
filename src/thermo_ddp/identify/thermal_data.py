"""Thermal identification data: a recording on its integration grid (held losses, kept samples, gaps)
and the winding's resistance thermometry from the motor voltage, with the settings of both and of the fit.
"""
from __future__ import annotations

import dataclasses
from typing import Mapping

import casadi as ca
import numpy as np

from ..model import motor
from .._config import checked_settings
from ..errors import InputError
from ..model.parameters import JointParameters
from ..model.thermal import feature_key, feature_value
from ..recordings import Recording

# Loss drivers held over each (sub-)step, (name in motor.losses_w, exponent): rows 1-3 and 5-9 of
# ThermalGrid.inputs; row 0 is the step length, row 4 the ambient, the last row the room (the second
# boundary).  The speed's powers 1.5 and 2.5 serve the iron loss of a fitted exponent
# (identify.network.SPEED_EXPONENTS); i^2 w^2 the AC copper loss.
DRIVERS = (("current_sq_a2", 1.0), ("friction_w", 1.0), ("speed_abs_rad_s", 2.0), ("speed_abs_rad_s", 1.0),
           ("speed_abs_rad_s", 1.5), ("speed_abs_rad_s", 2.5), ("current_sq_speed_sq", 1.0))
INPUT_ROWS = ("step_s", *(feature_key(*d) for d in DRIVERS[:3]), "ambient_c", *(feature_key(*d) for d in DRIVERS[3:]),
              "room_c")
BOUNDARY_ROWS = ("ambient_c", "room_c")  # inputs that are boundary temperatures, not loss drivers

@checked_settings("thermal settings", min_step_s="[0, inf)", max_step_s="(0, inf)", head_s="[0, inf)",
                  gap_factor="(1, inf)", gap_window_s="(0, inf)", max_nfev="[1, inf)", chi2_tolerance="(0, 1]",
                  thermometry_noise_v="(0, inf)", thermometry_min_current_a="(0, inf)",
                  thermometry_max_velocity_rad_s="(0, inf)", sensor_noise_c="(0, inf)")
class ThermalSettings:
    """Grid and optimiser settings.

    ``min_step_s``: merge samples closer than this (0: every sample is a grid point);
    ``max_step_s``: longest integration sub-step (gaps are cut into sub-steps);
    ``gap_factor``, ``gap_window_s``: an interval longer than ``gap_factor`` median sample steps is a
    gap; the losses held over it are the mean over ``gap_window_s`` on both sides;
    ``head_s``: span at the start of a recording whose median sets the initial offset of a
    recording the fit does not see (cross-validation); ``max_nfev``: optimiser evaluations;
    ``chi2_tolerance``: the optimiser stops when an iteration lowers the residual sum of squares by
    less than this many residual variances (a change of chi^2 far below 1 is statistically void;
    flat valleys of poorly identifiable parameters are not crawled along).

    Resistance thermometry (``voltage_thermometry``, used when a recording has ``voltage_v`` and the
    structure has a winding node apart from the sensor): at samples with |i| >= ``thermometry_min_current_a``
    and |v| <= ``thermometry_max_velocity_rad_s`` (the back-EMF is small there), the winding temperature
    T_w = T_ref + ((V - K_b N v) / (R_ref i) - 1) / alpha (report eqs. 2-4) is a second measurement.
    Its standard deviation is ``thermometry_noise_v`` / (R_ref alpha |i|) (voltage, current and velocity
    noise together, in volts); its rows are weighed against the sensor's ``sensor_noise_c``.
    """

    min_step_s: float = 0.0
    max_step_s: float = 2.0
    gap_factor: float = 4.0
    gap_window_s: float = 60.0
    head_s: float = 30.0
    max_nfev: int = 200
    chi2_tolerance: float = 0.05
    voltage_thermometry: bool = True
    thermometry_noise_v: float = 0.08
    thermometry_min_current_a: float = 1.0
    thermometry_max_velocity_rad_s: float = 0.05
    sensor_noise_c: float = 0.1



@dataclasses.dataclass(frozen=True)
class ThermalGrid:
    """A recording on its integration grid: kept samples and the held inputs of every sub-step."""

    name: str
    time_s: np.ndarray          # kept sample times (K,)
    measured_c: np.ndarray      # measured sensor temperature at the kept samples (K,)
    current_a: np.ndarray       # at the kept samples (for regimes and plots)
    velocity: np.ndarray        # at the kept samples (zeros when the recording has none)
    inputs: np.ndarray          # (len(INPUT_ROWS), S): the held INPUT_ROWS of every sub-step
    output_index: np.ndarray    # sub-step after which kept sample k+1 is reached (K-1,)
    has_velocity: bool
    has_ambient: bool
    winding_c: np.ndarray | None = None       # resistance thermometry at the kept samples (NaN: unusable)
    winding_weight: np.ndarray | None = None  # sensor_noise_c / its standard deviation (0: unusable)
    speed_source: str = "none"  # "velocity" (recorded), "position differences" or "none"
    sensors: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)  # node -> measured at kept samples
    ambient_c: np.ndarray | None = None  # at the kept samples (the file's ambient_c when not recorded)
    has_room: bool = False  # the recording has the room's temperature (``room_c``)

    @property
    def thermometry_samples(self) -> int:
        return 0 if self.winding_weight is None else int(np.count_nonzero(self.winding_weight))

    def __len__(self) -> int:
        return int(self.time_s.size)


def _velocity(rec: Recording) -> tuple[np.ndarray | None, str]:
    """The speed regressor and where it comes from: the recorded velocity when there is one (position
    differences at 1 Hz alias a 2.5 s curl and bias the speed-driven heat), else position differences."""
    if rec.velocity is not None:
        return np.asarray(rec.velocity, float), "velocity"
    if rec.position is not None and len(rec) > 2:
        return np.gradient(np.asarray(rec.position, float), rec.time_s), "position differences"
    return None, "none"


def thermal_grid(rec: Recording, params: JointParameters, settings: ThermalSettings | None = None,
                 sensor: str | None = None) -> ThermalGrid:
    """Validate ``rec`` (needs ``current_a`` and ``temperature_c``) and build its integration grid.
    ``sensors`` holds ``temperature_c`` under ``sensor`` (default: the file's sensor node) and every
    further measured node (:attr:`Recording.sensors`, ``node_<name>_c``)."""
    settings = settings or ThermalSettings()
    rec.require("current_a", "temperature_c")
    src = rec.source or rec.name
    if len(rec) < 3:
        raise InputError(src, "time_s", f"{len(rec)} samples", "a thermal fit needs at least 3 samples")
    t = np.asarray(rec.time_s, float)
    current = np.asarray(rec.current_a, float)
    velocity, speed_source = _velocity(rec)
    v = np.zeros_like(t) if velocity is None else velocity
    drivers = np.array(_drivers(params)(current[None, :], v[None, :]))
    ambient = np.full_like(t, params.thermal.ambient_c) if rec.ambient_c is None else np.asarray(rec.ambient_c, float)
    room = (np.asarray(rec.room_c, float) if rec.room_c is not None
            else np.full_like(t, params.thermal.room_c) if params.thermal.room_c is not None else ambient)
    features = _bridge_gaps(t, np.vstack([drivers[:3], ambient, drivers[3:], room]), settings)
    keep = _kept(t, settings.min_step_s)
    dt = np.diff(t)
    cum = np.concatenate([np.zeros((len(features), 1)), np.cumsum(features[:, :-1] * dt, axis=1)], axis=1)
    span = t[keep[1:]] - t[keep[:-1]]
    held = (cum[:, keep[1:]] - cum[:, keep[:-1]]) / span
    substeps = np.maximum(np.ceil(span / settings.max_step_s - 1e-9).astype(int), 1)
    inputs = np.vstack([np.repeat(span / substeps, substeps), np.repeat(held, substeps, axis=1)])
    thermometry = _thermometry(rec, params, settings, v, keep) if settings.voltage_thermometry else (None, None)
    measured = {sensor or params.thermal.sensor_node: np.asarray(rec.temperature_c, float)[keep]}
    measured |= {node: np.asarray(values, float)[keep] for node, values in rec.sensors.items()}
    return ThermalGrid(rec.name, t[keep], np.asarray(rec.temperature_c, float)[keep], current[keep], v[keep],
                       inputs, np.cumsum(substeps) - 1, velocity is not None, rec.ambient_c is not None, *thermometry,
                       speed_source=speed_source, sensors=measured, ambient_c=ambient[keep],
                       has_room=rec.room_c is not None)



def mean_room_c(grids) -> float | None:
    """The time-weighted mean room temperature of grids that record it (None when none does): the
    ``[thermal] room_c`` a file with room links is written with, for uses without a room column."""
    parts = [(g.inputs[0], g.inputs[INPUT_ROWS.index("room_c")]) for g in grids if g.has_room]
    if not parts:
        return None
    return float(sum(np.sum(h * r) for h, r in parts) / sum(np.sum(h) for h, _ in parts))


def split_at_gaps(rec: Recording, factor: float = 10.0, min_gap_s: float = 60.0,
                  min_samples: int = 12) -> tuple[list[Recording], int]:
    """The stretches of ``rec`` between gaps longer than ``factor`` median steps and ``min_gap_s`` (what
    heated the motor during a gap is unknown: each stretch starts from its own first measurement, as
    the contract's ``split_gaps_s``), and the number of samples in stretches shorter than ``min_samples``
    (left out).  Stretches are named ``name[k]`` when there is more than one."""
    t = np.asarray(rec.time_s, float)
    if t.size < 3:
        return [rec], 0
    dt = np.diff(t)
    cuts = np.flatnonzero(dt > max(factor * float(np.median(dt)), min_gap_s)) + 1
    if not cuts.size:
        return [rec], 0
    parts, skipped = [], 0
    for k, (a, b) in enumerate(zip(np.concatenate(([0], cuts)), np.concatenate((cuts, [t.size])))):
        if b - a < min_samples:
            skipped += int(b - a)
            continue
        parts.append(dataclasses.replace(rec.take(slice(int(a), int(b))), name=f"{rec.name}[{k}]"))
    return parts, skipped


def _thermometry(rec: Recording, params: JointParameters, settings: "ThermalSettings", velocity: np.ndarray,
                 keep: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Winding temperature from the motor voltage and its weight (see :class:`ThermalSettings`)."""
    if rec.voltage_v is None:
        return None, None
    m = params.motor
    i, v = np.asarray(rec.current_a, float)[keep], velocity[keep]
    usable = (np.abs(i) >= settings.thermometry_min_current_a) & (np.abs(v) <= settings.thermometry_max_velocity_rad_s)
    i_safe = np.where(usable, i, 1.0)
    emf = m.back_emf_v_s_per_rad * m.gear_ratio * v
    ohm = (np.asarray(rec.voltage_v, float)[keep] - emf) / (m.resistance_ohm * i_safe)
    winding = np.where(usable, m.resistance_ref_c + (ohm - 1.0) / m.copper_alpha_per_k, np.nan)
    sigma = settings.thermometry_noise_v / (m.resistance_ohm * m.copper_alpha_per_k * np.abs(i_safe))
    return winding, np.where(usable, settings.sensor_noise_c / sigma, 0.0)


def _bridge_gaps(t: np.ndarray, features: np.ndarray, settings: "ThermalSettings") -> np.ndarray:
    """Held losses over gaps (intervals longer than ``gap_factor`` median steps): the mean of the
    samples within ``gap_window_s`` on both sides, not the last sample (of an oscillating current
    one sample says little about the power during minutes without data)."""
    dt = np.diff(t)
    gaps = np.flatnonzero(dt > settings.gap_factor * np.median(dt))
    if not gaps.size:
        return features
    held = features.copy()
    for k in gaps:
        near = ((t >= t[k] - settings.gap_window_s) & (t <= t[k])) | \
               ((t >= t[k + 1]) & (t <= t[k + 1] + settings.gap_window_s))
        held[:, k] = features[:, near].mean(axis=1)
    return held


def _kept(t: np.ndarray, min_step_s: float) -> np.ndarray:
    """Indices of the kept samples: the first sample of every ``min_step_s`` bin, and the last."""
    if min_step_s <= 0:
        return np.arange(t.size)
    bins = np.floor((t - t[0]) / min_step_s)
    keep = np.flatnonzero(np.concatenate(([True], bins[1:] != bins[:-1])))
    return keep if keep[-1] == t.size - 1 else np.append(keep, t.size - 1)


def _drivers(params: JointParameters) -> ca.Function:
    """The DRIVERS at a sample's current and velocity (none depends on the temperature)."""
    i, v = ca.SX.sym("current_a"), ca.SX.sym("velocity_rad_s")
    losses = motor.losses_w(params.motor, i, v, params.motor.resistance_ref_c)
    return ca.Function("thermal_drivers", [i, v], [ca.vertcat(*(feature_value(losses, *d) for d in DRIVERS))],
                       ["current_a", "velocity_rad_s"], ["drivers"])
