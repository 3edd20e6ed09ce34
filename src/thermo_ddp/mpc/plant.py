"""The "real" elbow of the closed loop: a model whose parameters differ from the planner's,
integrated finely between control periods, seen only through noisy, quantised sensors."""
from __future__ import annotations

import collections
import dataclasses

import numpy as np

from ..actuated_arm import ActuatedArm
from .settings import MPCSettings


def perturbed_model(model: ActuatedArm, resistance_scale: float = 1.0, capacity_scale: float = 1.0) -> ActuatedArm:
    """The same arm with every thermal resistance (``*_k_per_w``) and heat capacity (``*_j_per_k``) scaled."""
    params = {}
    for joint, p in model.params.items():
        values = {k: v * resistance_scale for k, v in p.thermal.values.items() if k.endswith("_k_per_w")}
        values.update({k: v * capacity_scale for k, v in p.thermal.values.items() if k.endswith("_j_per_k")})
        params[joint] = p.replace("thermal", **values)
    return ActuatedArm.from_parameters(model.arm.settings, params)


@dataclasses.dataclass(frozen=True)
class Measurement:
    """What the controller sees at one control instant; ``casing_c`` is None when no sample arrived."""

    time_s: float
    q_rad: np.ndarray
    v_rad_s: np.ndarray
    current_a: np.ndarray     # measured current of the period that just ended
    casing_c: np.ndarray | None


class Plant:
    """The elbow: state x = [q, v, T_nodes] of ``model`` integrated by RK4 sub-steps, currents clipped to the peak.

    The casing sensor adds Gaussian noise, then quantises; it may be delayed by whole control
    periods and drop samples. The 84 °C safety cut-off acts on this measured casing value.
    """

    def __init__(self, model: ActuatedArm, x0: np.ndarray, settings: MPCSettings, rng: np.random.Generator):
        self.model, self.settings, self.rng = model, settings, rng
        self.x = np.array(x0, dtype=float)
        self.time_s = 0.0
        self.current_a = np.zeros(model.nu)
        dt = settings.control_period_s / settings.plant_substeps
        self._period = model.step(dt, "rk4").mapaccum(settings.plant_substeps)
        self._peak = np.array([model.params[j].motor.current_peak_a for j in model.joints])
        self._casing = model.node_indices("casing")
        self._winding = model.node_indices("winding")
        self._delayed = collections.deque(maxlen=settings.casing_delay_steps + 1)
        self.peak_winding_c = float(np.max(self.x[self._winding]))

    @property
    def safety_cutoff_c(self) -> float:
        return min(p.limits.safety_cutoff_c for p in self.model.params.values())

    def apply(self, current_a) -> None:
        """Hold ``current_a`` (clipped to +-peak) for one control period."""
        self.current_a = np.clip(np.asarray(current_a, dtype=float).reshape(-1), -self._peak, self._peak)
        xs = np.array(self._period(self.x, self.current_a, self.model.ambient_c))
        self.peak_winding_c = max(self.peak_winding_c, float(xs[self._winding, :].max()))
        self.x = xs[:, -1].copy()
        self.time_s += self.settings.control_period_s

    def voltage_v(self) -> np.ndarray:
        out = self.model.outputs(self.x, self.current_a, self.model.ambient_c)
        return np.array(out[self.model.outputs.name_out().index("voltage_v")]).ravel()

    def measure(self) -> Measurement:
        s, n = self.settings, self.model.nu
        casing = self.x[self._casing] + s.casing_noise_c * self.rng.standard_normal(n)
        if s.casing_quantum_c > 0:
            casing = np.round(casing / s.casing_quantum_c) * s.casing_quantum_c
        self._delayed.append(casing)
        sample = self._delayed[0] if len(self._delayed) == self._delayed.maxlen else None
        if sample is not None and self.rng.random() < s.casing_dropout_probability:
            sample = None
        return Measurement(self.time_s,
                           self.x[:n] + s.position_noise_rad * self.rng.standard_normal(n),
                           self.x[n:2 * n] + s.velocity_noise_rad_s * self.rng.standard_normal(n),
                           self.current_a + s.current_noise_a * self.rng.standard_normal(n), sample)
