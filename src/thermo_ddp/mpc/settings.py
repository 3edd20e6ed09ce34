"""``MPCSettings``: the closed-loop scenario, the plant's mismatch, the sensors and the controller."""
from __future__ import annotations

import dataclasses
import math

from .._config import require

_SRC = "MPCSettings"


@dataclasses.dataclass(frozen=True)
class MPCSettings:
    """Frozen, validated options of :func:`thermo_ddp.mpc.run_closed_loop` (times in s, temperatures in °C).

    Scenario: lift ``payload_kg``, hold ``hold_s`` (shortened online when it becomes infeasible),
    lower; the TRUE winding must stay under ``limit_c``; the planner uses ``limit_c - backoff_c``.
    Plant: every thermal resistance of the planner's model times ``plant_resistance_scale``, every
    heat capacity times ``plant_capacity_scale``; RK4 with ``plant_substeps`` sub-steps per control
    period. Sensors: casing temperature with Gaussian noise, quantisation, a delay in control
    periods and dropouts; q, v and the current with Gaussian noise.

    Faults and bad conditions (defaults: none). Sensor: NaN samples, stale samples (the previous
    value repeated), a casing sensor stuck at its reading from ``casing_stuck_time_s`` on. Plant:
    per-key scales of its ``[thermal]`` values, friction and payload scales, a uniform initial
    temperature, a room that warms by ``ambient_step_c`` at ``ambient_step_time_s``. Observer: the
    casing delay it compensates (None: the plant's, i.e. known), the motor voltage as a winding
    thermometer (``observe_voltage``), how it starts (``idle_equilibrium``: the first sample is an
    idle steady state; ``settled``: no current for minutes, winding = casing), the stuck-sensor tests.
    Controller: a solve slower than ``max_solve_s`` is discarded (a real-time deadline); the planner
    plans from the estimate with every thermal node raised by ``uncertainty_sigmas`` standard
    deviations of the winding estimate, plus ``sensor_fault_backoff_c`` once the casing sensor is
    distrusted; ``derate`` caps the fallback current at the no-heating current near the limit.
    """

    payload_kg: float = 40.0
    limit_c: float = 84.0
    hold_s: float = 10.0
    backoff_c: float = 1.0
    control_period_s: float = 0.1        # = the planner's knot spacing
    horizon_knots: int = 200
    integrator: str = "rk4"              # planner's and observer's step over one control period
    extra_s: float = 0.0                 # closed-loop time after the task (lift, hold, lower, settle)
    max_iterations: int = 50             # DDP iterations per re-solve
    feasibility_tolerance: float = 1e-4  # largest constraint violation of an accepted plan
    warm_penalty_max: float = 1e6        # cap on the AL penalty carried from one re-solve to the next
    hold_step_s: float = 0.5             # the remaining hold is shortened by this when infeasible
    max_retries: int = 4                 # shortened re-solves per control period
    plant_resistance_scale: float = 1.15
    plant_capacity_scale: float = 1.0
    plant_substeps: int = 10             # RK4 at control_period_s / plant_substeps (10 ms)
    casing_noise_c: float = 0.1          # standard deviation
    casing_quantum_c: float = 0.1        # 0: no quantisation
    casing_delay_steps: int = 0
    casing_dropout_probability: float = 0.0
    position_noise_rad: float = 1e-4
    velocity_noise_rad_s: float = 5e-3
    current_noise_a: float = 0.02
    estimate_resistance_scale: bool = True   # observer augmented with a thermal-resistance scale
    seed: int = 0
    parameter_file: str | None = None
    # --- faults and bad conditions -------------------------------------------------------
    casing_nan_probability: float = 0.0
    casing_stale_probability: float = 0.0   # the previous delivered value is repeated instead
    casing_stuck_time_s: float | None = None
    plant_thermal_scales: tuple = ()        # ((key of [thermal], scale), ...) on top of the common scales
    plant_friction_scale: float = 1.0       # viscous and Coulomb friction of the plant
    plant_payload_scale: float = 1.0        # the plant carries payload_kg times this
    plant_initial_c: float | None = None    # None: idle steady state; else every node at this temperature
    ambient_step_c: float = 0.0
    ambient_step_time_s: float = 0.0
    ambient_noise_c: float = 0.05           # room thermometer (standard deviation)
    ambient_change_c: float = 1.0           # the planner's ambient follows the room beyond this change
    voltage_noise_v: float = 0.05           # motor voltage reading (standard deviation)
    observe_voltage: bool = False           # EKF update with V = R(T_w) i + K_b N v
    observer_delay_steps: int | None = None
    observer_start: str = "idle_equilibrium"
    reject_repeated_casing: bool = True     # a sample equal to the previous one may be stale: not used
    stuck_false_alarm: float = 1e-6         # per-sample probability of a healthy run of equal samples
    innovation_window: int = 20
    innovation_threshold: float = 6.0       # |sum of normalised casing innovations| / sqrt(window)
    sensor_fault_backoff_c: float = 3.0
    uncertainty_sigmas: float = 0.0
    max_solve_s: float | None = None
    derate: bool = True
    payload_mismatch_tolerance: float = 0.1  # relative hold-current error reported as a payload mismatch

    def __post_init__(self):
        require(self.payload_kg >= 0, _SRC, "payload_kg", self.payload_kg, "must be >= 0")
        require(-50 < self.limit_c < 250, _SRC, "limit_c", self.limit_c, "expected a winding limit in °C")
        for name in ("hold_s", "backoff_c", "extra_s", "casing_noise_c", "casing_quantum_c", "position_noise_rad",
                     "velocity_noise_rad_s", "current_noise_a"):
            value = getattr(self, name)
            require(_number(value) and value >= 0, _SRC, name, value, "expected a finite number >= 0")
        for name in ("control_period_s", "feasibility_tolerance", "warm_penalty_max", "hold_step_s",
                     "plant_resistance_scale", "plant_capacity_scale"):
            value = getattr(self, name)
            require(_number(value) and value > 0, _SRC, name, value, "expected a finite number > 0")
        for name, low in (("horizon_knots", 2), ("max_iterations", 1), ("max_retries", 0),
                          ("plant_substeps", 1), ("casing_delay_steps", 0), ("seed", 0)):
            value = getattr(self, name)
            require(isinstance(value, int) and not isinstance(value, bool) and value >= low, _SRC, name, value,
                    f"expected an integer >= {low}")
        require(self.backoff_c < self.limit_c - 30, _SRC, "backoff_c", self.backoff_c, "leaves no usable range")
        p = self.casing_dropout_probability
        require(_number(p) and 0 <= p < 1, _SRC, "casing_dropout_probability", p, "expected a number in [0, 1)")
        require(self.integrator in ("rk4", "implicit_euler"), _SRC, "integrator", self.integrator,
                "choose rk4 or implicit_euler")
        require(isinstance(self.estimate_resistance_scale, bool), _SRC, "estimate_resistance_scale",
                self.estimate_resistance_scale, "expected True or False")

        self._validate_faults()

    def _validate_faults(self):
        for name in ("casing_nan_probability", "casing_stale_probability"):
            p = getattr(self, name)
            require(_number(p) and 0 <= p < 1, _SRC, name, p, "expected a number in [0, 1)")
        for name in ("ambient_noise_c", "voltage_noise_v", "sensor_fault_backoff_c", "uncertainty_sigmas",
                     "ambient_step_time_s"):
            value = getattr(self, name)
            require(_number(value) and value >= 0, _SRC, name, value, "expected a finite number >= 0")
        for name in ("plant_friction_scale", "plant_payload_scale", "ambient_change_c", "innovation_threshold"):
            value = getattr(self, name)
            require(_number(value) and value > 0, _SRC, name, value, "expected a finite number > 0")
        require(_number(self.ambient_step_c) and abs(self.ambient_step_c) < 50, _SRC, "ambient_step_c",
                self.ambient_step_c, "expected a room temperature change in K")
        for name in ("casing_stuck_time_s", "max_solve_s"):
            value = getattr(self, name)
            require(value is None or (_number(value) and value >= 0), _SRC, name, value, "expected None or >= 0")
        require(self.plant_initial_c is None or (_number(self.plant_initial_c) and -20 < self.plant_initial_c < 200),
                _SRC, "plant_initial_c", self.plant_initial_c, "expected None or a temperature in °C")
        scales = self.plant_thermal_scales
        require(isinstance(scales, tuple) and all(isinstance(k, str) and _number(v) and v > 0 for k, v in scales),
                _SRC, "plant_thermal_scales", scales, "expected ((key, scale > 0), ...)")
        d = self.observer_delay_steps
        require(d is None or (isinstance(d, int) and not isinstance(d, bool) and d >= 0), _SRC,
                "observer_delay_steps", d, "expected None or an integer >= 0")
        require(isinstance(self.innovation_window, int) and self.innovation_window >= 2, _SRC, "innovation_window",
                self.innovation_window, "expected an integer >= 2")
        require(_number(self.stuck_false_alarm) and 0 < self.stuck_false_alarm < 0.5, _SRC, "stuck_false_alarm",
                self.stuck_false_alarm, "expected a probability in (0, 0.5)")
        require(self.observer_start in ("idle_equilibrium", "settled"), _SRC, "observer_start", self.observer_start,
                "choose idle_equilibrium or settled")
        for name in ("observe_voltage", "reject_repeated_casing", "derate"):
            require(isinstance(getattr(self, name), bool), _SRC, name, getattr(self, name), "expected True or False")

    @property
    def observer_delay(self) -> int:
        """Control periods of casing delay the observer compensates."""
        return self.casing_delay_steps if self.observer_delay_steps is None else self.observer_delay_steps

    @property
    def planning_limit_c(self) -> float:
        return self.limit_c - self.backoff_c


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
