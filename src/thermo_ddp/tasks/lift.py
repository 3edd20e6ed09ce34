"""``plan_lift()``: can the elbow lift and hold a payload, and for how long, under a winding limit?

The lift is a problem built on the general OCP layer (the solvers know nothing of it):
- state x = [q, v, T_nodes] of the elbow, control u = winding current, per-knot parameter
  p = [q_ref, sqrt(tracking weight), hold flag, ambient_c, direction, the request's numbers];
- costs by name: ``tracking`` (q to a smooth reference: lift, hold, lower), ``joule_energy``
  (R(T_w) i^2 dt, the heat put into the winding), ``velocity`` (small regulariser);
- constraints by name: ``winding_limit`` (T_w <= limit), ``bus_voltage`` (|R(T) i + K_b N v| <= V_bus at the knot's
  start and end, the current held),
  ``joint_range``, ``joint_velocity``, ``hold_band`` (|q - goal| <= tolerance while holding),
  ``return_band`` (back down at the end); the current box |i| <= peak;
- with ``careful_motion`` (on by default), the motion a careful operator would ask for: the cost
  ``acceleration`` (smooth phases: the joint acceleration of the model's ODE) and the constraints
  ``stop_approach`` (the speed near a joint stop shrinks with the distance to it), ``one_way`` (the lift moves
  only toward the goal, the hold is still, the lowering only toward the start: up, hold, down and no other
  reversal) and ``terminal_rest``;
- with ``acceleration_limit_rad_s2`` (off by default), the constraint ``acceleration_limit`` on the mean
  acceleration over each step (e.g. :func:`reference_acceleration_limit`).
When the requested hold is infeasible, the longest feasible hold is found by complete optimisations (each a
verdict of the solver), placed by a thermal prediction (:mod:`thermo_ddp.tasks.hold_search`), not guessed.
A solve without a verdict is retried (:mod:`thermo_ddp.tasks.attempts`); the plan is ``failed`` when no
retry reaches one (:mod:`thermo_ddp.tasks.lift_plan`).
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any, Mapping

import casadi as ca
import numpy as np

from .. import codegen
from .._config import require, settings_from_mapping
from .._memo import Memo
from ..model import motor
from ..model.actuated import ActuatedArm, check_integrator, load_model
from ..model.arm import ELBOW, PAYLOAD_KG
from ..model.parameters import Bound, load_parameters, packaged_parameter_file
from ..ocp import Constraint, Cost, KnotParameters, OptimalControlProblem, term_function
from ..solvers import DDPSettings, DDPSolver, FatropSolver, IpoptSolver, SolverResult, WarmStart
from .attempts import Outcome, SolverLadder
from .constraints import joint_limit_constraints, stop_approach
from .hold_search import longest_feasible_hold, predicted_hold_knots, predicted_peak_winding_c
from .lift_plan import LiftPlan, LimitComparison, joule_energy_j, stop_approach_time_s  # noqa: F401 (public here)
from .limits import (DEFAULT_HOLD_S, HOLD_S, MAX_LIMITS, check_fields, check_idle_below_limits, check_in_joint_range,
                     check_knots, check_limit_c, joint_limit_c, joint_range_rad, limit_pair_c, winding_limits_c)
from .problem import TaskProblem, initial_guess
from .thermal_hold import time_to_limit_by_joint
from .verdicts import binding_constraints, cause_of, deciding_constraints, is_feasible, solver_summary  # noqa: F401

log = logging.getLogger(__name__)

# Per-knot parameters of the lift, so one compiled solver serves every request (issue 15): the angle to track
# and its weight, 1 on the hold's knots, the room; ``direction``: the sign the velocity may take (the lift's,
# the lowering's), 0 while holding; then every number of the request (payload, limit, angles, weights, motion
# bounds), constant over the knots. Only the model's structure, the time step and the integrator are compiled.
# The cost weights enter as their square roots (``sqrt_<weight>``), the factor of a least-squares residual: so
# every derivative, also with respect to the parameters (IPOPT's), is finite at a zero weight (issue 23; the
# Joule residual sqrt(w) sqrt(R dt) i, as sqrt(w R dt) i, had 0/0 in d/dT at w = 0).
_REQUEST = ("payload_kg", "limit_c", "goal_rad", "start_rad", "hold_tolerance_rad", "velocity_limit_rad_s",
            "sqrt_energy_weight", "sqrt_velocity_weight", "sqrt_acceleration_weight", "acceleration_limit_rad_s2",
            "stop_speed_rad_s", "stop_slope_per_s", "one_way_tolerance_rad_s")
LIFT_PARAMETERS = KnotParameters((("q_ref_rad", 1), ("sqrt_tracking_weight", 1), ("hold_flag", 1), ("ambient_c", 1),
                                  ("direction", 1), *((name, 1) for name in _REQUEST)))

SOLVERS = {"ddp": DDPSolver, "ipopt": IpoptSolver, "fatrop": FatropSolver}
# Full DDP: the winding limit's R(T) i^2 curvature lives in the dynamics, which Gauss-Newton
# iLQR ignores (it then needs ~4x more iterations on this problem).
# DDP on the lift: full second order (the R(T) i^2 curvature is in the dynamics) and a schedule tuned on
# the lift (benchmarks/README.md): a looser first inner tolerance (0.1, x0.3 per loop, 20 inner iterations
# at most), a slower regularisation decrease and the pivot jump cut the infeasible probe of the
# longest-hold search from 146 to 95 iterations.
# The active margin and the nonmonotone line search (3 iterates) took the default searches from 2.3-3.3 to
# 1.4-1.5 forward passes per iteration, with no failed line search (benchmarks/README.md, issue 23); the retry
# with the rows a line search crossed 220 -> 156 forward passes at 140 °C (passes7).
# The knots compiled with codegen.REASSOCIATING_FLAGS: passes ~25 % faster, the same iterates to rounding.
DDP_OPTIONS = DDPSettings(full_second_order=True, inner_tolerance_init=0.1, inner_tolerance_factor=0.3,
                          inner_max_iterations=20, reg_decrease=10.0 ** 0.5, pivot_jump=True, active_margin=1e-4,
                          nonmonotone_memory=3, retry_crossed_rows=True,
                          compiler_flags=(*DDPSettings().compiler_flags, *codegen.REASSOCIATING_FLAGS))
# Careful motion off, no margin: with it the 40 kg 84 °C search took 7 solves, 964 iterations and an IPOPT rung,
# without 4 solves and 291 iterations, the same hold (benchmarks/README.md, issue 23).
DDP_OPTIONS_CAREFUL_OFF = dataclasses.replace(DDP_OPTIONS, active_margin=0.0)
DEFAULT_OPTIONS = {"ddp": DDP_OPTIONS}
_SRC = "plan_lift"
_PHASE_S = Bound(1e-3, 600.0, "s", "a lift or lowering phase: seconds, not hours")
_WEIGHT = Bound(0.0, 1e9, "", "a cost weight")
# Every number of LiftSettings and its range (the joint range of the angles is checked on the model).
SETTING_BOUNDS = {
    "payload_kg": PAYLOAD_KG, "hold_s": HOLD_S, "lift_s": _PHASE_S, "lower_s": _PHASE_S,
    "settle_s": Bound(0.0, 600.0, "s", "a rest at the end: seconds, not hours"),
    "dt_s": Bound(1e-3, 0.5, "s", "the control step; RK4 sub-steps must resolve the arm's fast modes"),
    "goal_rad": Bound(-2 * math.pi, 2 * math.pi, "rad", "a joint angle"),
    "start_rad": Bound(-2 * math.pi, 2 * math.pi, "rad", "a joint angle"),
    "hold_tolerance_rad": Bound(1e-6, 0.5, "rad", "a band around the goal"),
    "tracking_weight": Bound(1e-9, 1e9, "", "a cost weight, > 0: the lift must track its reference"),
    "energy_weight": _WEIGHT, "velocity_weight": _WEIGHT, "acceleration_weight": _WEIGHT,
    "stop_speed_rad_s": Bound(1e-3, 100.0, "rad/s", "the speed allowed at a joint stop, > 0"),
    "stop_slope_per_s": Bound(0.0, 1e3, "1/s", "how fast the speed allowed grows away from a stop"),
    "one_way_tolerance_rad_s": Bound(1e-6, 1.0, "rad/s", "a speed small enough to count as still"),
}
_ACCELERATION_LIMIT = Bound(0.1, 1e3, "rad/s²", "a joint acceleration bound, > 0 (None: no bound)")
_VELOCITY_LIMIT = Bound(1e-3, 100.0, "rad/s", "a joint speed limit, > 0 (None: the URDF's)")


@dataclasses.dataclass(frozen=True)
class LiftSettings:
    """The lift scenario and its transcription (all times in s, angles in rad).

    ``limit_c``: the winding limit (None: the elbow parameter file's, see
    :func:`thermo_ddp.tasks.limits.default_limit_c`; :func:`build_lift_problem` fills it in)."""

    payload_kg: float = 40.0
    limit_c: float | None = None
    hold_s: float = DEFAULT_HOLD_S
    goal_rad: float = -math.pi / 2      # forearm horizontal
    start_rad: float = -0.05            # forearm hanging, just off the elbow's stop at 0 rad
    lift_s: float = 2.0
    lower_s: float = 2.0
    settle_s: float = 0.5
    dt_s: float = 0.1
    integrator: str = "rk4_4"           # RK4, 4 sub-steps of 25 ms: stable for any payload at dt = 0.1 s
    hold_tolerance_rad: float = 0.02
    velocity_limit_rad_s: float | None = None   # default: the URDF's limit
    tracking_weight: float = 100.0
    energy_weight: float = 1e-2
    velocity_weight: float = 1e-2
    careful_motion: bool = True         # the acceleration cost and the stop_approach, one_way, terminal_rest
                                        # constraints (issue 15)
    acceleration_weight: float = 0.1    # per (rad/s^2)^2 s: smooth phases; measured against 1e-3 on the 40 kg
                                        # longest-hold searches: 28 % (84 °C) and 35 % (140 °C) fewer DDP
                                        # backward passes, the same holds (benchmarks/README.md)
    acceleration_limit_rad_s2: float | None = None  # bound on |mean acceleration over a step| (None: none).
    # Off by default: with reference_acceleration_limit's 4.4 rad/s² the 40 kg searches take DDP 2.1 s instead
    # of 0.8-1.1 s and the fixed-horizon solves up to 5x longer (benchmarks/README.md, issue 15)
    stop_speed_rad_s: float = 0.1       # the speed toward a joint stop allowed at the stop,
    stop_slope_per_s: float = 2.0       #   growing by this per rad of distance from it
    one_way_tolerance_rad_s: float = 0.01   # the speed against a phase's direction allowed (and at the end)
    solver: str = "ddp"
    parameter_file: str | None = None
    find_longest_hold: bool = True

    def __post_init__(self):
        check_fields(self, _SRC, SETTING_BOUNDS)
        object.__setattr__(self, "limit_c", check_limit_c(_SRC, self.limit_c))
        optional = {"velocity_limit_rad_s": _VELOCITY_LIMIT, "acceleration_limit_rad_s2": _ACCELERATION_LIMIT}
        for name, bound in optional.items():
            if getattr(self, name) is not None:
                check_fields(self, _SRC, {name: bound})
        check_knots(_SRC, sum(self.knots().values()), self.dt_s)
        require(isinstance(self.careful_motion, bool), _SRC, "careful_motion", self.careful_motion,
                "expected True or False")
        require(self.solver in SOLVERS, _SRC, "solver", self.solver, f"choose one of {', '.join(SOLVERS)}")
        check_integrator(_SRC, self.integrator)

    def knots(self) -> dict[str, int]:
        return {name: int(round(dur / self.dt_s)) for name, dur in
                (("lift", self.lift_s), ("hold", self.hold_s), ("lower", self.lower_s), ("settle", self.settle_s))}


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile from 0 to 1 over s in [0, 1]."""
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


