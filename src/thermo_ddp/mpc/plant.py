"""The "real" elbow of the closed loop: a model whose parameters differ from the planner's,
integrated finely between control periods, seen only through noisy, quantised sensors that may
be late, drop samples, send NaN or stale values, or stick; the room may warm up meanwhile."""
from __future__ import annotations

import collections
import dataclasses
from typing import Mapping

import numpy as np

from ..model.actuated import ActuatedArm
from .settings import MPCSettings


def perturbed_model(model: ActuatedArm, resistance_scale: float = 1.0, capacity_scale: float = 1.0,
                    thermal_scales: Mapping[str, float] | None = None, friction_scale: float = 1.0,
                    payload_scale: float = 1.0) -> ActuatedArm:
    """The same arm with every thermal resistance (``*_k_per_w``) and heat capacity (``*_j_per_k``) scaled,
    then each ``[thermal]`` key in ``thermal_scales`` scaled, viscous and Coulomb friction times
    ``friction_scale`` and the payload times ``payload_scale``."""
    scales = dict(thermal_scales or {})
    params = {}
    for joint, p in model.params.items():
        values = {k: v * resistance_scale for k, v in p.thermal.values.items() if k.endswith("_k_per_w")}
        values.update({k: v * capacity_scale for k, v in p.thermal.values.items() if k.endswith("_j_per_k")})
        for key, scale in scales.items():
            if key not in p.thermal.values:
                raise KeyError(f"{key!r} is not a [thermal] value of {joint}")
            values[key] = values.get(key, p.thermal.values[key]) * scale
        p = p.replace("thermal", **values)
        if friction_scale != 1.0:
            m = p.motor
            p = p.replace("motor", viscous_friction_nm_s_per_rad=m.viscous_friction_nm_s_per_rad * friction_scale,
                          coulomb_friction_nm=m.coulomb_friction_nm * friction_scale)
        params[joint] = p
    arm = model.arm.settings
    if payload_scale != 1.0:
        arm = dataclasses.replace(arm, payload_kg=arm.payload_kg * payload_scale)
    return ActuatedArm.from_parameters(arm, params)


@dataclasses.dataclass(frozen=True)
class Measurement:
    """What the controller sees at one control instant; ``casing_c`` is None when no sample arrived
    (a delivered sample may still be NaN or stale). ``voltage_v``: the motor voltage of the period that
    just ended at this instant; ``ambient_c``: the room thermometer (None: not measured)."""

    time_s: float
    q_rad: np.ndarray
    v_rad_s: np.ndarray
    current_a: np.ndarray     # measured current of the period that just ended
    casing_c: np.ndarray | None
    voltage_v: np.ndarray | None = None
    ambient_c: float | None = None


