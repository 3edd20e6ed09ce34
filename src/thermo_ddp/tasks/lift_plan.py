"""The answer of :func:`thermo_ddp.tasks.lift.plan_lift`: the plan, its verdict in words and its cause.

Statuses (contract, third round): ``feasible`` (the requested hold), ``infeasible_hold`` (a shorter hold is
the longest feasible one), ``infeasible`` (not even reaching the goal; or, with ``find_longest_hold`` off,
the requested hold) and ``failed`` (no solve reached a verdict: nothing is said about the robot). The cause
(``thermal``, ``actuator``, ``motion``, ``range``) comes from the constraints that decide the verdict and
their multipliers, with the number a user can change.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from .limits import joint_range_rad
from .motion import MotionQuality
from .series import PlanSeries, format_s
from .verdicts import CAUSE_WORDS



@dataclasses.dataclass(frozen=True)
class LiftPlan(PlanSeries):
    """The answer of :func:`plan_lift` (contract: ``to_dict()`` is the plan JSON).

    ``cause``: the class of the constraints that decide the verdict (None when feasible or failed);
    ``remedy``: the number a user can change (e.g. ``lift_s >= 1.42 s``, ``limit_c >= 97.3 °C``)."""

    feasible: bool
    status: str
    message: str
    settings: Any
    achieved_hold_s: float
    time_s: np.ndarray
    xs: np.ndarray
    us: np.ndarray
    model: Any
    solver: Mapping[str, Any]
    binding_constraints: tuple[str, ...]
    time_to_limit_s: float
    cause: str | None = None
    remedy: str = ""

    @property
    def motion(self) -> MotionQuality:
        """Reversals, speed near the stops, rest at the end, acceleration (see :class:`MotionQuality`)."""
        lo, hi = (b[0] for b in joint_range_rad(self.model))
        return MotionQuality.of(self.time_s, self.xs[:, 0], self.xs[:, 1], lo, hi)

    def to_dict(self) -> dict:
        s = self.settings
        d = self.contract_dict(s.payload_kg, s.limit_c, s.hold_s, self.achieved_hold_s, s.integrator, s.dt_s)
        d["remedy"] = self.remedy or None
        return d

    def headline(self) -> str:
        """The answer in a sentence: ``40 kg: holds 12.4 s of the 60 s asked under 84 °C; the winding limit
        decides (time to limit at the goal 13.0 s)``."""
        s = self.settings
        head = f"{s.payload_kg:g} kg: "
        if self.status == "failed":
            return head + "no answer: " + self.message
        if self.status == "feasible":
            return head + f"holds the {s.hold_s:g} s asked under {s.limit_c:g} °C"
        if self.status == "infeasible_hold":
            text = f"holds {self.achieved_hold_s:.1f} s of the {s.hold_s:g} s asked under {s.limit_c:g} °C"
        elif s.find_longest_hold:
            text = f"cannot be lifted to the goal under {s.limit_c:g} °C"
        else:
            text = f"cannot hold the {s.hold_s:g} s asked under {s.limit_c:g} °C"
        decides = f"; {CAUSE_WORDS[self.cause]}" if self.cause else ""
        ttl = f" (time to limit at the goal {format_s(self.time_to_limit_s)})" if self.cause == "thermal" else ""
        return head + text + decides + ttl

    def report(self) -> str:
        w, c, m = self.series("winding_c").max(), self.sensor_c().max(), self.motion
        lines = [self.headline()]
        if self.remedy:
            lines.append(f"  to do better: {self.remedy}")
        if self.status != "failed":
            lines.append(f"  time to limit at the goal {format_s(self.time_to_limit_s)}; peak winding {w:.1f} °C, "
                         f"peak casing {c:.1f} °C, peak |current| {np.abs(self.us).max():.2f} A")
            lines.append(f"  constraints at their bound: {', '.join(self.binding_constraints) or 'none'}")
            lines.append(f"  motion: {m.reversals} reversal(s), {m.max_speed_near_stop_rad_s:.2f} rad/s at most within "
                         f"0.1 rad of a stop, {m.final_speed_rad_s:.3f} rad/s at the end, "
                         f"{m.max_acceleration_rad_s2:.1f} rad/s² at most")
        sv = self.solver
        lines.append(f"  solver {sv['name']}: {sv['solves']} solve(s), {sv['work']['iterations']} iterations, "
                     f"{1e3 * sv['total_solve_s']:.0f} ms")
        return "\n".join(lines)

    def plot(self, path=None):
        """The plan's figure: written to ``path`` when given, else returned (a matplotlib Figure, for notebooks)."""
        from .plots import plot_lift
        return plot_lift(self, path)


@dataclasses.dataclass(frozen=True)
class LimitComparison:
    """The same lift planned under several winding limits."""

    plans: tuple[LiftPlan, ...]

    def rows(self) -> list[dict]:
        return [{"limit_c": p.settings.limit_c, "status": p.status, "hold_s": p.achieved_hold_s,
                 "peak_winding_c": float(p.series("winding_c").max()),
                 "peak_casing_c": float(p.sensor_c().max()),
                 "joule_energy_j": joule_energy_j(p), "binding": ", ".join(p.binding_constraints),
                 "solve_s": p.solver["total_solve_s"]} for p in self.plans]

    def table(self) -> str:
        p0 = self.plans[0].settings
        head = (f"{p0.payload_kg:g} kg at the gripper, requested hold {p0.hold_s:g} s\n"
                f"{'limit °C':>9} {'holds all':>9} {'hold s':>7} {'winding °C':>11} {'casing °C':>10} "
                f"{'Joule kJ':>9} {'solve s':>8}  binding")
        words = {"feasible": "yes", "infeasible_hold": "part", "infeasible": "no", "failed": "unknown"}
        lines = [f"{r['limit_c']:9.0f} {words[r['status']]:>9} {r['hold_s']:7.1f} {r['peak_winding_c']:11.1f} "
                 f"{r['peak_casing_c']:10.1f} {r['joule_energy_j'] / 1e3:9.2f} {r['solve_s']:8.2f}  {r['binding']}"
                 for r in self.rows()]
        return "\n".join([head, *lines, *(f"  {p.headline()}" for p in self.plans)])


def joule_energy_j(plan: LiftPlan) -> float:
    """Heat put into the winding over the plan, sum of R(T_w) i^2 dt."""
    joule = plan.model.outputs.map(plan.us.shape[0])
    amb = np.full((1, plan.us.shape[0]), plan.model.ambient_c)
    power = np.array(joule(plan.xs[:-1].T, plan.us.T, amb)[plan.model.outputs.name_out().index("joule_w")])
    return float(power.sum() * plan.settings.dt_s)


def stop_approach_time_s(lo: float, hi: float, a: float, b: float, stop_speed: float, slope: float,
                         velocity_limit: float, samples: int = 2001) -> float:
    """Shortest time to move from ``a`` to ``b`` within the stop-approach speed bound (the speed allowed
    ``stop_speed + slope * distance`` to the nearer stop of [lo, hi], at most ``velocity_limit``): the
    integral of dq / v_max(q) (a lower bound on the lift or lowering time)."""
    q = np.linspace(min(a, b), max(a, b), samples)
    vmax = np.minimum(np.minimum(stop_speed + slope * (hi - q), stop_speed + slope * (q - lo)), velocity_limit)
    inv = 1.0 / np.maximum(vmax, 1e-12)
    return float(np.sum((inv[1:] + inv[:-1]) / 2 * np.diff(q))) if samples > 1 else math.inf