MIN_JERK_PEAK_ACCELERATION = 10 / math.sqrt(3)  # max of min_jerk'' on [0, 1] (at s = 1/2 - sqrt(3)/6)


def reference_acceleration_limit(settings: LiftSettings) -> float:
    """A bound for ``acceleration_limit_rad_s2``: twice the peak acceleration of the minimum-jerk reference
    over the shorter of the lift and the lowering (room to catch up with the reference, not a bang-bang at
    the current limit; 4.4 rad/s² for the default lift)."""
    distance = abs(settings.goal_rad - settings.start_rad)
    return 2 * MIN_JERK_PEAK_ACCELERATION * distance / min(settings.lift_s, settings.lower_s) ** 2


@dataclasses.dataclass(frozen=True)
class LiftProblem(TaskProblem):
    """The transcribed lift: the general OCP plus its data (x0, per-knot parameters, time grid).

    The horizon is fixed by ``settings.hold_s``; :meth:`with_hold` gives a shorter hold inside the
    same horizon (new parameters only), so one built solver serves every hold duration.
    ``settings.limit_c`` is the limit in use (the parameter file's when none was asked for).
    """

    settings: LiftSettings
    hold_knots: tuple[int, int]

    def with_hold(self, hold_s: float) -> "LiftProblem":
        params, hold = _reference(self.settings, hold_s, self.model.ambient_c)
        return dataclasses.replace(self, params=params, hold_knots=hold)

    @property
    def hold_s(self) -> float:
        return (self.hold_knots[1] - self.hold_knots[0]) * self.settings.dt_s


