"""The whole arm: several joints, each with its own motor, thermal network and winding limit.

On the composed model of :mod:`thermo_ddp.model.actuated` (joints chosen by name):
:func:`plan_whole_arm` chooses the holding posture (:mod:`thermo_ddp.tasks.posture`), then plans by
DDP from the hanging posture to it and the hold, with per-joint constraints by name
(``winding_limit_<joint>``, ``bus_voltage_<joint>``, ``joint_range_<joint>``, ``joint_velocity_<joint>``;
the current box is each joint's peak, ``current_peak_<joint>``) and the task-space ``hold_band``.
Each joint's winding limit is its parameter file's unless ``limit_c`` is given. The result names
the joint that limits the hold and how long the hold can last (simulated from the plan's state on
arrival).

Stiffness: the tanh-smoothed Coulomb friction (slope F_c / smoothing at v = 0) over the small
inertias of the upper-arm rotation and wrist joints gives eigenvalues up to ~110 /s (7 joints);
classic RK4 is stable for |lambda| dt < 2.78, so the control step is chosen from the model's
spectrum (:func:`stable_dt_s`) unless given.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from .._config import require, settings_from_mapping
from ..model import motor
from ..model.actuated import ActuatedArm, load_model
from ..model.arm import ELBOW, LEFT_ARM, PAYLOAD_KG
from ..model.parameters import Bound
from ..ocp import Constraint, Cost, KnotParameters, OptimalControlProblem, term_function
from ..solvers import DDPSettings, DDPSolver, WarmStart
from .constraints import joint_limit_constraints
from .limits import DEFAULT_HOLD_S, HOLD_S, check_fields, check_knots, check_limit_c, winding_limits_c
from .problem import TaskProblem, initial_guess
from .series import PlanSeries, finite_or_none, format_s
from .thermal_hold import limiting_joint, time_to_limit_by_joint
from .attempts import SolverLadder, rest_guess, solve_until_verdict
from .verdicts import (CAUSE_WORDS, binding_constraints, cause_of, deciding_constraints, solver_summary, verdict,
                       violated_constraints)
from .lift import SETTING_BOUNDS as LIFT_BOUNDS
from .lift import min_jerk
from .posture import (PostureChoice, evaluate_posture, hanging_posture, naive_posture, optimal_posture,
                      payload_point_function)

log = logging.getLogger(__name__)
_SRC = "plan_whole_arm"
RK4_STABLE = 2.0          # |lambda| dt kept below this (RK4's real-axis limit is 2.785)
_POSITIVE_HOLD_S = Bound(1e-3, HOLD_S.high, HOLD_S.unit, HOLD_S.reason)
SETTING_BOUNDS = {  # every number of WholeArmSettings and its range
    "payload_kg": PAYLOAD_KG, "hold_s": _POSITIVE_HOLD_S, "posture_hold_s": _POSITIVE_HOLD_S,
    "move_s": LIFT_BOUNDS["lift_s"], "tracking_weight": LIFT_BOUNDS["tracking_weight"],
    "energy_weight": LIFT_BOUNDS["energy_weight"], "velocity_weight": LIFT_BOUNDS["velocity_weight"],
    "target_tolerance_m": Bound(1e-6, 1.0, "m", "a band around the payload point"),
    "range_margin_rad": Bound(0.0, 0.5, "rad", "kept inside each joint's range"),
}


@dataclasses.dataclass(frozen=True)
class WholeArmSettings:
    """The whole-arm hold task and its transcription (times in s, angles in rad, lengths in m).

    ``joints``: planned joints by name (shoulder to wrist); the others are locked at
    ``locked_posture`` (default 0 rad). ``limit_c``: the winding limit of every joint (None: each
    joint's own, from its parameter file). ``target_m``: payload point in the base frame of the
    reduced model (default: where the naive posture holds it). ``posture_hold_s``: H of the posture
    objective. ``posture_choice``: ``"optimal"`` (the NLP) or ``"naive"`` (elbow at -pi/2, the rest
    at 0). ``dt_s``: control step (None: the largest stable RK4 step, see :func:`stable_dt_s`).
    """

    joints: tuple[str, ...] = LEFT_ARM[:4]
    payload_kg: float = 40.0
    limit_c: float | None = None
    hold_s: float = DEFAULT_HOLD_S
    move_s: float = 3.0
    posture_hold_s: float = 60.0
    posture_choice: str = "optimal"
    target_m: tuple[float, float, float] | None = None
    target_tolerance_m: float = 0.02
    locked_posture: Mapping[str, float] = dataclasses.field(default_factory=dict)
    range_margin_rad: float = 0.05
    dt_s: float | None = None
    tracking_weight: float = 100.0
    energy_weight: float = 1e-2
    velocity_weight: float = 1e-2
    starts: int = 8
    seed: int = 0
    ddp_backend: str = "codegen"
    gauss_newton_iterations: int = 100
    max_iterations: int = 300

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(self.joints))
        require(ELBOW in self.joints, _SRC, "joints", list(self.joints),
                f"the payload hangs on the forearm: include {ELBOW}")
        check_fields(self, _SRC, SETTING_BOUNDS)
        object.__setattr__(self, "limit_c", check_limit_c(_SRC, self.limit_c))
        require(self.posture_choice in ("optimal", "naive"), _SRC, "posture_choice", self.posture_choice,
                "choose optimal or naive")
        if self.dt_s is not None:
            check_fields(self, _SRC, {"dt_s": LIFT_BOUNDS["dt_s"]})
            check_knots(_SRC, round((self.move_s + self.hold_s) / self.dt_s), self.dt_s)
        for name in ("gauss_newton_iterations", "max_iterations"):
            v = getattr(self, name)
            require(isinstance(v, int) and v >= 0, _SRC, name, v, "expected an integer >= 0")
        require(isinstance(self.starts, int) and self.starts >= 1, _SRC, "starts", self.starts,
                "expected an integer >= 1")
        require(self.ddp_backend in ("codegen", "casadi", "numpy"), _SRC, "ddp_backend", self.ddp_backend,
                "choose codegen, casadi or numpy")
        if self.target_m is not None:
            t = tuple(float(v) for v in self.target_m)
            require(len(t) == 3 and all(map(math.isfinite, t)), _SRC, "target_m", self.target_m,
                    "expected three finite numbers (x, y, z) in m")
            object.__setattr__(self, "target_m", t)


def stable_dt_s(model: ActuatedArm, postures: Sequence[np.ndarray], dt_max_s: float = 0.1) -> float:
    """Largest dt = dt_max / k (k integer) with |lambda| dt <= RK4_STABLE at rest in ``postures``."""
    lam = 0.0
    for q in postures:
        x = model.state(q=q)
        a = np.array(model.ode_jacobians(x, model.static_current_a(q), model.ambient_c)[1])
        lam = max(lam, float(np.abs(np.linalg.eigvals(a)).max()))
    return dt_max_s / max(1, math.ceil(lam * dt_max_s / RK4_STABLE))


# --------------------------------------------------------------------------------------------
# The dynamic plan: hanging -> posture -> hold, by DDP
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class HoldProblem(TaskProblem):
    """The transcribed move-and-hold. p per knot = [q_ref (n), tracking weight, hold flag, ambient]."""

    dt_s: float
    hold_knot: int
    q_goal: np.ndarray
    target_m: np.ndarray
    limits_c: Mapping[str, float]


def _joint_constraints(model, x, u, p, limits_c, vmax):
    """Per joint, by name: winding_limit_<j>, bus_voltage_<j> (at the knot's start only: the rows at its end grow
    the 7-joint arm's local model; its build took a median 18.4 s with them, 16.6 s without, 3 alternated runs each), joint_range_<j>,
    joint_velocity_<j>."""
    out = []
    for k, j in enumerate(model.joints):
        for kind, g in joint_limit_constraints(model, j, x, u[k], limits_c[j], vmax[k]).items():
            out.append(Constraint(f"{kind}_{j}", term_function(f"{kind}_{j}", g, "g", x, p, u)))
    return out


def hold_parameters(joints: int) -> KnotParameters:
    """Per-knot parameters of the hold: each joint's reference angle, the tracking weight, 1 on the
    hold's knots, the room."""
    return KnotParameters((("q_ref_rad", joints), ("tracking_weight", 1), ("hold_flag", 1), ("ambient_c", 1)))


def build_hold_problem(model: ActuatedArm, settings: WholeArmSettings, q_goal, target_m, dt_s: float) -> HoldProblem:
    """Move from the hanging posture to ``q_goal`` in ``move_s`` (min-jerk reference), then hold ``hold_s``
    with the payload inside the ``hold_band`` around ``target_m``; every joint's limits as constraints."""
    n, s = model.nu, settings
    limits = winding_limits_c(model, s.limit_c)
    layout = hold_parameters(n)
    x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", n), ca.SX.sym("p", layout.size)
    par = layout.symbols(p)
    step, jac = model.step_function(dt_s), model.step_jacobians(dt_s)
    dyn = term_function("hold_dynamics", step(x, u, par["ambient_c"]), "x_next", x, p, u)
    dyn_jac = ca.Function("hold_dynamics_jacobians", [x, u, p], list(jac(x, u, par["ambient_c"])), ["x", "u", "p"],
                          ["x_next", "A", "B"])
    q = x[[model.index(j, "q_rad") for j in model.joints]]
    v = x[[model.index(j, "v_rad_s") for j in model.joints]]
    w = x[[model.index(j, "winding_c") for j in model.joints]]
    res = ca.vertcat(*[motor.resistance_ohm(model.params[j].motor, w[k]) for k, j in enumerate(model.joints)])
    tracking = ca.sqrt(par["tracking_weight"]) * (q - par["q_ref_rad"])
    costs = (Cost("tracking", 1.0, term_function("tracking", tracking, "r", x, p, u)),
             Cost("joule_energy", s.energy_weight,
                  term_function("joule_energy", ca.sqrt(res * dt_s) * u, "r", x, p, u)),
             Cost("velocity", s.velocity_weight, term_function("velocity", v, "r", x, p, u)))
    tcosts = (Cost("terminal_tracking", s.tracking_weight,
                   term_function("terminal_tracking", q - par["q_ref_rad"], "r", x, p)),
              Cost("terminal_velocity", 1.0, term_function("terminal_velocity", v, "r", x, p)))
    point = payload_point_function(model)(q)
    target, tol = ca.DM(np.asarray(target_m, float)), s.target_tolerance_m
    band = ca.vertcat(par["hold_flag"] * (point - target) - tol, par["hold_flag"] * (target - point) - tol)
    vmax = np.asarray(model.arm.model.velocityLimit, float)
    w_max = ca.DM([limits[j] for j in model.joints])
    cons = tuple(_joint_constraints(model, x, u, p, limits, vmax)) + (
        Constraint("hold_band", term_function("hold_band", band, "g", x, p, u)),)
    tcons = (Constraint("terminal_winding_limit", term_function("terminal_winding_limit", w - w_max, "g", x, p)),
             Constraint("terminal_hold_band", term_function("terminal_hold_band", band, "g", x, p)))
    peak = np.array([model.params[j].motor.current_peak_a for j in model.joints])
    move, hold = int(round(s.move_s / dt_s)), int(round(s.hold_s / dt_s))
    check_knots(_SRC, move + hold, dt_s)
    problem = OptimalControlProblem(dyn, move + hold, costs, tcosts, cons, tcons, u_lb=-peak, u_ub=peak,
                                    name=f"whole_arm_{n}", dynamics_jacobians=dyn_jac, parameters=layout)
    start = hanging_posture(model, s.range_margin_rad)
    q_ref = np.vstack([start + np.outer(min_jerk(np.arange(move + 1) / move), np.asarray(q_goal) - start),
                       np.tile(q_goal, (hold, 1))])
    flag = (np.arange(move + hold + 1) >= move).astype(float)
    params = layout.values(move + hold + 1, q_ref_rad=q_ref, tracking_weight=s.tracking_weight, hold_flag=flag,
                           ambient_c=model.ambient_c)
    return HoldProblem(model=model, problem=problem, x0=model.state(q=start), params=params,
                       time_s=np.arange(move + hold + 1) * dt_s,
                       box_names=tuple(f"current_peak_{j}" for j in model.joints), dt_s=dt_s, hold_knot=move,
                       q_goal=np.asarray(q_goal, float), target_m=np.asarray(target_m, float), limits_c=limits)


def solve_hold(hp: HoldProblem, settings: WholeArmSettings, warm_start: WarmStart | None = None):
    """Solve until a verdict (:mod:`thermo_ddp.tasks.attempts`): first Gauss-Newton iLQR (robust from the gapped
    initial guess), then full DDP warm-started from it when not yet converged (the R(T) i^2 curvature of an
    active winding limit); without a verdict, a regularised restart, the same from rest, then IPOPT.
    Returns (outcome, summary).

    Full DDP from the cold guess fails on the 4-joint arm: the dynamics-tensor term makes the value
    Hessians indefinite and Quu regularisation does not bound them."""
    stages: list[dict] = []
    guess = warm_start or initial_guess(hp)
    ladder = SolverLadder(hp.problem, None, DDPSettings(backend=settings.ddp_backend,
                                                        max_iterations=max(settings.max_iterations, 1)))
    outcome = solve_until_verdict((
        ("ddp", lambda: _staged(hp, settings, guess, stages)),
        ("ddp regularised restart", lambda: ladder.restart.solve(hp.x0, hp.params, WarmStart(guess.xs, guess.us))),
        ("ddp regularised from rest", lambda: ladder.restart.solve(hp.x0, hp.params, rest_guess(hp))),
        ("ipopt", lambda: ladder.reference.solve(hp.x0, hp.params, WarmStart(guess.xs, guess.us)))))
    results = outcome.results
    solve_s = sum(r.solve_s for r in results)
    summary = solver_summary(outcome.result, solve_s, len(results) - 1 + len(stages), results, solve_s=solve_s,
                             stages=stages, attempts=[name for name, _ in outcome.attempts])
    return outcome, summary


def _staged(hp: HoldProblem, settings: WholeArmSettings, warm: WarmStart, stages: list[dict]):
    """Gauss-Newton iLQR, then full DDP from it unless already feasible (each stage recorded in ``stages``)."""
    result = None
    for full, iterations in ((False, settings.gauss_newton_iterations), (True, settings.max_iterations)):
        if iterations == 0 or (result is not None and verdict(result) == "feasible"):
            continue
        solver = DDPSolver(hp.problem, DDPSettings(full_second_order=full, backend=settings.ddp_backend,
                                                   max_iterations=iterations))
        result = solver.solve(hp.x0, hp.params, warm)
        warm = WarmStart.from_result(result)
        stages.append({"full_second_order": full, "status": result.status, "iterations": int(result.iterations),
                       "solve_s": float(result.solve_s), "build_s": float(solver.build_s)})
    return result


@dataclasses.dataclass(frozen=True)
class WholeArmPlan(PlanSeries):
    """The answer of :func:`plan_whole_arm`: the chosen posture, the naive one, the DDP plan and the hold limit.

    ``to_dict()`` follows the plan JSON contract (arrays [time][joint], ``model`` echo; ``limit_c`` the
    lowest joint limit), with extra keys ``limits_c``, ``violated_constraints``, ``posture``,
    ``naive_posture``, ``limiting_joint``, ``time_to_limit_by_joint_s``. Constraint names carry the
    joint: ``winding_limit_arm_left_2_joint``, ``current_peak_arm_left_4_joint``.
    """

    feasible: bool
    status: str
    message: str
    settings: WholeArmSettings
    posture: PostureChoice
    naive: PostureChoice
    time_s: np.ndarray
    xs: np.ndarray
    us: np.ndarray
    dt_s: float
    model: ActuatedArm
    solver: Mapping[str, Any]
    binding_constraints: tuple[str, ...]
    violated_constraints: tuple[str, ...]
    time_to_limit_by_joint_s: Mapping[str, float]
    limits_c: Mapping[str, float]
    cause: str | None = None   # thermal | actuator | motion | range when infeasible (see tasks.verdicts.CAUSES)

    @property
    def limiting_joint(self) -> str:
        final = dict(zip(self.model.joints, self.series("winding_c")[-1]))
        return limiting_joint(self.time_to_limit_by_joint_s, final)

    @property
    def time_to_limit_s(self) -> float:
        """How long the hold can last from the plan's state on arrival at the posture."""
        return float(self.time_to_limit_by_joint_s[self.limiting_joint])

    @property
    def gain(self) -> float:
        """Hold time at the chosen posture over the naive one (static, from idle)."""
        return self.posture.hold_limit_s / self.naive.hold_limit_s if self.naive.hold_limit_s > 0 else math.inf

    def to_dict(self) -> dict:
        s = self.settings
        d = self.contract_dict(s.payload_kg, min(self.limits_c.values()), s.hold_s,
                               s.hold_s if self.feasible else 0.0, "rk4", self.dt_s)
        d.update(limits_c=dict(self.limits_c), violated_constraints=list(self.violated_constraints),
                 posture=self.posture.to_dict(), naive_posture=self.naive.to_dict(), limiting_joint=self.limiting_joint,
                 time_to_limit_by_joint_s={j: finite_or_none(t) for j, t in self.time_to_limit_by_joint_s.items()})
        return d

    def report(self) -> str:
        p, nv, s = self.posture, self.naive, self.settings
        rows = [f"{'joint':>17} {'limit °C':>8} {'naive q':>8} {'naive A':>8} {'naive s':>8} {'chosen q':>9} "
                f"{'chosen A':>9} {'chosen s':>9} {'plan Tw max':>11}"]
        wmax = self.series("winding_c").max(axis=0)
        for k, j in enumerate(self.model.joints):
            rows.append(f"{j:>17} {self.limits_c[j]:8.1f} {nv.q_rad[k]:8.3f} {nv.current_a[k]:8.2f} "
                        f"{format_s(nv.time_to_limit_s[j]):>8} {p.q_rad[k]:9.3f} {p.current_a[k]:9.2f} "
                        f"{format_s(p.time_to_limit_s[j]):>9} {wmax[k]:11.1f}")
        return "\n".join([
            f"whole arm ({len(self.model.joints)} joints), {s.payload_kg:g} kg at the gripper: {self.message}",
            f"  task: payload at {np.round(p.payload_point_m, 3).tolist()} m (±{s.target_tolerance_m:g} m)",
            f"  naive posture: limiting joint {nv.limiting_joint}, hold {format_s(nv.hold_limit_s)} from idle",
            f"  {p.method} posture: limiting joint {p.limiting_joint}, hold {format_s(p.hold_limit_s)} from idle "
            f"(x{self.gain:.2f})",
            f"  plan: hold {s.hold_s:g} s after a {s.move_s:g} s move; from arrival the hold can last "
            f"{format_s(self.time_to_limit_s)} (limited by {self.limiting_joint})",
            f"  binding: {', '.join(self.binding_constraints) or 'none'}"
            + ("" if self.feasible else f"; violated: {', '.join(self.violated_constraints) or 'none'}"),
            f"  solver {self.solver['name']}: {self.solver['iterations']} iterations, {self.solver['solve_s']:.2f} s, "
            f"dt {self.dt_s:.4g} s, N {self.us.shape[0]}",
            *["  " + r for r in rows]])


def _limit_text(limits_c: Mapping[str, float]) -> str:
    values = set(limits_c.values())
    return f"{values.pop():g} °C" if len(values) == 1 else "per joint"


def prepare(settings: WholeArmSettings, model: ActuatedArm | None = None):
    """Model, naive and chosen postures, task point and step: everything before the DDP."""
    s = settings
    model = model or load_model(s.joints, payload_kg=s.payload_kg, posture=dict(s.locked_posture))
    naive_q = naive_posture(model)
    target = np.asarray(s.target_m if s.target_m is not None else payload_point_function(model)(naive_q), float).ravel()
    naive = evaluate_posture(model, naive_q, s.limit_c, s.posture_hold_s, "naive")
    if s.posture_choice == "naive":
        chosen = naive
    else:
        chosen = optimal_posture(model, target, s.target_tolerance_m, s.limit_c, s.posture_hold_s, s.range_margin_rad,
                                 s.starts, s.seed)
    dt = s.dt_s or stable_dt_s(model, [hanging_posture(model, s.range_margin_rad), chosen.q_rad])
    return model, naive, chosen, target, dt


def plan_whole_arm(model: ActuatedArm | None = None, **options) -> WholeArmPlan:
    """Choose the holding posture, plan hanging -> posture -> hold by DDP, name the limiting joint.
    Options: the fields of :class:`WholeArmSettings`."""
    s = settings_from_mapping(WholeArmSettings, options, _SRC)
    model, naive, chosen, target, dt = prepare(s, model)
    hp = build_hold_problem(model, s, chosen.q_rad, target, dt)
    outcome, summary = solve_hold(hp, s)
    result, feasible = outcome.result, outcome.feasible
    arrival = result.xs[hp.hold_knot]
    ttl = time_to_limit_by_joint(model, model.static_current_a(chosen.q_rad), arrival[2 * model.nu:], hp.limits_c)
    binding, violated = tuple(binding_constraints(hp, result)), tuple(violated_constraints(hp, result))
    cause = None
    if outcome.verdict is None:
        status = "failed"
        message = f"no solve reached a verdict ({outcome.tried()}); nothing is known about this hold"
    elif feasible:
        status, message = "feasible", f"holds {s.hold_s:g} s under {_limit_text(hp.limits_c)}"
    else:
        status, cause = "infeasible_hold", cause_of(deciding_constraints(hp, result, violated=True))
        message = (f"cannot hold {s.hold_s:g} s under {_limit_text(hp.limits_c)}"
                   + (f"; {CAUSE_WORDS[cause]}" if cause else "") + f" (violated: {', '.join(violated) or 'none'})")
    log.info("whole arm %s: %s", model.joints, message)
    return WholeArmPlan(feasible, status, message, s, chosen, naive, hp.time_s, result.xs, result.us, dt, model,
                        summary, binding, violated, ttl, hp.limits_c, cause)
