"""Settings of the closed loop, one frozen object per part (do-mpc style): the scenario, the controller,
the estimator (EKF), the plant (its mismatch with the planner's model) and the sensors (with their
faults). ``MPCSettings`` composes them; ``MPCSettings.from_options`` routes flat options by name.

Times in s, temperatures in °C. Scenario: lift ``payload_kg``, hold ``hold_s`` (shortened online when it
becomes infeasible), lower; the TRUE winding must stay under ``limit_c`` (None: the parameter file's
default, :func:`thermo_ddp.tasks.limits.default_limit_c`); the planner uses ``limit_c - backoff_c``.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from .._config import checked_settings, require
from ..errors import InputError

_SRC = "MPCSettings"


def _optional(settings: object, source: str, name: str, low: float) -> None:
    value = getattr(settings, name)
    require(value is None or (isinstance(value, (int, float)) and not isinstance(value, bool) and value >= low),
            source, name, value, f"expected None or a number >= {low:g}")


def _integers(settings: object, source: str, *names: str) -> None:
    for name in names:
        value = getattr(settings, name)
        require(isinstance(value, int) and not isinstance(value, bool), source, name, value, "expected an integer")


def _flags(settings: object, source: str, *names: str) -> None:
    for name in names:
        value = getattr(settings, name)
        require(isinstance(value, bool), source, name, value, "expected True or False")


@checked_settings("MPCSettings scenario", payload_kg="[0, inf)", hold_s="[0, inf)", backoff_c="[0, inf)",
                  extra_s="[0, inf)", seed="[0, inf)")
class ScenarioSettings:
    """The task: lift ``payload_kg``, hold ``hold_s``, lower, then ``extra_s`` more; the random ``seed``."""

    payload_kg: float = 40.0
    limit_c: float | None = None
    hold_s: float = 10.0
    backoff_c: float = 1.0
    extra_s: float = 0.0                 # closed-loop time after the task (lift, hold, lower, settle)
    seed: int = 0
    parameter_file: str | None = None

    def __post_init__(self):
        _optional(self, "MPCSettings scenario", "limit_c", -50.0)
        _integers(self, "MPCSettings scenario", "seed")
        if self.limit_c is not None:
            require(self.backoff_c < self.limit_c - 30, _SRC, "backoff_c", self.backoff_c, "leaves no usable range")


@checked_settings("MPCSettings controller", control_period_s="(0, inf)", horizon_knots="[2, inf)",
                  max_iterations="[1, inf)", feasibility_tolerance="(0, inf)", warm_penalty_max="(0, inf)",
                  hold_step_s="(0, inf)", max_retries="[0, inf)", uncertainty_sigmas="[0, inf)",
                  sensor_fault_backoff_c="[0, inf)", ambient_change_c="(0, inf)", backoff_weight_per_k2="[0, inf)",
                  motion_weight="[0, inf)", stop_weight="[0, inf)", robust_uncertainty="[0, 1)", robust_sigmas="[0, inf)",
                  robust_replan_s="(0, inf)", lowering_reserve_c="[0, inf)",
                  range_margin_rad="[0, inf)", voltage_margin_v="[0, inf)")
class ControllerSettings:
    """Receding-horizon DDP: a solve slower than ``max_solve_s`` is discarded (a real-time deadline); the
    winding is held hard under the task's limit and the scenario's ``backoff_c`` band beneath it costs
    ``0.5 * backoff_weight_per_k2 * excess^2`` (0: the band is hard, the planning limit a constraint); the
    planner plans from the estimate with every thermal node raised by ``uncertainty_sigmas`` standard
    deviations of the winding estimate, plus ``sensor_fault_backoff_c`` once the casing sensor is
    distrusted; ``derate`` caps the fallback current at the no-heating current near the limit;
    ``careful_motion``: the planner's lift with ``LiftSettings.careful_motion`` (on, as the lift's); its rows cost
    ``0.5 * weight * excess_rad_s^2`` instead of binding (``motion_weight`` for ``one_way``, ``stop_weight`` for
    ``stop_approach``; 0: hard, from x_1 on); ``robust_uncertainty``
    > 0: the hold kept safe for every motor of the file's values within +-that fraction, its resistances
    narrowed to the observer's ``robust_sigmas`` interval, reviewed every ``robust_replan_s``
    (:mod:`thermo_ddp.mpc.robust`; 0: the nominal hold); ``lowering_reserve_c``: the winding limit of the
    lowering's knots lowered by this while the lowering lies ahead (the hold ends with the lowering's heat kept);
    ``range_margin_rad`` and ``voltage_margin_v``: soft bands inside the joint range and under the bus voltage
    (the hard rows kept; :func:`thermo_ddp.mpc.controller.controller_ocp`)."""

    control_period_s: float = 0.1        # = the planner's knot spacing
    horizon_knots: int = 200
    integrator: str = "rk4"              # planner's and observer's step over one control period
    max_iterations: int = 50             # DDP iterations per re-solve
    feasibility_tolerance: float = 1e-3  # largest constraint violation of an accepted plan (mK, mrad, mV:
                                         # below what the sensors resolve)
    warm_penalty_max: float = 1e6        # cap on the AL penalty carried from one re-solve to the next
    hold_step_s: float = 0.5             # the remaining hold is shortened by this when infeasible
    max_retries: int = 4                 # shortened re-solves per control period
    uncertainty_sigmas: float = 0.0
    sensor_fault_backoff_c: float = 3.0
    max_solve_s: float | None = None
    derate: bool = True
    ambient_change_c: float = 1.0        # the planner's ambient follows the room beyond this change
    backoff_weight_per_k2: float = 1e4   # > 0: the back-off band under the limit is soft (mpc.controller)
    careful_motion: bool = True          # one_way and stop_approach in the planner (mpc.controller)
    motion_weight: float = 10.0          # > 0: one_way soft, 0.5 * w * excess^2 (mpc.controller)
    stop_weight: float = 100.0           # > 0: stop_approach soft, 0.5 * w * excess^2 (mpc.controller)
    robust_uncertainty: float = 0.0      # the set's +-fraction (mpc.robust); 0: nominal planning
    robust_sigmas: float = 2.0           # the resistances' interval: the EKF's scale +- this many std
    robust_replan_s: float = 0.5         # the set and the hold reviewed this often while lifting and holding
    lowering_reserve_c: float = 1.0      # K; measured on the nominal sweep (benchmarks/README.md, branch mpc6)
    range_margin_rad: float = 0.04       # soft band inside the joint range (rad)
    voltage_margin_v: float = 2.0        # soft band under the bus voltage (V)

    def __post_init__(self):
        require(self.integrator in ("rk4", "implicit_euler"), "MPCSettings controller", "integrator",
                self.integrator, "choose rk4 or implicit_euler")
        _optional(self, "MPCSettings controller", "max_solve_s", 0.0)
        _flags(self, "MPCSettings controller", "derate", "careful_motion")
        _integers(self, "MPCSettings controller", "horizon_knots", "max_iterations", "max_retries")


@checked_settings("MPCSettings estimator", stuck_false_alarm="(0, 0.5)", innovation_window="[2, inf)",
                  innovation_threshold="(0, inf)", payload_mismatch_tolerance="(0, inf)")
class EstimatorSettings:
    """The EKF and its checks: the casing delay it compensates (None: the sensor's, i.e. known), the motor
    voltage as a winding thermometer, how it starts (``idle_equilibrium``: the first sample is an idle
    steady state; ``settled``: no current for minutes, winding = casing), the stuck-sensor tests."""

    estimate_resistance_scale: bool = True   # observer augmented with a thermal-resistance scale
    observe_voltage: bool = False           # EKF update with V = R(T_w) i + K_b N v
    observer_delay_steps: int | None = None
    observer_start: str = "idle_equilibrium"
    reject_repeated_casing: bool = True     # a sample equal to the previous one may be stale: not used
    stuck_false_alarm: float = 1e-6         # per-sample probability of a healthy run of equal samples
    innovation_window: int = 20
    innovation_threshold: float = 6.0       # |sum of normalised casing innovations| / sqrt(window)
    payload_mismatch_tolerance: float = 0.1  # relative hold-current error reported as a payload mismatch

    def __post_init__(self):
        src = "MPCSettings estimator"
        _flags(self, src, "estimate_resistance_scale", "observe_voltage", "reject_repeated_casing")
        _integers(self, src, "innovation_window")
        require(self.observer_start in ("idle_equilibrium", "settled"), src, "observer_start", self.observer_start,
                "choose idle_equilibrium or settled")
        d = self.observer_delay_steps
        require(d is None or (isinstance(d, int) and not isinstance(d, bool) and d >= 0), src,
                "observer_delay_steps", d, "expected None or an integer >= 0")


@checked_settings("MPCSettings plant", plant_resistance_scale="(0, inf)", plant_capacity_scale="(0, inf)",
                  plant_substeps="[1, inf)", plant_friction_scale="(0, inf)", plant_payload_scale="(0, inf)",
                  ambient_step_c="(-50, 50)", ambient_step_time_s="[0, inf)")
class PlantSettings:
    """The robot against the planner's model: every thermal resistance times ``plant_resistance_scale``,
    every heat capacity times ``plant_capacity_scale``, per-key scales of its ``[thermal]`` values,
    friction and payload scales, a uniform initial temperature, a room that warms by ``ambient_step_c``
    at ``ambient_step_time_s``; RK4 with ``plant_substeps`` sub-steps per control period."""

    plant_resistance_scale: float = 1.15
    plant_capacity_scale: float = 1.0
    plant_substeps: int = 10             # RK4 at control_period_s / plant_substeps (10 ms)
    plant_thermal_scales: tuple = ()     # ((key of [thermal], scale), ...) on top of the common scales
    plant_friction_scale: float = 1.0    # viscous and Coulomb friction of the plant
    plant_payload_scale: float = 1.0     # the plant carries payload_kg times this
    plant_initial_c: float | None = None  # None: idle steady state; else every node at this temperature
    ambient_step_c: float = 0.0
    ambient_step_time_s: float = 0.0

    def __post_init__(self):
        src = "MPCSettings plant"
        _integers(self, src, "plant_substeps")
        t0 = self.plant_initial_c
        require(t0 is None or (isinstance(t0, (int, float)) and -20 < t0 < 200), src, "plant_initial_c", t0,
                "expected None or a temperature in °C")
        scales = self.plant_thermal_scales
        require(isinstance(scales, tuple) and all(isinstance(k, str) and isinstance(v, (int, float)) and v > 0
                                                  for k, v in scales),
                src, "plant_thermal_scales", scales, "expected ((key, scale > 0), ...)")


@checked_settings("MPCSettings sensors", casing_noise_c="[0, inf)", casing_quantum_c="[0, inf)",
                  casing_delay_steps="[0, inf)", casing_dropout_probability="[0, 1)",
                  position_noise_rad="[0, inf)", velocity_noise_rad_s="[0, inf)", current_noise_a="[0, inf)",
                  ambient_noise_c="[0, inf)", voltage_noise_v="[0, inf)", casing_nan_probability="[0, 1)",
                  casing_stale_probability="[0, 1)")
class SensorSettings:
    """What the controller measures and how it fails: casing temperature with Gaussian noise,
    quantisation, a delay in control periods, dropouts, NaN and stale samples, a casing sensor stuck at
    its reading from ``casing_stuck_time_s`` on; q, v, the current, the room and the voltage with noise."""

    casing_noise_c: float = 0.1          # standard deviation
    casing_quantum_c: float = 0.1        # 0: no quantisation
    casing_delay_steps: int = 0
    casing_dropout_probability: float = 0.0
    position_noise_rad: float = 1e-4
    velocity_noise_rad_s: float = 5e-3
    current_noise_a: float = 0.02
    ambient_noise_c: float = 0.05        # room thermometer (standard deviation)
    voltage_noise_v: float = 0.05        # motor voltage reading (standard deviation)
    casing_nan_probability: float = 0.0
    casing_stale_probability: float = 0.0  # the previous delivered value is repeated instead
    casing_stuck_time_s: float | None = None

    def __post_init__(self):
        _optional(self, "MPCSettings sensors", "casing_stuck_time_s", 0.0)
        _integers(self, "MPCSettings sensors", "casing_delay_steps")


_PARTS = {"scenario": ScenarioSettings, "controller": ControllerSettings, "estimator": EstimatorSettings,
          "plant": PlantSettings, "sensors": SensorSettings}


@dataclasses.dataclass(frozen=True)
class MPCSettings:
    """The closed loop's settings, one object per part; build from flat options with :meth:`from_options`."""

    scenario: ScenarioSettings = ScenarioSettings()
    controller: ControllerSettings = ControllerSettings()
    estimator: EstimatorSettings = EstimatorSettings()
    plant: PlantSettings = PlantSettings()
    sensors: SensorSettings = SensorSettings()

    def __post_init__(self):
        for part, cls in _PARTS.items():
            require(isinstance(getattr(self, part), cls), _SRC, part, type(getattr(self, part)).__name__,
                    f"expected {cls.__name__}")

    @classmethod
    def from_options(cls, **options: Any) -> "MPCSettings":
        """Settings from flat options (each field name belongs to exactly one part); unknown names raise."""
        return cls().replace(**options)

    def replace(self, **options: Any) -> "MPCSettings":
        """A copy with flat options changed, each routed to its part."""
        grouped: dict[str, dict[str, Any]] = {}
        for name, value in options.items():
            grouped.setdefault(_part_of(name, value), {})[name] = value
        return dataclasses.replace(self, **{part: dataclasses.replace(getattr(self, part), **values)
                                            for part, values in grouped.items()})

    def with_default_limit(self, limit_c: float) -> "MPCSettings":
        """The settings with ``limit_c`` filled in when none was given (from the parameter file)."""
        if self.scenario.limit_c is not None:
            return self
        return self.replace(limit_c=float(limit_c))

    @property
    def observer_delay(self) -> int:
        """Control periods of casing delay the observer compensates."""
        d = self.estimator.observer_delay_steps
        return self.sensors.casing_delay_steps if d is None else d

    @property
    def limit_c(self) -> float:
        require(self.scenario.limit_c is not None, _SRC, "limit_c", None,
                "not resolved yet: use with_default_limit(file's limit) first")
        return self.scenario.limit_c

    @property
    def planning_limit_c(self) -> float:
        return self.limit_c - self.scenario.backoff_c

    def flat(self) -> dict[str, Any]:
        """Every option by its flat name (the inverse of :meth:`from_options`)."""
        return {k: v for part in _PARTS for k, v in dataclasses.asdict(getattr(self, part)).items()}


def _part_of(name: str, value: object) -> str:
    for part, cls in _PARTS.items():
        if name in _FIELDS[part]:
            return part
    known = sorted(n for names in _FIELDS.values() for n in names)
    raise InputError(_SRC, name, value, f"unknown option; known: {', '.join(known)}")


_FIELDS: Mapping[str, frozenset[str]] = {part: frozenset(f.name for f in dataclasses.fields(cls))
                                         for part, cls in _PARTS.items()}