def _reference(settings: LiftSettings, hold_s: float, ambient_c: float) -> tuple[np.ndarray, tuple[int, int]]:
    """Per-knot parameters (:data:`LIFT_PARAMETERS`) for a hold of ``hold_s`` inside the horizon of
    ``settings.hold_s``: lift, hold, lower, then rest at the start until the end."""
    k = settings.knots()
    hold = int(round(hold_s / settings.dt_s))
    s0, g = settings.start_rad, settings.goal_rad
    up = s0 + (g - s0) * min_jerk(np.arange(1, k["lift"] + 1) / k["lift"])
    down = g + (s0 - g) * min_jerk(np.arange(1, k["lower"] + 1) / k["lower"])
    rest = k["settle"] + k["hold"] - hold
    q_ref = np.concatenate([[s0], up, np.full(hold, g), down, np.full(rest, s0)])
    flag = np.zeros(q_ref.size)
    first = k["lift"]
    flag[first:first + hold + 1] = 1.0  # the goal is reached at the end of the lift, held to its end
    direction = np.zeros(q_ref.size)
    direction[:first] = np.sign(g - s0)               # lifting: toward the goal only
    direction[first + hold + 1:] = np.sign(s0 - g)    # lowering and resting: toward the start only
    request = {name: math.sqrt(getattr(settings, name[5:])) if name.startswith("sqrt_") else getattr(settings, name)
               for name in _REQUEST}
    if request["acceleration_limit_rad_s2"] is None:
        request["acceleration_limit_rad_s2"] = 0.0  # no bound: no function reads it
    p = LIFT_PARAMETERS.values(q_ref.size, q_ref_rad=q_ref, sqrt_tracking_weight=math.sqrt(settings.tracking_weight),
                               hold_flag=flag, ambient_c=ambient_c, direction=direction, **request)
    return p, (first, first + hold)


