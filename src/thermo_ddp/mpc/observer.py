"""Extended Kalman filter of the elbow's state, winding temperature included, from the casing
sensor, the measured current and the joint encoders.

The filter predicts with the planner's own model (its CasADi ODE, integrated by the project's
integrator step (RK4 by default), with exact step Jacobians). Optionally the state is augmented with a common
scale ``s`` of the thermal resistances (R_true = s R_model, a random walk): a plant whose
resistances are 15 % higher then does not bias the winding estimate low. The initial scale comes
from the first casing sample, assuming the motor idled long enough to be at equilibrium (every
idle temperature rise above ambient is proportional to s); the filter then refines it.

Bad sensor data (:meth:`ExtendedKalmanFilter.filter_step`): a NaN or missing casing sample is
skipped; a sample equal to the previous one may be stale and is not used; a run of equal samples
that a healthy noisy, quantised sensor produces with probability below ``stuck_false_alarm`` (a
variance test: the reading lost the noise the sensor model says it has), or a window of casing
innovations whose normalised sum leaves +-``innovation_threshold`` (the reading disagrees with the
model's prediction), marks the casing sensor as distrusted for the rest of the run: the filter then
runs open loop on the model (encoders, current and, when observed, the voltage). A casing delay of
D periods is compensated exactly by re-processing: the sample of instant k - D updates the stored
prediction of that instant, and the D periods since are predicted and updated again.
"""
from __future__ import annotations

import collections
import dataclasses
import logging
import math

import casadi as ca
import numpy as np

from .._config import require
from ..model import motor
from ..model.actuated import ActuatedArm
from ..model.integrators import make_step, step_jacobians
from ..model.thermal import joint_heat_rhs
from .plant import Measurement
from .settings import MPCSettings

log = logging.getLogger(__name__)
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
    initial_drive_c: float = 5.0     # settled start: the unmeasured drive node's initial uncertainty
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
        parts.append(joint_heat_rhs(net, model.params[joint].motor, temps, u[k], x[n + k], amb))
    return ca.Function("scaled_ode", [z, u, amb], [ca.vertcat(*parts, 0)], ["x", "current_a", "ambient_c"], ["xdot"])


