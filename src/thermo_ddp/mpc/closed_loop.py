"""``run_closed_loop()``: plant, observer and receding-horizon controller together, and its result."""
from __future__ import annotations

import collections
import dataclasses
import logging
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from ..model.actuated import ActuatedArm, load_model
from ..model.arm import ELBOW
from ..tasks.limits import default_limit_c, joint_range_rad
from .controller import ControlStep, RecedingHorizonController, planning_problem
from .observer import ExtendedKalmanFilter, ObserverSettings
from .plant import Measurement, Plant, perturbed_model
from .settings import MPCSettings

log = logging.getLogger(__name__)
# Events counted in the result and its report but not named in its message: a repeated or missing casing sample
# (the estimator predicts through it) and the range guard's brake in the lowering (the lift's normal end since
# branch mpc6; a fallback period is named in the message by its own count).
ROUTINE_EVENTS = frozenset({"casing_repeat", "casing_missing", "range_brake"})


@dataclasses.dataclass(frozen=True)
class ClosedLoopResult:
    """The closed loop's time series at the control instants t_k (k = 0..K) and per-period logs (K).

    True plant signals: ``winding_c``, ``casing_c``, ``drive_c`` (None without a drive node), ``q_rad``,
    ``v_rad_s``. Observer: ``estimated_winding_c``, ``winding_std_c``, ``resistance_scale``. Sensor:
    ``measured_casing_c`` (the last received sample; ``casing_received`` says which instants got one).
    Per period k -> k+1: ``current_a``, ``voltage_v`` (at t_{k+1}, the sensor's), ``period_voltage_v`` (the
    largest absolute voltage over the period: its start, the plant's sub-steps, its end), ``solve_s``, ``first_solve_s``,
    ``iterations``, ``step_status``, ``hold_s``. ``peak_winding_c`` includes the plant's sub-steps.
    ``planner_x0`` (K, nx) and ``planner_params`` (K, N+1, np): what every solve was given;
    ``measurements`` (K+1): what the observer was given (to re-run a filter offline).
    ``joint_range_rad`` (the model's URDF range), ``current_peak_a`` and ``bus_voltage_v`` (the motor's) are
    the bounds :attr:`range_excess_rad` and :attr:`actuator_excess` measure the true motion and the commands
    against. ``events`` (K): per period, what happened beyond the normal (sensor samples missing, NaN, repeated,
    the casing sensor stuck or inconsistent and then distrusted, solves failed or late, fallbacks,
    derates, hold shortened, the room changed, a payload mismatch, the cut-off); ``tightening_c`` (K):
    the kelvin added to the planning state's thermal nodes (uncertainty and sensor-fault back-off).
    """

    success: bool
    status: str
    message: str
    settings: MPCSettings
    time_s: np.ndarray
    winding_c: np.ndarray
    casing_c: np.ndarray
    drive_c: np.ndarray | None
    q_rad: np.ndarray
    v_rad_s: np.ndarray
    estimated_winding_c: np.ndarray
    winding_std_c: np.ndarray
    resistance_scale: np.ndarray
    measured_casing_c: np.ndarray
    casing_received: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    solve_s: np.ndarray
    first_solve_s: np.ndarray
    iterations: np.ndarray
    step_status: tuple[str, ...]
    hold_s: np.ndarray
    peak_winding_c: float
    safety_cutoff_c: float
    cutoff_tripped: bool
    planner_x0: np.ndarray
    planner_params: np.ndarray
    measurements: tuple[Measurement, ...]
    events: tuple[tuple[str, ...], ...] = ()
    tightening_c: np.ndarray | None = None
    joint_range_rad: tuple[float, float] = (-np.inf, np.inf)
    current_peak_a: float = np.inf
    bus_voltage_v: float = np.inf
    period_voltage_v: np.ndarray | None = None

    def __repr__(self) -> str:
        return (f"ClosedLoopResult({self.status}, peak winding {self.peak_winding_c:.2f} °C, "
                f"limit {self.limit_c:g} °C)")

    @property
    def limit_c(self) -> float:
        return self.settings.limit_c

    @property
    def achieved_hold_s(self) -> float:
        """The hold executed: the controller's planned hold after the last period."""
        return float(self.hold_s[-1])

    @property
    def time_over_limit_s(self) -> float:
        return float(np.sum(self.winding_c > self.limit_c) * self.settings.controller.control_period_s)

    @property
    def margin_c(self) -> float:
        """Limit minus the peak TRUE winding (negative: the limit was exceeded)."""
        return self.limit_c - self.peak_winding_c

    @property
    def range_excess_rad(self) -> np.ndarray:
        """Per instant, how far the TRUE position is outside the joint range (0 inside)."""
        lo, hi = self.joint_range_rad
        return np.maximum(np.maximum(self.q_rad - hi, lo - self.q_rad), 0.0)

    @property
    def actuator_excess(self) -> dict[str, np.ndarray]:
        """Per period, how far the current sent is over the motor's peak (A) and the motor voltage over the bus
        voltage (V), over the whole period (``period_voltage_v``; without it, at its end) (0 within)."""
        volts = self.voltage_v if self.period_voltage_v is None else self.period_voltage_v
        return {"current_a": np.maximum(np.abs(self.current_a) - self.current_peak_a, 0.0),
                "voltage_v": np.maximum(np.abs(volts) - self.bus_voltage_v, 0.0)}

    @property
    def estimation_error_c(self) -> np.ndarray:
        return self.estimated_winding_c - self.winding_c

    def warm_solve_s(self) -> np.ndarray:
        """First-solve times of the warm periods (k >= 1)."""
        return self.first_solve_s[1:]

    def event_counts(self) -> dict[str, dict[str, float]]:
        """Per event name: the number of periods it occurred in and the time of the first."""
        out: dict[str, dict[str, float]] = {}
        for k, names in enumerate(self.events):
            for name in dict.fromkeys(names):
                entry = out.setdefault(name, {"count": 0, "first_s": float(self.time_s[k + 1])})
                entry["count"] += 1
        return dict(sorted(out.items(), key=lambda item: item[1]["first_s"]))

    def summary(self) -> dict[str, Any]:
        warm = self.warm_solve_s()
        counts = {s: self.step_status.count(s) for s in sorted(set(self.step_status))}
        return {"success": self.success, "status": self.status, "message": self.message,
                "limit_c": self.limit_c, "planning_limit_c": self.settings.planning_limit_c,
                "peak_winding_c": self.peak_winding_c, "margin_c": self.margin_c,
                "max_range_excess_rad": float(self.range_excess_rad.max()),
                "peak_casing_measured_c": float(self.measured_casing_c.max()),
                "cutoff_tripped": self.cutoff_tripped, "safety_cutoff_c": self.safety_cutoff_c,
                "requested_hold_s": self.settings.scenario.hold_s, "planned_hold_s": float(self.hold_s[-1]),
                "max_abs_estimation_error_c": float(np.abs(self.estimation_error_c).max()),
                "final_resistance_scale": float(self.resistance_scale[-1]),
                "warm_solve_median_s": float(np.median(warm)) if warm.size else None,
                "warm_solve_max_s": float(warm.max()) if warm.size else None,
                "period_solve_max_s": float(self.solve_s.max()),
                "median_iterations": float(np.median(self.iterations[1:])) if warm.size else None,
                "step_status": counts, "events": self.event_counts(),
                "max_tightening_c": float(np.max(self.tightening_c)) if self.tightening_c is not None and
                self.tightening_c.size else 0.0}

    def to_dict(self) -> dict[str, Any]:
        d = self.summary()
        d["settings"] = dataclasses.asdict(self.settings)
        for key in ("time_s", "winding_c", "casing_c", "q_rad", "v_rad_s", "estimated_winding_c", "winding_std_c",
                    "resistance_scale", "measured_casing_c", "current_a", "voltage_v", "solve_s", "iterations",
                    "hold_s"):
            d[key] = np.asarray(getattr(self, key)).tolist()
        if self.drive_c is not None:
            d["drive_c"] = self.drive_c.tolist()
        d["step_status_series"] = list(self.step_status)
        d["events_series"] = [list(e) for e in self.events]
        return d

    def report(self) -> str:
        s = self.summary()
        warm = "n/a" if s["warm_solve_median_s"] is None else \
            f"{1e3 * s['warm_solve_median_s']:.2f} ms median, {1e3 * s['warm_solve_max_s']:.2f} ms max"
        return "\n".join([
            f"closed-loop lift {self.settings.scenario.payload_kg:g} kg, winding limit {self.limit_c:g} °C "
            f"(planned at {self.settings.planning_limit_c:g} °C): {'SUCCESS' if self.success else 'FAILURE'} "
            f"({self.status})",
            f"  {self.message}",
            f"  peak TRUE winding {self.peak_winding_c:.2f} °C, margin {self.margin_c:.2f} K; "
            f"largest |estimate - true| {s['max_abs_estimation_error_c']:.2f} K; "
            f"resistance scale estimate {s['final_resistance_scale']:.3f} "
            f"(plant {self.settings.plant.plant_resistance_scale:g})",
            f"  measured casing peak {s['peak_casing_measured_c']:.1f} °C, cut-off {self.safety_cutoff_c:g} °C "
            f"{'TRIPPED' if self.cutoff_tripped else 'not tripped'}",
            f"  hold requested {self.settings.scenario.hold_s:.1f} s, planned {s['planned_hold_s']:.1f} s",
            f"  warm re-solves: {warm}; median {s['median_iterations']} iterations; "
            f"periods: {', '.join(f'{k} {v}' for k, v in s['step_status'].items())}",
            "  events: " + (", ".join(f"{name} x{e['count']} (first at {e['first_s']:.1f} s)"
                                      for name, e in s["events"].items()) or "none")
            + (f"; planning state raised by up to {s['max_tightening_c']:.2f} K" if s["max_tightening_c"] else "")])

    def plot(self, path) -> None:
        from .plots import plot_closed_loop
        plot_closed_loop(self, path)


