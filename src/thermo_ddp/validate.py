"""Validation of a parameter file on recordings: predict, do not refit (``thermo-ddp validate``).

Each recording (each segment of a split CSV) is simulated open loop with the file's thermal network
(``network_from_parameters``, heated through ``joint_heat_rhs``) from every node at the segment's first
measured temperature, with the recorded current, speed and ambient held over each step of a
``grid_s`` grid (losses averaged exactly over the step, :func:`thermal_grid`), integrated by the
trapezoidal rule solved exactly for the network (affine in the temperatures over a step).  The error
is the predicted sensor node minus the measurement at the grid's kept samples.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

from ._figures import new_figure
from .errors import InputError
from .identify.thermal import load_joint_parameters
from .identify.thermal_data import INPUT_ROWS, ThermalGrid, ThermalSettings, thermal_grid
from .model.parameters import JointParameters
from .model.thermal import joint_heat_rhs, network_from_parameters
from .recordings import RecordingSet, as_recordings, read_recordings

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class ValidateSettings:
    """``grid_s``: step of the prediction grid (samples closer than this are merged, the losses held
    over a step are its exact means; thermal time constants are tens of seconds and more)."""

    grid_s: float = 1.0

    def __post_init__(self) -> None:
        if not (isinstance(self.grid_s, (int, float)) and math.isfinite(self.grid_s) and self.grid_s > 0):
            raise InputError("validate settings", "grid_s", self.grid_s, "must be a finite number > 0")


@dataclasses.dataclass(frozen=True)
class Prediction:
    """One recording: measured and predicted sensor temperature at the kept samples."""

    recording: str
    time_s: np.ndarray
    measured_c: np.ndarray
    predicted_c: np.ndarray

    @property
    def error_c(self) -> np.ndarray:
        return self.predicted_c - self.measured_c

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.error_c ** 2)))

    @property
    def max_abs_error(self) -> float:
        return float(np.max(np.abs(self.error_c)))

    def to_dict(self) -> dict:
        return {"recording": self.recording, "rmse": self.rmse, "max_abs_error": self.max_abs_error,
                "samples": int(self.time_s.size)}


@dataclasses.dataclass(frozen=True)
class Validation:
    """Result of :func:`validate_thermal` (``to_dict()``: the contract's Validate JSON plus ``rows``)."""

    model: str
    predictions: tuple[Prediction, ...]
    rows: dict = dataclasses.field(default_factory=dict)

    @property
    def success(self) -> bool:
        return all(np.all(np.isfinite(p.predicted_c)) for p in self.predictions)

    @property
    def status(self) -> str:
        return "ok" if self.success else "not_finite"

    @property
    def message(self) -> str:
        if self.success:
            return f"predicted {len(self.predictions)} recordings with the file as it is (no refit)"
        bad = [p.recording for p in self.predictions if not np.all(np.isfinite(p.predicted_c))]
        return f"the prediction diverged (thermal runaway?) on {', '.join(bad)}"

    @property
    def rmse(self) -> float:
        errors = np.concatenate([p.error_c for p in self.predictions])
        return float(np.sqrt(np.mean(errors ** 2)))

    @property
    def max_abs_error(self) -> float:
        return max(p.max_abs_error for p in self.predictions)

    def to_dict(self) -> dict:
        if not self.success:
            return {"success": False, "status": self.status, "message": self.message, "model": self.model,
                    "recordings": [p.recording for p in self.predictions], "rmse": None, "max_abs_error": None,
                    "per_recording": [], "rows": dict(self.rows)}
        return {"success": True, "status": self.status, "message": self.message, "model": self.model,
                "recordings": [p.recording for p in self.predictions], "rmse": self.rmse,
                "max_abs_error": self.max_abs_error, "per_recording": [p.to_dict() for p in self.predictions],
                "rows": dict(self.rows)}

    def report(self) -> str:
        lines = [f"validate {self.model}: {self.status} ({self.message})"]
        if self.success:
            lines += [f"  {p.recording}: rmse {p.rmse:.3g} K, worst {p.max_abs_error:.3g} K, {p.time_s.size} samples"
                      for p in self.predictions]
            lines.append(f"all: rmse {self.rmse:.3g} K, worst {self.max_abs_error:.3g} K")
        return "\n".join(lines)

    def plot(self, path: str | Path, max_recordings: int = 4) -> Path:
        """Measured and predicted sensor temperature (top) and the error (bottom), per recording."""
        shown = self.predictions[:max_recordings]
        fig, axes = new_figure(2, len(shown), figsize=(6 * len(shown), 6), sharex="col", squeeze=False)
        for c, p in enumerate(shown):
            axes[0, c].plot(p.time_s, p.measured_c, "k.", ms=1.5, label="recorded")
            axes[0, c].plot(p.time_s, p.predicted_c, lw=1.0, label=f"predicted ({Path(self.model).name})")
            axes[1, c].plot(p.time_s, p.error_c, lw=0.8, label=f"rmse {p.rmse:.3g} K, worst {p.max_abs_error:.3g} K")
            axes[0, c].set(title=p.recording, ylabel="sensor temperature [°C]")
            axes[1, c].set(xlabel="time [s]", ylabel="predicted - recorded [K]")
            for ax in axes[:, c]:
                ax.legend(fontsize=8, loc="best")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        return Path(path)


def _simulator(params: JointParameters) -> tuple[ca.Function, int]:
    """(one step of every node over a held-input step of the grid, index of the sensor node)."""
    network = network_from_parameters(params.thermal)
    temps = ca.SX.sym("temperatures_c", len(network.nodes))
    u = ca.SX.sym("inputs", len(INPUT_ROWS))
    row = dict(zip(INPUT_ROWS, ca.vertsplit(u)))
    held = {k: row[k] for k in INPUT_ROWS[1:] if k != "ambient_c"}
    rhs = joint_heat_rhs(network, params.motor, temps, ca.sqrt(row["current_sq_a2"]), 0.0, row["ambient_c"], held)
    h = row["step_s"]
    trapezoid = temps + h * ca.solve(ca.SX.eye(temps.numel()) - 0.5 * h * ca.jacobian(rhs, temps), rhs)
    return ca.Function("validate_step", [temps, u], [trapezoid]), network.index(network.sensor_node)


def _predict(step: ca.Function, sensor: int, grid: ThermalGrid) -> Prediction:
    x0 = np.full(step.size1_in(0), grid.measured_c[0])
    states = np.asarray(step.mapaccum(grid.inputs.shape[1])(x0, grid.inputs))
    predicted = np.concatenate([[grid.measured_c[0]], states[sensor, grid.output_index]])
    return Prediction(grid.name, grid.time_s, grid.measured_c, predicted)


def validate_thermal(recordings, parameters: JointParameters | str | Path,
                     settings: ValidateSettings | None = None, rows: dict | None = None) -> Validation:
    """Predict ``recordings`` (``current_a``, ``temperature_c``; ``velocity`` and ``ambient_c`` when
    logged) with the parameter file ``parameters`` as it is; report the error per recording."""
    settings = settings or ValidateSettings()
    params = load_joint_parameters(parameters)
    recs = as_recordings(recordings, "validate")
    grid_settings = ThermalSettings(min_step_s=settings.grid_s, max_step_s=settings.grid_s, voltage_thermometry=False)
    grids = [thermal_grid(r, params, grid_settings) for r in recs]
    step, sensor = _simulator(params)
    name = parameters if isinstance(parameters, (str, Path)) else params.path
    result = Validation(str(name), tuple(_predict(step, sensor, g) for g in grids),
                        rows or {"used": sum(len(r) for r in recs), "skipped": 0, "segments": len(recs)})
    if not result.success:
        log.warning("%s: %s", result.model, result.message)
    return result


def validate_files(paths: Sequence[str | Path], parameters: str | Path, columns=None,
                   settings: ValidateSettings | None = None) -> Validation:
    """CLI entry (``thermo-ddp validate``): CSV paths (and a column map) -> :class:`Validation`."""
    params = load_joint_parameters(parameters)  # bad file: refused before the recordings are read
    recordings: RecordingSet = read_recordings(paths, columns)
    result = validate_thermal(list(recordings.recordings), params, settings, recordings.rows)
    return dataclasses.replace(result, model=str(parameters))