def _functions(model: ActuatedArm, settings: LiftSettings):
    """The lift's dynamics, costs and constraints. Every number of the request is read from the per-knot
    parameters (:data:`LIFT_PARAMETERS`), so these functions depend only on the model's structure, the time
    step, the integrator and ``careful_motion``: their compiled code serves every payload, limit and hold."""
    joint = model.joints[0]
    m = model.params[joint].motor
    x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("p", LIFT_PARAMETERS.size)
    par = LIFT_PARAMETERS.symbols(p)
    q, v = x[model.index(joint, "q_rad")], x[model.index(joint, "v_rad_s")]
    winding = x[model.index(joint, "winding_c")]
    env = ca.vertcat(par["ambient_c"], par["payload_kg"])
    step = model.step_function(settings.dt_s, settings.integrator, runtime_payload=True)
    dyn = ca.Function("lift_dynamics", [x, u, p], [step(x, u, env)], ["x", "u", "p"], ["x_next"])
    jac = model.step_jacobians(settings.dt_s, settings.integrator, runtime_payload=True)
    dyn_jac = ca.Function("lift_dynamics_jacobians", [x, u, p], list(jac(x, u, env)), ["x", "u", "p"],
                          ["x_next", "A", "B"])
    tol, goal, start = par["hold_tolerance_rad"], par["goal_rad"], par["start_rad"]
    xn = ca.SX.sym("x_next", model.nx)  # the knot's end state (a term that reads it: ocp.term_function)

    def stage(name, expr, out="r"):
        return term_function(name, expr, out, x, p, u, xn)

    def terminal(name, expr, out="r"):
        return term_function(name, expr, out, x, p)

    joule = motor.resistance_ohm(m, winding) * settings.dt_s
    costs = (
        Cost("tracking", 1.0, stage("tracking", par["sqrt_tracking_weight"] * (q - par["q_ref_rad"]))),
        Cost("joule_energy", 1.0, stage("joule_energy", par["sqrt_energy_weight"] * ca.sqrt(joule) * u[0])),
        Cost("velocity", 1.0, stage("velocity", par["sqrt_velocity_weight"] * v)),
    )
    terminal_costs = (
        Cost("terminal_tracking", 1.0, terminal("terminal_tracking", par["sqrt_tracking_weight"] * (q - start))),
        Cost("terminal_velocity", 1.0, terminal("terminal_velocity", v)))
    limits = joint_limit_constraints(model, joint, x, u[0], par["limit_c"], par["velocity_limit_rad_s"], x_next=xn)
    constraints = tuple(Constraint(kind, stage(kind, g, "g")) for kind, g in limits.items()) + (
        Constraint("hold_band", stage("hold_band", ca.vertcat(par["hold_flag"] * (q - goal) - tol,
                                                             par["hold_flag"] * (goal - q) - tol), "g")),
    )
    terminal_constraints = (
        Constraint("terminal_winding_limit", terminal("terminal_winding_limit", limits["winding_limit"], "g")),
        Constraint("return_band", terminal("return_band", ca.vertcat(q - start - tol, start - q - tol), "g")),
    )
    if settings.careful_motion:
        still = par["one_way_tolerance_rad_s"]
        acceleration = model.runtime_payload_functions[0](x, u, env)[model.index(joint, "v_rad_s")]
        costs += (Cost("acceleration", 1.0, stage("acceleration", par["sqrt_acceleration_weight"]
                                                   * math.sqrt(settings.dt_s) * acceleration)),)
        constraints += (
            Constraint("stop_approach", stage("stop_approach", stop_approach(
                model, joint, x, par["stop_speed_rad_s"], par["stop_slope_per_s"]), "g")),
            Constraint("one_way", stage("one_way", ca.vertcat(-par["direction"] * v - still, par["hold_flag"] * v - still,
                                                              -par["hold_flag"] * v - still), "g")))
        terminal_constraints += (Constraint("terminal_rest", terminal("terminal_rest", ca.vertcat(v - still, -v - still),
                                                                      "g")),)
    if settings.acceleration_limit_rad_s2 is not None:
        amax = par["acceleration_limit_rad_s2"]
        mean = (xn[model.index(joint, "v_rad_s")] - v) / settings.dt_s  # what a plot of v shows
        constraints += (Constraint("acceleration_limit", stage("acceleration_limit",
                                                               ca.vertcat(mean - amax, -mean - amax), "g")),)
    return dyn, dyn_jac, costs, terminal_costs, constraints, terminal_constraints, m.current_peak_a