@dataclasses.dataclass
class _Log:
    rows: dict[str, list] = dataclasses.field(default_factory=lambda: {k: [] for k in (
        "x", "est", "std", "scale", "casing", "received", "current", "voltage", "period_voltage", "steps", "x0",
        "params", "measurements", "events", "tightening")})

    def instant(self, plant: Plant, observer: ExtendedKalmanFilter, m: Measurement, casing, received: bool):
        r = self.rows
        r["measurements"].append(m)
        r["x"].append(plant.x.copy())
        r["est"].append(observer.winding_c)
        r["std"].append(observer.winding_std_c)
        r["scale"].append(observer.resistance_scale)
        r["casing"].append(casing)
        r["received"].append(received)

    def period(self, plant: Plant, step: ControlStep, x0, params):
        r = self.rows
        r["current"].append(plant.current_a.copy())
        r["voltage"].append(plant.voltage_v())
        r["period_voltage"].append(plant.period_voltage_v.copy())
        r["steps"].append(step)
        r["x0"].append(np.array(x0))
        r["params"].append(params)


def build_models(settings: MPCSettings) -> tuple[ActuatedArm, ActuatedArm]:
    """The planner's model and the plant's (thermal values, friction and payload scaled)."""
    files = {ELBOW: settings.scenario.parameter_file} if settings.scenario.parameter_file else None
    model = load_model((ELBOW,), payload_kg=settings.scenario.payload_kg, parameter_files=files)
    return model, perturbed_model(model, settings.plant.plant_resistance_scale, settings.plant.plant_capacity_scale,
                                  dict(settings.plant.plant_thermal_scales), settings.plant.plant_friction_scale,
                                  settings.plant.plant_payload_scale)