class Plant:
    """The elbow: state x = [q, v, T_nodes] of ``model`` integrated by RK4 sub-steps, currents clipped to the peak.

    The casing sensor adds Gaussian noise, then quantises; it may be delayed by whole control
    periods and drop samples, deliver NaN or the previous value again (stale), or stick at its
    reading. The 84 °C safety cut-off acts on this measured casing value. Fault draws use their own
    random stream, so a scenario without faults sees the same noise as before they existed.
    """

    def __init__(self, model: ActuatedArm, x0: np.ndarray, settings: MPCSettings, rng: np.random.Generator):
        self.model, self.settings, self.rng = model, settings, rng
        self.fault_rng = np.random.default_rng((settings.scenario.seed, 1))
        self.x = np.array(x0, dtype=float)
        self.time_s = 0.0
        self.current_a = np.zeros(model.nu)
        dt = settings.controller.control_period_s / settings.plant.plant_substeps
        self._period = model.step_function(dt, "rk4").mapaccum(settings.plant.plant_substeps)
        self._peak = np.array([model.params[j].motor.current_peak_a for j in model.joints])
        self._casing = model.sensor_indices()
        self._winding = model.node_indices("winding")
        self._delayed = collections.deque(maxlen=settings.sensors.casing_delay_steps + 1)
        self._delivered: np.ndarray | None = None
        self._stuck: np.ndarray | None = None
        self.peak_winding_c = float(np.max(self.x[self._winding]))
        self._outputs = model.outputs.map(settings.plant.plant_substeps + 1)
        self._voltage_out = model.outputs.name_out().index("voltage_v")
        self.period_voltage_v = np.zeros(model.nu)

    @property
    def safety_cutoff_c(self) -> float:
        return min(p.limits.safety_cutoff_c for p in self.model.params.values())

    @property
    def ambient_c(self) -> float:
        """The room now (it warms by ``ambient_step_c`` at ``ambient_step_time_s``)."""
        s = self.settings
        stepped = s.plant.ambient_step_c != 0 and self.time_s >= s.plant.ambient_step_time_s - 1e-9
        return self.model.ambient_c + (s.plant.ambient_step_c if stepped else 0.0)

    def apply(self, current_a) -> None:
        """Hold ``current_a`` (clipped to +-peak) for one control period; ``period_voltage_v``: per joint, the
        largest absolute motor voltage over it (its start, every sub-step, its end)."""
        self.current_a = np.clip(np.asarray(current_a, dtype=float).reshape(-1), -self._peak, self._peak)
        xs = np.hstack([self.x[:, None], np.array(self._period(self.x, self.current_a, self.ambient_c))])
        self.peak_winding_c = max(self.peak_winding_c, float(xs[self._winding, :].max()))
        out = self._outputs(xs, np.repeat(self.current_a[:, None], xs.shape[1], axis=1), self.ambient_c)
        self.period_voltage_v = np.abs(np.array(out[self._voltage_out])).max(axis=1)
        self.x = xs[:, -1].copy()
        self.time_s += self.settings.controller.control_period_s

    def voltage_v(self) -> np.ndarray:
        out = self.model.outputs(self.x, self.current_a, self.ambient_c)
        return np.array(out[self.model.outputs.name_out().index("voltage_v")]).ravel()

    def measure(self) -> Measurement:
        s, n = self.settings, self.model.nu
        casing = self.x[self._casing] + s.sensors.casing_noise_c * self.rng.standard_normal(n)
        if s.sensors.casing_quantum_c > 0:
            casing = np.round(casing / s.sensors.casing_quantum_c) * s.sensors.casing_quantum_c
        self._delayed.append(casing)
        sample = self._delayed[0] if len(self._delayed) == self._delayed.maxlen else None
        if sample is not None and self.rng.random() < s.sensors.casing_dropout_probability:
            sample = None
        sample = self._faulty(sample)
        f = self.fault_rng
        voltage = self.voltage_v() + s.sensors.voltage_noise_v * f.standard_normal(n)
        ambient = self.ambient_c + s.sensors.ambient_noise_c * f.standard_normal()
        return Measurement(self.time_s,
                           self.x[:n] + s.sensors.position_noise_rad * self.rng.standard_normal(n),
                           self.x[n:2 * n] + s.sensors.velocity_noise_rad_s * self.rng.standard_normal(n),
                           self.current_a + s.sensors.current_noise_a * self.rng.standard_normal(n), sample,
                           voltage, float(ambient))

    def _faulty(self, sample: np.ndarray | None) -> np.ndarray | None:
        """NaN, stale (the previous delivered value again) and stuck samples."""
        s, f = self.settings, self.fault_rng
        if sample is None:
            return None
        if s.sensors.casing_stuck_time_s is not None and self.time_s >= s.sensors.casing_stuck_time_s - 1e-9:
            if self._stuck is None:
                self._stuck = sample.copy() if self._delivered is None else self._delivered.copy()
            return self._stuck.copy()
        if s.sensors.casing_nan_probability and f.random() < s.sensors.casing_nan_probability:
            return np.full_like(sample, np.nan)
        stale = s.sensors.casing_stale_probability
        if stale and self._delivered is not None and f.random() < stale:
            return self._delivered.copy()
        self._delivered = sample.copy()
        return sample.copy()