def lift_terms(model: ActuatedArm, settings: LiftSettings):
    """The lift's costs, terminal costs, constraints, terminal constraints (functions of one model's x, u, p)
    and its current peak: what the robust lift (:mod:`thermo_ddp.tasks.robust`) imposes per scenario."""
    return _functions(model, settings)[2:]


_PROBLEMS = Memo()  # the lift's OCP by what its functions are built from (the horizon aside)


def _structure(model: ActuatedArm, settings: LiftSettings) -> OptimalControlProblem:
    """The lift's OCP for the model's structure, the step, the integrator, ``careful_motion`` and whether the
    acceleration is bounded (built once in a process, with its :attr:`OptimalControlProblem.functions`); its
    horizon is set by the caller."""
    def build():
        dyn, dyn_jac, costs, tcosts, cons, tcons, peak = _functions(model, settings)
        problem = OptimalControlProblem(dyn, 1, costs, tcosts, cons, tcons, u_lb=[-peak], u_ub=[peak], name="lift",
                                        dynamics_jacobians=dyn_jac, parameters=LIFT_PARAMETERS)
        problem.functions  # built here, shared by every horizon
        return problem

    key = (model.structure_key, settings.dt_s, settings.integrator, settings.careful_motion,
           settings.acceleration_limit_rad_s2 is not None)
    return _PROBLEMS.get(key, build)