class _Supervisor:
    """Between observer and controller: the room the planner assumes, the tightening of the planning state
    (uncertainty and sensor-fault back-off) and the payload check while holding."""

    def __init__(self, settings: MPCSettings, model: ActuatedArm, controller: RecedingHorizonController,
                 ekf: ExtendedKalmanFilter):
        self.settings, self.model, self.controller, self.ekf = settings, model, controller, ekf
        self.room_c: float | None = None
        self.assumed_c = model.ambient_c
        per_second = max(1, round(1.0 / settings.controller.control_period_s))
        self._room: collections.deque = collections.deque(maxlen=per_second)
        self._ratios: list[float] = []
        self.payload_reported = False

    def room(self, m: Measurement) -> list[str]:
        """When the room thermometer's 1-s median leaves the assumed room by ambient_change_c, the planner and the
        observer take the median of the last three readings."""
        if m.ambient_c is None or not np.isfinite(m.ambient_c):
            return []
        self._room.append(m.ambient_c)
        if abs(float(np.median(self._room)) - self.assumed_c) <= self.settings.controller.ambient_change_c:
            return []
        self.room_c = float(np.median(list(self._room)[-3:]))   # the new level: the latest samples
        log.warning("t = %.1f s: room %.1f °C, planner assumed %.1f °C: following it", m.time_s, self.room_c,
                    self.assumed_c)
        self.assumed_c = self.controller.ambient_c = self.ekf.ambient_c = float(self.room_c)
        return ["ambient_change"]

    def tighten(self) -> float:
        c, ekf = self.settings.controller, self.ekf
        t = c.uncertainty_sigmas * float(np.max(ekf.winding_std_c))
        if not ekf.monitor.trusted:
            t += c.sensor_fault_backoff_c
        self.controller.tightening_c = t
        if self.controller.robust is not None and ekf.augmented:  # the set narrows as the EKF learns the scale
            self.controller.robust.narrow(ekf.resistance_scale, ekf.resistance_scale_std)
        return t

    def payload(self, m: Measurement, k: int) -> list[str]:
        """While holding still: the measured current against the model's static current (1 s averages)."""
        c = self.controller
        holding = c.task.with_hold(c.hold_s).params[:, c.lp.problem.parameters.slice("hold_flag")].ravel()
        if self.payload_reported or k >= holding.size or holding[k] < 0.5 or np.max(np.abs(m.v_rad_s)) > 0.05:
            self._ratios.clear()
            return []
        static = self.model.static_current_a(m.q_rad)
        self._ratios.append(float(np.mean(m.current_a / static)))
        if len(self._ratios) < round(1.0 / self.settings.controller.control_period_s):
            return []
        ratio = float(np.mean(self._ratios))
        self._ratios.clear()
        if abs(ratio - 1) <= self.settings.estimator.payload_mismatch_tolerance:
            return []
        self.payload_reported = True
        log.warning("t = %.1f s: holding takes %.0f %% of the model's current: the payload differs from the "
                    "planned %.1f kg", m.time_s, 100 * ratio, self.settings.scenario.payload_kg)
        return ["payload_mismatch"]


