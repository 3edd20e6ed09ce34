"""Extended Kalman filter of the elbow's state, winding temperature included, from the casing
sensor, the measured current and the joint encoders.

The filter predicts with the planner's own model (its CasADi ODE, integrated by the project's
integrator step (RK4 by default), with exact step Jacobians). Optionally the state is augmented with a common
scale ``s`` of the thermal resistances (R_true = s R_model, a random walk): a plant whose
resistances are 15 % higher then does not bias the winding estimate low. The initial scale comes
from the first casing sample, assuming the motor idled long enough to be at equilibrium (every
idle temperature rise above ambient is proportional to s); the filter then refines it.
"""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from .. import motor
from .._config import require
from ..actuated_arm import ActuatedArm
from ..integrators import make_step, step_jacobians
from .plant import Measurement
from .settings import MPCSettings

_SRC = "ObserverSettings"


@dataclasses.dataclass(frozen=True)
class ObserverSettings:
    """Process noise (standard deviation per control period) and initial uncertainty of the EKF."""

    position_rad: float = 1e-3
    velocity_rad_s: float = 2e-2
    temperature_c: float = 0.01
    winding_c: float = 0.05          # extra on the winding node: unmodelled heat flows
    resistance_scale: float = 1e-4   # random walk of s
    initial_temperature_c: float = 0.3
    initial_resistance_scale: float = 0.05
    scale_bounds: tuple[float, float] = (0.5, 2.0)

    def __post_init__(self):
        for f in dataclasses.fields(self)[:-1]:
            value = getattr(self, f.name)
            require(isinstance(value, (int, float)) and np.isfinite(value) and value > 0, _SRC, f.name, value,
                    "expected a finite number > 0")
        low, high = self.scale_bounds
        require(0 < low < 1 < high, _SRC, "scale_bounds", self.scale_bounds, "expected (low, high), low < 1 < high")


def scaled_ode(model: ActuatedArm) -> ca.Function:
    """``scaled_ode(x, current_a, ambient_c) -> xdot`` on x = [model state, s]: the model's ODE with every
    thermal resistance times s (built from the same motor and thermal-network expressions)."""
    n, nx = model.nu, model.nx
    z = ca.SX.sym("x", nx + 1)
    u, amb = ca.SX.sym("current_a", n), ca.SX.sym("ambient_c")
    x, s = z[:nx], z[nx]
    parts = [model.ode(x, u, amb)[:2 * n]]
    for k, joint in enumerate(model.joints):
        net = model.networks[joint]
        links = tuple(dataclasses.replace(link, resistance_k_per_w=link.resistance_k_per_w * s) for link in net.links)
        net = dataclasses.replace(net, links=links)
        first = model.index(joint, net.state_names[0])
        temps = x[first:first + len(net.nodes)]
        losses = motor.losses_w(model.params[joint].motor, u[k], x[n + k], temps[net.index(net.limit_node)])
        parts.append(net.rhs(temps, losses, amb))
    return ca.Function("scaled_ode", [z, u, amb], [ca.vertcat(*parts, 0)], ["x", "current_a", "ambient_c"], ["xdot"])


class ExtendedKalmanFilter:
    """EKF on z = [q, v, T_nodes (, s)]; measurements q, v and the casing temperature (when a sample came)."""

    def __init__(self, model: ActuatedArm, settings: MPCSettings, observer: ObserverSettings = ObserverSettings()):
        self.model, self.settings, self.observer = model, settings, observer
        self.augmented = settings.estimate_resistance_scale
        dt = settings.control_period_s
        ode = scaled_ode(model) if self.augmented else model.ode
        step = make_step(ode, dt, settings.integrator)
        self._step_jacobians = step_jacobians(step)
        n, nx = model.nu, model.nx
        self.nz = nx + int(self.augmented)
        self._casing, self._winding = model.node_indices("casing"), model.node_indices("winding")
        self._measured = np.concatenate([np.arange(2 * n), self._casing])
        temp_var = settings.casing_noise_c ** 2 + settings.casing_quantum_c ** 2 / 12
        self._r = np.concatenate([np.full(n, settings.position_noise_rad ** 2),
                                  np.full(n, settings.velocity_noise_rad_s ** 2), np.full(n, temp_var)])
        self._r = np.maximum(self._r, 1e-12)
        q = np.concatenate([np.full(n, observer.position_rad ** 2), np.full(n, observer.velocity_rad_s ** 2),
                            np.full(nx - 2 * n, observer.temperature_c ** 2)])
        q[self._winding] += observer.winding_c ** 2
        self._q = np.diag(np.append(q, observer.resistance_scale ** 2) if self.augmented else q)
        self.z = np.zeros(self.nz)
        self.P = np.eye(self.nz)

    # --- estimates ----------------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """The model state [q, v, T_nodes] (what the planner starts from)."""
        return self.z[:self.model.nx].copy()

    @property
    def winding_c(self) -> np.ndarray:
        return self.z[self._winding].copy()

    @property
    def winding_std_c(self) -> np.ndarray:
        return np.sqrt(np.diag(self.P)[self._winding])

    @property
    def resistance_scale(self) -> float:
        return float(self.z[-1]) if self.augmented else 1.0

    # --- filter -------------------------------------------------------------------------
    def initialise(self, m: Measurement) -> None:
        """Idle equilibrium scaled to the measured casing; q, v from the encoders."""
        model, o = self.model, self.observer
        if m.casing_c is None:
            raise ValueError("the observer needs a casing sample to start")
        amb = model.ambient_c
        idle = model.idle_temperatures()
        scale = float(np.clip(np.mean((m.casing_c - amb) / (idle[np.array(self._casing) - 2 * model.nu] - amb)),
                              *o.scale_bounds))
        temps = amb + scale * (idle - amb)
        x = np.concatenate([m.q_rad, m.v_rad_s, temps])
        self.z = np.append(x, scale) if self.augmented else x
        p0 = np.concatenate([self._r[:2 * model.nu], np.full(model.nx - 2 * model.nu, o.initial_temperature_c ** 2)])
        self.P = np.diag(np.append(p0, o.initial_resistance_scale ** 2) if self.augmented else p0)

    def predict(self, current_a) -> None:
        """Propagate over one control period with the measured current."""
        z_next, a, _ = self._step_jacobians(self.z, np.asarray(current_a, float), self.model.ambient_c)
        a = np.array(a)
        self.z = np.array(z_next).ravel()
        self.P = a @ self.P @ a.T + self._q
        if self.augmented:
            self.z[-1] = np.clip(self.z[-1], *self.observer.scale_bounds)

    def update(self, m: Measurement) -> None:
        """Correct with q, v and (when present) the casing sample (Joseph form)."""
        y = np.concatenate([m.q_rad, m.v_rad_s] + ([m.casing_c] if m.casing_c is not None else []))
        rows = self._measured[:y.size]
        h = np.zeros((y.size, self.nz))
        h[np.arange(y.size), rows] = 1.0
        s = h @ self.P @ h.T + np.diag(self._r[:y.size])
        gain = np.linalg.solve(s, h @ self.P).T
        self.z = self.z + gain @ (y - self.z[rows])
        i_kh = np.eye(self.nz) - gain @ h
        self.P = i_kh @ self.P @ i_kh.T + gain @ np.diag(self._r[:y.size]) @ gain.T
        if self.augmented:
            self.z[-1] = np.clip(self.z[-1], *self.observer.scale_bounds)