def build_lift_problem(settings: LiftSettings, model: ActuatedArm | None = None) -> LiftProblem:
    files = {ELBOW: settings.parameter_file} if settings.parameter_file else None
    model = model or load_model((ELBOW,), payload_kg=settings.payload_kg, parameter_files=files)
    require(model.arm.settings.payload_kg == settings.payload_kg, _SRC, "payload_kg", settings.payload_kg,
            f"the model given carries {model.arm.settings.payload_kg:g} kg")
    limits = winding_limits_c(model, settings.limit_c)
    check_idle_below_limits(model, limits)
    vmax = settings.velocity_limit_rad_s or float(model.arm.model.velocityLimit[0])  # default: the URDF's
    settings = dataclasses.replace(settings, limit_c=limits[model.joints[0]], velocity_limit_rad_s=vmax)
    for name in ("start_rad", "goal_rad"):
        check_in_joint_range(model, _SRC, name, model.joints[0], getattr(settings, name))
    params, hold = _reference(settings, settings.hold_s, model.ambient_c)
    problem = _structure(model, settings).with_horizon(params.shape[0] - 1)
    x0 = model.state(q=[settings.start_rad])
    return LiftProblem(model=model, problem=problem, x0=x0, params=params,
                       time_s=np.arange(params.shape[0]) * settings.dt_s, box_names=("current_peak",),
                       settings=settings, hold_knots=hold)


def make_solver(lp: LiftProblem, solver: str | None = None, options: Mapping[str, Any] | None = None):
    """A solver instance for the lift's OCP (built once, reusable for every hold and warm start)."""
    name = solver or lp.settings.solver
    if options is None:
        careful_off = name == "ddp" and not lp.settings.careful_motion
        options = DDP_OPTIONS_CAREFUL_OFF if careful_off else DEFAULT_OPTIONS.get(name)
    return SOLVERS[name](lp.problem, options)


def solve(lp: LiftProblem, solver=None, warm_start: WarmStart | None = None) -> SolverResult:
    """Solve the lift with a solver instance (or the name of one, built here)."""
    instance = solver if hasattr(solver, "solve") else make_solver(lp, solver)
    return instance.solve(lp.x0, lp.params, warm_start or initial_guess(lp))


def time_to_limit_s(model: ActuatedArm, x_start: np.ndarray, q_goal: float, limit_c: float,
                    horizon_s: float = 3600.0, dt_s: float = 0.5) -> float:
    """Time for the (one) joint's winding to reach ``limit_c`` holding still at ``q_goal`` from the
    temperatures of ``x_start`` (inf: not within ``horizon_s``)."""
    joint = model.joints[0]
    temperatures = np.asarray(x_start, dtype=float)[2 * model.nu:]
    # the first minute first: a plan's own boundary is usually seconds away (3600 s cost 25-50 ms a plan)
    for horizon in sorted({min(60.0, horizon_s), horizon_s}):
        ttl = time_to_limit_by_joint(model, model.static_current_a([q_goal]), temperatures, {joint: limit_c},
                                     horizon, dt_s)[joint]
        if math.isfinite(ttl):
            return ttl
    return ttl