def run_closed_loop(settings: MPCSettings | None = None, *, solver=None, observer: ObserverSettings | None = None,
                    plant_model: ActuatedArm | None = None, progress: bool = True, **options) -> ClosedLoopResult:
    """Lift, hold and lower in closed loop: the plant (mismatched model, fine RK4, noisy sensors), the EKF
    and the receding-horizon DDP controller. Options: the fields of :class:`MPCSettings` (or ``settings``).
    ``solver``: a DDP solver built earlier for the same planning problem (see ``controller.mpc_solver``).
    ``plant_model``: the robot's own model (e.g. a simulated robot's true physics) instead of the planner's
    model perturbed by the settings' plant scales."""
    if settings is None:
        settings = MPCSettings.from_options(**options)
    elif options:
        raise TypeError("give either settings or options, not both")
    model, perturbed = build_models(settings)
    settings = settings.with_default_limit(default_limit_c(model.params[ELBOW]))
    plant_model = plant_model or perturbed
    lp = planning_problem(settings, model)
    controller = RecedingHorizonController(lp, settings, solver)
    rng = np.random.default_rng(settings.scenario.seed)
    temps = None if settings.plant.plant_initial_c is None else np.full(plant_model.nx - 2 * plant_model.nu,
                                                                   settings.plant.plant_initial_c)
    plant = Plant(plant_model, plant_model.state(q=[lp.settings.start_rad], temperatures_c=temps), settings, rng)
    ekf = ExtendedKalmanFilter(model, settings, observer or ObserverSettings())
    supervisor = _Supervisor(settings, model, controller, ekf)
    steps = controller.task_knots + int(round(settings.scenario.extra_s / settings.controller.control_period_s))
    m = plant.measure()
    while m.casing_c is None or not np.all(np.isfinite(m.casing_c)):  # wait at rest for the first sample
        plant.apply(np.zeros(model.nu))
        m = plant.measure()
    supervisor.room(m)
    ekf.initialise(m)
    log_ = _Log()
    last_casing = m.casing_c.copy()
    log_.instant(plant, ekf, m, last_casing, True)
    tripped = False
    started = time.perf_counter()
    for k in tqdm(range(steps), desc="closed loop", unit="period", disable=not progress, leave=False):
        tightening = supervisor.tighten()
        x0 = controller.planning_state(ekf.state)
        step = controller.start(ekf.state) if k == 0 else controller.step(ekf.state)
        plant.apply(step.current_a)
        log_.period(plant, step, x0, controller.window(k))  # the window of the accepted plan
        m = plant.measure()
        events = list(step.events) + ekf.filter_step(m) + supervisor.room(m) + supervisor.payload(m, k + 1)
        received = m.casing_c is not None and bool(np.all(np.isfinite(m.casing_c)))
        last_casing = m.casing_c.copy() if received else last_casing
        log_.instant(plant, ekf, m, last_casing, received)
        if received and np.any(m.casing_c >= plant.safety_cutoff_c):
            tripped = True
            events.append("cutoff_tripped")
            log.warning("t = %.1f s: measured casing %.1f °C: safety cut-off", plant.time_s, m.casing_c.max())
        log_.rows["events"].append(tuple(events))
        log_.rows["tightening"].append(tightening)
        if tripped:
            break
    log.info("closed loop: %d periods in %.2f s", len(log_.rows["steps"]), time.perf_counter() - started)
    return _result(settings, plant, log_, tripped)