class ExtendedKalmanFilter:
    """EKF on z = [q, v, T_nodes (, s)]; measurements q, v and the casing temperature (when a sample came)."""

    def __init__(self, model: ActuatedArm, settings: MPCSettings, observer: ObserverSettings = ObserverSettings()):
        self.model, self.settings, self.observer = model, settings, observer
        self.augmented = settings.estimator.estimate_resistance_scale
        dt = settings.controller.control_period_s
        ode = scaled_ode(model) if self.augmented else model.ode
        step = make_step(ode, dt, settings.controller.integrator)
        self._step_jacobians = step_jacobians(step)
        n, nx = model.nu, model.nx
        self.nz = nx + int(self.augmented)
        self._casing, self._winding = model.sensor_indices(), model.node_indices("winding")
        self._measured = np.concatenate([np.arange(2 * n), self._casing])
        temp_var = settings.sensors.casing_noise_c ** 2 + settings.sensors.casing_quantum_c ** 2 / 12
        self._r = np.concatenate([np.full(n, settings.sensors.position_noise_rad ** 2),
                                  np.full(n, settings.sensors.velocity_noise_rad_s ** 2), np.full(n, temp_var)])
        self._r = np.maximum(self._r, 1e-12)
        q = np.concatenate([np.full(n, observer.position_rad ** 2), np.full(n, observer.velocity_rad_s ** 2),
                            np.full(nx - 2 * n, observer.temperature_c ** 2)])
        q[self._winding] += observer.winding_c ** 2
        self._q = np.diag(np.append(q, observer.resistance_scale ** 2) if self.augmented else q)
        self.z = np.zeros(self.nz)
        self.P = np.eye(self.nz)
        self.ambient_c = float(model.ambient_c)   # the room the prediction uses (the controller may move it)
        self._voltage = _voltage_function(model, self.nz, self._winding)
        self.monitor = CasingMonitor(settings)
        self._history: collections.deque = collections.deque(maxlen=settings.observer_delay + 1)

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

    @property
    def resistance_scale_std(self) -> float:
        """The standard deviation of the resistance scale's estimate (0 without the scale)."""
        return float(np.sqrt(self.P[-1, -1])) if self.augmented else 0.0

    # --- filter -------------------------------------------------------------------------
    def initialise(self, m: Measurement) -> None:
        """Idle equilibrium scaled (or, without idle heat, shifted) to the measured sensor node (the casing,
        or the winding of a one-node model); q, v from the encoders."""
        model, o = self.model, self.observer
        if m.casing_c is None:
            raise ValueError("the observer needs a casing sample to start")
        if not np.all(np.isfinite(m.casing_c)):
            raise ValueError("the observer needs a finite casing sample to start")
        amb = self.ambient_c = float(model.ambient_c if m.ambient_c is None else m.ambient_c)
        p0 = np.concatenate([self._r[:2 * model.nu], np.full(model.nx - 2 * model.nu, o.initial_temperature_c ** 2)])
        if self.settings.estimator.observer_start == "settled":   # no current for minutes: winding = casing
            temps, scale = np.full(model.nx - 2 * model.nu, float(np.mean(m.casing_c))), 1.0
            drive = [i - 2 * model.nu for i in _indices(model, "drive")]
            p0[2 * model.nu + np.array(drive, dtype=int)] = o.initial_drive_c ** 2
        else:
            idle = model.idle_temperatures(amb)
            rise = idle[np.array(self._casing) - 2 * model.nu] - amb
            if np.all(np.abs(rise) > 1e-6):  # idle heat (drive): scale the idle rise to the sample
                scale = float(np.clip(np.mean((m.casing_c - amb) / rise), *o.scale_bounds))
                temps = amb + scale * (idle - amb)
            else:                            # no idle heat: shift every node by the sample's offset
                scale, temps = 1.0, idle + float(np.mean(m.casing_c - amb - rise))
        x = np.concatenate([m.q_rad, m.v_rad_s, temps])
        self.z = np.append(x, scale) if self.augmented else x
        self.P = np.diag(np.append(p0, o.initial_resistance_scale ** 2) if self.augmented else p0)
        self.monitor = CasingMonitor(self.settings)
        self.monitor.classify(m.casing_c)
        self._history.clear()
        self._history.append(_Instant(self.z.copy(), self.P.copy(), m))

    def predict(self, current_a) -> None:
        """Propagate over one control period with the measured current."""
        z_next, a, _ = self._step_jacobians(self.z, np.asarray(current_a, float), self.ambient_c)
        a = np.array(a)
        self.z = np.array(z_next).ravel()
        self.P = a @ self.P @ a.T + self._q
        if self.augmented:
            self.z[-1] = np.clip(self.z[-1], *self.observer.scale_bounds)

    def update(self, m: Measurement, casing_c: np.ndarray | None = None, use_casing: bool = True) -> np.ndarray | None:
        """Correct with q, v, the casing sample (``casing_c``, default ``m.casing_c``; skipped when absent,
        non-finite or ``use_casing`` is False) and, with ``settings.estimator.observe_voltage``, the voltage
        (Joseph form). Returns the normalised casing innovations (None without a casing update)."""
        n = self.model.nu
        casing = m.casing_c if casing_c is None else casing_c
        use = use_casing and casing is not None and bool(np.all(np.isfinite(casing)))
        y = np.concatenate([m.q_rad, m.v_rad_s] + ([casing] if use else []))
        rows = self._measured[:y.size]
        h = np.zeros((y.size, self.nz))
        h[np.arange(y.size), rows] = 1.0
        r = self._r[:y.size]
        prediction = self.z[rows]
        if self.settings.estimator.observe_voltage and m.voltage_v is not None and np.all(np.isfinite(m.voltage_v)):
            hv, offset, rv = self._voltage_rows(m)
            y, h = np.concatenate([y, m.voltage_v]), np.vstack([h, hv])
            r, prediction = np.concatenate([r, rv]), np.concatenate([prediction, hv @ self.z + offset])
        s = h @ self.P @ h.T + np.diag(r)
        gain = np.linalg.solve(s, h @ self.P).T
        innovation = y - prediction
        self.z = self.z + gain @ innovation
        i_kh = np.eye(self.nz) - gain @ h
        self.P = i_kh @ self.P @ i_kh.T + gain @ np.diag(r) @ gain.T
        if self.augmented:
            self.z[-1] = np.clip(self.z[-1], *self.observer.scale_bounds)
        if not use:
            return None
        c = slice(2 * n, 3 * n)
        return innovation[c] / np.sqrt(np.diag(s)[c])

    def _voltage_rows(self, m: Measurement):
        """V = R(T_w) i + K_b N v (``motor.voltage_v``) is linear in the state for the measured current i:
        rows of H, the constant term and the variance (voltage noise plus R(T_w) times the current noise)."""
        s = self.settings
        volts, h, ohm = (np.array(a, dtype=float) for a in self._voltage(self.z, np.asarray(m.current_a, float)))
        volts, ohm = volts.ravel(), ohm.ravel()
        return h, volts - h @ self.z, s.sensors.voltage_noise_v ** 2 + (ohm * s.sensors.current_noise_a) ** 2

    def filter_step(self, m: Measurement) -> list[str]:
        """Predict over the period that just ended with ``m.current_a``, check the casing sample, update
        (a delayed sample at its own instant, then the periods since again). Returns the events."""
        self.predict(m.current_a)
        self._history.append(_Instant(self.z.copy(), self.P.copy(), m))
        events = self.monitor.classify(m.casing_c)
        usable = not events and self.monitor.trusted
        if not self.monitor.trusted:
            events.append("casing_distrusted")
        delay = self.settings.observer_delay
        if delay and len(self._history) <= delay:
            usable = False   # the sample is older than the filter's start
        if usable and delay:
            return events + self._reprocess(m.casing_c)
        nu = self.update(m, m.casing_c, usable)
        return events + (self.monitor.innovation(nu) if nu is not None else [])

    def _reprocess(self, casing_c: np.ndarray) -> list[str]:
        """The sample of instant k - D updates that instant's stored prediction; the D periods since are
        predicted and updated (without casing) again, replacing their stored predictions."""
        history = self._history
        first = history[0]
        self.z, self.P = first.z.copy(), first.P.copy()
        nu = self.update(first.m, casing_c, True)
        for j in range(1, len(history)):
            self.predict(history[j].m.current_a)
            history[j] = _Instant(self.z.copy(), self.P.copy(), history[j].m)
            self.update(history[j].m, use_casing=False)
        history.popleft()
        return self.monitor.innovation(nu) if nu is not None else []