def plan_lift(payload_kg: float | None = None, limit_c: float | None = None, hold_s: float | None = None, *,
              settings: LiftSettings | None = None, uncertainty=None, **options) -> LiftPlan:
    """Plan lifting ``payload_kg`` at the gripper (default 40 kg) to horizontal, holding ``hold_s`` (default
    :data:`DEFAULT_HOLD_S`), lowering back, with the winding kept under ``limit_c`` (None: the elbow
    parameter file's limit). Give either a :class:`LiftSettings` (``settings=``) or its fields as keywords.
    ``uncertainty``: a fraction (every thermal value within +-fraction), ``"file"`` (the parameter file's
    ``[uncertainty]``) or a :class:`thermo_ddp.tasks.robust.Uncertainty`: the plan then keeps every motor of
    that set under the limit (:func:`thermo_ddp.tasks.robust.plan_robust_lift`).

    A solve that reaches no verdict is retried (:class:`SolverLadder`); when none does, the plan is
    ``failed``, never infeasible."""
    settings = _lift_settings(payload_kg, limit_c, hold_s, settings, options)
    if uncertainty is not None:
        from .robust import plan_robust_lift
        return plan_robust_lift(settings, uncertainty)
    lp = build_lift_problem(settings)
    settings = lp.settings  # the limit and speed bound filled in
    ladder = SolverLadder(lp.problem, make_solver(lp))

    def solve_probe(probe: LiftProblem, warm: WarmStart | None) -> Outcome:
        return ladder.solve(probe, warm or initial_guess(probe))

    if settings.find_longest_hold:
        # first probe: the time to the limit holding at the goal from the start's temperatures (the lift's
        # own heat aside, so a little long: the infeasible plan it gives predicts the boundary well)
        estimate = time_to_limit_s(lp.model, lp.x0, settings.goal_rad, settings.limit_c,
                                   horizon_s=settings.hold_s + settings.dt_s)
        search = longest_feasible_hold(lp, solve_probe, int(min(estimate, settings.hold_s) / settings.dt_s))
        (lp_best, outcome), knots, results = search.best, search.knots, search.results
        probes = len(search.probes)
    else:
        lp_best = lp
        outcome = solve_probe(lp, None)
        knots, results, probes = (lp.hold_knots[1] - lp.hold_knots[0]) if outcome.feasible else -1, outcome.results, 1
    return _plan(lp, lp_best, outcome, knots, results, probes)


def _lift_settings(payload_kg, limit_c, hold_s, settings: LiftSettings | None, options: Mapping) -> LiftSettings:
    """The request as :class:`LiftSettings`: ``settings`` itself, or the keywords (not both)."""
    given = {k: v for k, v in (("payload_kg", payload_kg), ("limit_c", limit_c), ("hold_s", hold_s)) if v is not None}
    if settings is not None:
        require(isinstance(settings, LiftSettings), _SRC, "settings", type(settings).__name__,
                "expected a LiftSettings")
        require(not given and not options, _SRC, "settings", "LiftSettings(...)",
                f"give settings or keyword options, not both (also given: {', '.join([*given, *options])})")
        return settings
    return settings_from_mapping(LiftSettings, {**given, **options}, _SRC)