def _verdict(settings: MPCSettings, plant: Plant, tripped: bool, range_excess_rad: float) -> tuple[bool, str, str]:
    """success, status and message: the cut-off, then the true winding over the limit; the message also says when
    the true position left the joint range (counted by the sweep; not yet a failed status: the default planner
    still leaves it in some loops, benchmarks/README.md)."""
    peak = plant.peak_winding_c
    if tripped:
        success, status = False, "safety_cutoff"
        message = f"the measured casing reached the {plant.safety_cutoff_c:g} °C cut-off"
    elif peak > settings.limit_c:
        success, status = False, "winding_limit_exceeded"
        message = f"the true winding reached {peak:.2f} °C > {settings.limit_c:g} °C"
    else:
        success, status = True, "completed"
        message = f"the true winding stayed {settings.limit_c - peak:.2f} K under the limit"
    if range_excess_rad > 0:
        message += f"; the arm left the joint range by {range_excess_rad:.3f} rad"
    return success, status, message


def _result(settings: MPCSettings, plant: Plant, log_: _Log, tripped: bool) -> ClosedLoopResult:
    model, r = plant.model, log_.rows
    xs = np.array(r["x"])
    steps: list[ControlStep] = r["steps"]

    def node(name):
        return xs[:, model.node_indices(name)][:, 0]

    drive = node("drive") if "drive" in model.networks[model.joints[0]].nodes else None
    peak = plant.peak_winding_c
    fallbacks = sum(s.status == "fallback" for s in steps)
    lo, hi = (float(b[0]) for b in joint_range_rad(model))
    q = xs[:, model.index(model.joints[0], "q_rad")]
    success, status, message = _verdict(settings, plant, tripped, float(np.max(np.maximum(q - hi, lo - q))))
    if fallbacks:
        message += f"; {fallbacks} periods used the fallback control"
    faults = sorted({e for names in r["events"] for e in names} - ROUTINE_EVENTS)
    if faults:
        message += f"; events: {', '.join(faults)}"
    first = model.joints[0]

    def logged(key):
        return np.array(r[key])[:, 0]

    return ClosedLoopResult(
        success=success, status=status, message=message, settings=settings,
        time_s=np.arange(xs.shape[0]) * settings.controller.control_period_s,
        winding_c=node("winding"), casing_c=node("casing"), drive_c=drive,
        q_rad=xs[:, model.index(first, "q_rad")], v_rad_s=xs[:, model.index(first, "v_rad_s")],
        estimated_winding_c=logged("est"), winding_std_c=logged("std"), resistance_scale=np.array(r["scale"]),
        measured_casing_c=logged("casing"), casing_received=np.array(r["received"]),
        current_a=logged("current"), voltage_v=logged("voltage"), period_voltage_v=logged("period_voltage"),
        solve_s=np.array([s.solve_s for s in steps]), first_solve_s=np.array([s.first_solve_s for s in steps]),
        iterations=np.array([s.iterations for s in steps]), step_status=tuple(s.status for s in steps),
        hold_s=np.array([s.hold_s for s in steps]), peak_winding_c=float(peak),
        safety_cutoff_c=plant.safety_cutoff_c, cutoff_tripped=tripped, planner_x0=np.array(r["x0"]),
        planner_params=np.array(r["params"]), measurements=tuple(r["measurements"]), events=tuple(r["events"]),
        tightening_c=np.array(r["tightening"], dtype=float),
        joint_range_rad=(lo, hi),
        current_peak_a=float(model.params[first].motor.current_peak_a),
        bus_voltage_v=float(model.params[first].motor.bus_voltage_v))