def _voltage_function(model: ActuatedArm, nz: int, winding: list[int]) -> ca.Function:
    """``voltage(z, current_a) -> (voltage_v, d voltage_v / dz, resistance_ohm)`` of every joint's motor."""
    n = model.nu
    z, i = ca.SX.sym("z", nz), ca.SX.sym("current_a", n)
    motors = [model.params[j].motor for j in model.joints]
    volts = ca.vertcat(*(motor.voltage_v(m, i[k], z[n + k], z[winding[k]]) for k, m in enumerate(motors)))
    ohm = ca.vertcat(*(motor.resistance_ohm(m, z[winding[k]]) for k, m in enumerate(motors)))
    return ca.Function("observer_voltage", [z, i], [volts, ca.jacobian(volts, z), ohm], ["z", "current_a"],
                       ["voltage_v", "dvoltage_dz", "resistance_ohm"])


@dataclasses.dataclass(frozen=True)
class _Instant:
    """The filter's prediction (before any update) at one instant and what was measured then."""

    z: np.ndarray
    P: np.ndarray
    m: Measurement


def _indices(model, node: str) -> list[int]:
    try:
        return model.node_indices(node)
    except (KeyError, ValueError):
        return []


class CasingMonitor:
    """Classifies casing samples and decides when the sensor is no longer trusted.

    - ``casing_missing`` (no sample), ``casing_nan`` (non-finite), ``casing_repeat`` (equal to the
      previous delivered sample: possibly stale, not used when ``reject_repeated_casing``);
    - ``casing_stuck``: ``stuck_samples`` equal samples in a row. A healthy sensor with noise sigma and
      quantum q repeats its previous reading with probability p ~ q / (2 sqrt(pi) sigma) (the density at 0
      of the difference of two noise samples times q), so a run of n equal samples has probability
      p^(n-1); n is the smallest run with p^(n-1) <= ``stuck_false_alarm`` (at least 3). Without noise
      no run is implausible and this test is off.
    - ``casing_inconsistent``: the last ``innovation_window`` normalised innovations sum beyond
      +-``innovation_threshold`` * sqrt(window) (a sensor that disagrees with the model's prediction).

    Both verdicts distrust the sensor for the rest of the run.
    """

    def __init__(self, settings: MPCSettings):
        self.settings = settings
        self.trusted = True
        self.reason: str | None = None
        self._previous: np.ndarray | None = None
        self._run = 1
        self._innovations: collections.deque = collections.deque(maxlen=settings.estimator.innovation_window)
        self.stuck_samples = stuck_run_length(settings.sensors.casing_noise_c, settings.sensors.casing_quantum_c,
                                              settings.estimator.stuck_false_alarm)

    def classify(self, sample: np.ndarray | None) -> list[str]:
        if sample is None:
            return ["casing_missing"]
        if not np.all(np.isfinite(sample)):
            return ["casing_nan"]
        repeat = self._previous is not None and np.array_equal(sample, self._previous)
        self._run = self._run + 1 if repeat else 1
        self._previous = np.array(sample, dtype=float)
        events = []
        if repeat:
            if self.trusted and self._run >= self.stuck_samples:
                self._distrust("casing_stuck", f"{self._run} equal samples in a row")
                events.append("casing_stuck")
            if self.settings.estimator.reject_repeated_casing or not self.trusted:
                events.append("casing_repeat")
        return events

    def innovation(self, normalised: np.ndarray) -> list[str]:
        self._innovations.append(float(np.mean(normalised)))
        w = self.settings.estimator.innovation_window
        if self.trusted and len(self._innovations) == w:
            statistic = abs(sum(self._innovations)) / math.sqrt(w)
            if statistic > self.settings.estimator.innovation_threshold:
                self._distrust("casing_inconsistent", f"normalised innovation sum {statistic:.1f} over {w} samples")
                return ["casing_inconsistent"]
        return []

    def _distrust(self, reason: str, detail: str) -> None:
        self.trusted, self.reason = False, reason
        log.warning("casing sensor distrusted (%s: %s); open loop on the model", reason,
                                            detail)


def stuck_run_length(noise_c: float, quantum_c: float, false_alarm: float) -> int:
    """Equal samples in a row that flag a stuck sensor (a huge number when the sensor has no noise)."""
    if noise_c <= 0:
        return 10 ** 9
    p = min(1.0, quantum_c / (2 * math.sqrt(math.pi) * noise_c))
    if p <= 0:
        return 3
    if p >= 1:
        return 10 ** 9
    return max(3, math.ceil(1 + math.log(false_alarm) / math.log(p)))
