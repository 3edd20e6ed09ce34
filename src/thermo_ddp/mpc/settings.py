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

    @property
    def planning_limit_c(self) -> float:
        return self.limit_c - self.backoff_c


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