def _plan(lp: LiftProblem, best: LiftProblem, outcome: Outcome, knots: int, results, probes: int) -> LiftPlan:
    """The plan of the decisive probe: status, sentence, cause and remedy (see :mod:`.lift_plan`)."""
    s, result = lp.settings, outcome.result
    top = lp.hold_knots[1] - lp.hold_knots[0]
    if outcome.verdict is None:
        status, cause, remedy = "failed", None, ""
        message = f"no solve reached a verdict ({outcome.tried()}); nothing is known about this lift"
    else:
        status = ("feasible" if knots == top else "infeasible" if knots < 0 or not s.find_longest_hold
                  else "infeasible_hold")
        cause, remedy = (None, "") if status == "feasible" else _cause(lp, best, outcome)
        message = ""
    achieved = s.hold_s if status == "feasible" else max(knots, 0) * s.dt_s
    ttl = time_to_limit_s(lp.model, result.xs[best.hold_knots[0]], s.goal_rad, s.limit_c)
    summary = solver_summary(result, sum(r.solve_s for r in results), len(results), results, name=s.solver,
                             probes=probes, attempts=[name for name, _ in outcome.attempts])
    plan = LiftPlan(status == "feasible", status, message, s, float(achieved), lp.time_s, result.xs, result.us,
                    lp.model, summary, tuple(binding_constraints(best, result)), ttl, cause, remedy)
    return dataclasses.replace(plan, message=plan.headline() + (f"; {remedy}" if remedy else ""))


def _cause(lp: LiftProblem, best: LiftProblem, outcome: Outcome) -> tuple[str | None, str]:
    """The cause class of a verdict short of the request and the number a user can change."""
    names = deciding_constraints(best, outcome.result, violated=not outcome.feasible)
    s, held = lp.settings, best.hold_knots[1] - best.hold_knots[0]
    # the heat decides a hold cut short; a lift that fails outright only when the replayed heat exceeds the limit
    heat = outcome.feasible or predicted_hold_knots(lp, (best, outcome.result)) < held
    cause = cause_of(names, heat)
    if cause == "thermal":
        need = predicted_peak_winding_c(lp, (best, outcome.result), lp.hold_knots[1] - lp.hold_knots[0])
        return cause, f"the {s.hold_s:g} s hold needs limit_c >= {math.ceil(need * 10) / 10:.1f} °C"
    if cause == "motion":
        lo, hi = (float(b[0]) for b in joint_range_rad(lp.model))
        need = stop_approach_time_s(lo, hi, s.start_rad, s.goal_rad, s.stop_speed_rad_s, s.stop_slope_per_s,
                                    s.velocity_limit_rad_s)
        knots = math.ceil(need / s.dt_s - 1e-9)
        short = [name for name in ("lift_s", "lower_s") if getattr(s, name) < knots * s.dt_s - 1e-9]
        return cause, (f"{names[0]} binds: {' and '.join(short or ['lift_s'])} >= {knots * s.dt_s:.2f} s "
                       f"({knots} steps; the speed allowed near the stops alone takes {need:.2f} s), "
                       "or careful_motion off")
    if cause == "actuator":
        peak = lp.model.params[lp.model.joints[0]].motor.current_peak_a
        hold = float(np.abs(lp.model.static_current_a([s.goal_rad])).max())
        return cause, (f"{names[0]} binds: holding {s.payload_kg:g} kg at the goal takes {hold:.1f} A of the "
                       f"{peak:g} A peak; a lighter payload or longer lift_s")
    if cause == "range":
        return cause, f"{names[0]} binds: keep goal_rad and start_rad inside the joint range with hold_tolerance_rad"
    return None, ""


def compare_limits(payload_kg: float = 40.0, limits_c=None, hold_s: float = DEFAULT_HOLD_S,
                   **options) -> LimitComparison:
    """:func:`plan_lift` under each winding limit; by default the elbow file's cut-off and short-term
    winding limit (:func:`thermo_ddp.tasks.limits.limit_pair_c`: 84 °C and 140 °C)."""
    params = load_parameters(options.get("parameter_file") or packaged_parameter_file(ELBOW))
    limits_c = limit_pair_c(params) if limits_c is None else tuple(limits_c)
    require(0 < len(limits_c) <= MAX_LIMITS, _SRC, "limits_c", limits_c,
            f"give 1 to {MAX_LIMITS} winding limits (each is a complete plan)")
    for lim in limits_c:  # every limit checked before the first plan
        joint_limit_c(params, check_limit_c(_SRC, lim))
    return LimitComparison(tuple(plan_lift(payload_kg, lim, hold_s, **options) for lim in limits_c))
