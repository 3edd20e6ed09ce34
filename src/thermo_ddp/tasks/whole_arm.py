"""The whole arm: several joints, each with its own motor, thermal network and winding limit.

Three parts, all on the composed model of :mod:`thermo_ddp.model.actuated` (joints chosen by name):

1. **Posture** (:func:`optimal_posture`): hold ``payload_kg`` at a task point with the posture whose
   hottest winding stays coolest. A small NLP (IPOPT) over the joint angles q and an epigraph
   variable t::

       min t   s.t.  T_w,j(q; H) <= t            for every joint j
                     |p(q) - p_target| <= tol     (payload point, per axis, base frame)
                     q_lo + margin <= q <= q_hi - margin

   where T_w,j(q; H) is joint j's winding temperature after holding q for H s from the idle state
   (its thermal network driven by the static current i_j = g_j(q) / (N K_m), RK4), and p(q) the
   payload point. The default task point is where the *naive* posture (every joint at 0, forearm
   horizontal by the elbow alone) holds the payload: the same point in space, reached by another
   posture.
2. **Plan** (:func:`plan_whole_arm`): DDP from the hanging posture to the chosen posture and the
   hold, with per-joint constraints by name (``winding_limit_<joint>``, ``bus_voltage_<joint>``,
   ``joint_range_<joint>``, ``joint_velocity_<joint>``; the current box is each joint's peak) and
   the task-space ``hold_band``. The result names the joint that limits the hold and how long
   the hold can last (simulated from the plan's state on arrival).
3. **Monitor** (:func:`monitor_bag`): per joint, an open-loop simulation of its thermal network
   driven by the recorded current and velocity, initialised from the casing reading; reports each
   joint's winding estimate, the hottest joint and the time to the limit. A joint without a
   current signal (or without a parameter file) is reported as not estimable, never guessed.

Stiffness: the tanh-smoothed Coulomb friction (slope F_c / smoothing at v = 0) over the small
inertias of the upper-arm rotation and wrist joints gives eigenvalues up to ~110 /s (7 joints);
classic RK4 is stable for |lambda| dt < 2.78, so the control step is chosen from the model's
spectrum (:func:`stable_dt_s`) unless given.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np
from tqdm.auto import tqdm

from ..model import motor
from .._config import require, settings_from_mapping
from ..model.actuated import ActuatedArm, load_model
from ..model.arm import ELBOW, LEFT_ARM
from ..model.integrators import rk4
from .lift import min_jerk
from ..ocp import Constraint, Cost, OptimalControlProblem
from ..model.parameters import JointParameters, load_parameters, packaged_parameter_file
from ..recordings import Recording, TopicMap, read_bag_joints
from ..model.rigid_body import RigidBodyDynamics
from ..solvers import DDPSettings, DDPSolver, SolverResult, WarmStart
from ..model.thermal import network_from_parameters

log = logging.getLogger(__name__)
_SRC = "plan_whole_arm"
RK4_STABLE = 2.0          # |lambda| dt kept below this (RK4's real-axis limit is 2.785)
HOLD_DT_S = 2.0           # thermal-only RK4 step of the posture objective (winding tau >= 30 s)
FEASIBLE_TOL = 1e-4


# --------------------------------------------------------------------------------------------
# Settings
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class WholeArmSettings:
    """The whole-arm hold task and its transcription (times in s, angles in rad, lengths in m).

    ``joints``: planned joints by name (shoulder to wrist); the others are locked at
    ``locked_posture`` (default 0 rad). ``target_m``: payload point in the base frame of the
    reduced model (default: where the naive posture holds it). ``posture_hold_s``: H of the posture
    objective. ``posture_choice``: ``"optimal"`` (the NLP) or ``"naive"`` (elbow at -pi/2, the rest
    at 0). ``dt_s``: control step (None: the largest stable RK4 step, see :func:`stable_dt_s`).
    """

    joints: tuple[str, ...] = LEFT_ARM[:4]
    payload_kg: float = 40.0
    limit_c: float = 84.0
    hold_s: float = 10.0
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
        require(self.payload_kg >= 0, _SRC, "payload_kg", self.payload_kg, "must be >= 0")
        require(-50 < self.limit_c < 250, _SRC, "limit_c", self.limit_c, "expected a winding limit in °C")
        for name in ("hold_s", "move_s", "posture_hold_s", "target_tolerance_m", "tracking_weight"):
            require(getattr(self, name) > 0, _SRC, name, getattr(self, name), "must be > 0")
        for name in ("range_margin_rad", "energy_weight", "velocity_weight"):
            require(getattr(self, name) >= 0, _SRC, name, getattr(self, name), "must be >= 0")
        require(self.posture_choice in ("optimal", "naive"), _SRC, "posture_choice", self.posture_choice,
                "choose optimal or naive")
        require(self.dt_s is None or self.dt_s > 0, _SRC, "dt_s", self.dt_s, "must be > 0 (or None: automatic)")
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


# --------------------------------------------------------------------------------------------
# Named CasADi functions of the model (kinematics, statics, thermal-only steps)
# --------------------------------------------------------------------------------------------
def payload_point_function(model: ActuatedArm) -> ca.Function:
    """``payload_point(q_rad) -> point_m``: the payload's centre in the reduced model's base frame."""
    pm = model.arm.model
    q = ca.SX.sym("q_rad", pm.nq)
    rot, pos = RigidBodyDynamics(pm).placements(q)
    frame = pm.frames[pm.getFrameId(model.arm.payload_frame)]
    local = frame.placement.act(model.arm.payload_translation_m)
    point = pos[frame.parentJoint] + rot[frame.parentJoint] @ ca.DM(local)
    return ca.Function("payload_point", [q], [point], ["q_rad"], ["point_m"])


def gravity_torque_function(model: ActuatedArm) -> ca.Function:
    """``gravity_torque(q_rad) -> torque_nm``: g(q) by the CasADi RNEA (payload included)."""
    pm = model.arm.model
    q = ca.SX.sym("q_rad", pm.nv)
    zero = ca.SX.zeros(pm.nv)
    return ca.Function("gravity_torque", [q], [RigidBodyDynamics(pm).rnea(q, zero, zero)], ["q_rad"], ["torque_nm"])


def static_current_function(model: ActuatedArm) -> ca.Function:
    """``static_current(q_rad) -> current_a``: each joint's current holding q at rest."""
    q = ca.SX.sym("q_rad", model.nu)
    g = gravity_torque_function(model)(q)
    i = [motor.current_for_torque_a(model.params[j].motor, g[k]) for k, j in enumerate(model.joints)]
    return ca.Function("static_current", [q], [ca.vertcat(*i)], ["q_rad"], ["current_a"])


def thermal_rhs_function(model: ActuatedArm) -> ca.Function:
    """``thermal_rhs(temperatures_c, current_a, velocity_rad_s, ambient_c) -> dtemperatures_c_dt`` of
    every joint's network (temperatures stacked as in the model state after q and v)."""
    sizes = [len(model.networks[j].nodes) for j in model.joints]
    temps = ca.SX.sym("temperatures_c", sum(sizes))
    i, v, amb = ca.SX.sym("current_a", model.nu), ca.SX.sym("velocity_rad_s", model.nu), ca.SX.sym("ambient_c")
    offsets, out = np.cumsum([0] + sizes), []
    for k, j in enumerate(model.joints):
        net, m = model.networks[j], model.params[j].motor
        t = temps[offsets[k]:offsets[k + 1]]
        out.append(net.rhs(t, motor.losses_w(m, i[k], v[k], t[net.index(net.limit_node)]), amb))
    return ca.Function("thermal_rhs", [temps, i, v, amb], [ca.vertcat(*out)],
                       ["temperatures_c", "current_a", "velocity_rad_s", "ambient_c"], ["dtemperatures_c_dt"])


def thermal_step_function(rhs: ca.Function, dt_s: float) -> ca.Function:
    """``thermal_step(temperatures_c, current_a, velocity_rad_s, ambient_c) -> temperatures_next_c`` (RK4)."""
    args = [ca.SX.sym(rhs.name_in(k), rhs.size1_in(k)) for k in range(4)]
    return ca.Function("thermal_step", args, [rk4(rhs, args[0], dt_s, *args[1:])], rhs.name_in(),
                       ["temperatures_next_c"])


def winding_indices(model: ActuatedArm) -> list[int]:
    """Index of each joint's winding node in the stacked temperatures (x[2n:])."""
    return [model.index(j, "winding_c") - 2 * model.nu for j in model.joints]


def stable_dt_s(model: ActuatedArm, postures: Sequence[np.ndarray], dt_max_s: float = 0.1) -> float:
    """Largest dt = dt_max / k (k integer) with |lambda| dt <= RK4_STABLE at rest in ``postures``."""
    lam = 0.0
    for q in postures:
        x = model.state(q=q)
        a = np.array(model.ode_jacobians(x, model.static_current_a(q), model.ambient_c)[1])
        lam = max(lam, float(np.abs(np.linalg.eigvals(a)).max()))
    return dt_max_s / max(1, math.ceil(lam * dt_max_s / RK4_STABLE))


# --------------------------------------------------------------------------------------------
# Static holding: temperatures, time to limit, posture choice
# --------------------------------------------------------------------------------------------
def hold_temperatures(model: ActuatedArm, current_a, temperatures_c, duration_s: float,
                      dt_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Thermal-only simulation of holding still with constant ``current_a``: (time_s, temperatures)."""
    steps = max(1, int(math.ceil(duration_s / dt_s)))
    f = thermal_step_function(thermal_rhs_function(model), dt_s).mapaccum(steps)
    temps = np.array(f(np.asarray(temperatures_c, float), np.asarray(current_a, float), np.zeros(model.nu),
                       model.ambient_c)).T
    return np.arange(steps + 1) * dt_s, np.vstack([np.asarray(temperatures_c, float), temps])


def _first_crossing(time_s: np.ndarray, values: np.ndarray, level: float) -> float:
    hit = np.flatnonzero(values >= level)
    if hit.size == 0:
        return math.inf
    k = hit[0]
    return 0.0 if k == 0 else float(np.interp(level, values[k - 1:k + 1], time_s[k - 1:k + 1]))


def time_to_limit_by_joint(model: ActuatedArm, current_a, temperatures_c, limit_c: float,
                           horizon_s: float = 3600.0, dt_s: float = 0.5) -> dict[str, float]:
    """Per joint: time until its winding reaches ``limit_c`` holding ``current_a`` (inf: not within horizon)."""
    time_s, temps = hold_temperatures(model, current_a, temperatures_c, horizon_s, dt_s)
    w = temps[:, winding_indices(model)]
    return {j: _first_crossing(time_s, w[:, k], limit_c) for k, j in enumerate(model.joints)}


@dataclasses.dataclass(frozen=True)
class PostureChoice:
    """A holding posture and what it costs each joint (static: v = 0, gravity only)."""

    method: str
    joints: tuple[str, ...]
    q_rad: np.ndarray
    payload_point_m: np.ndarray
    torque_nm: np.ndarray
    current_a: np.ndarray
    winding_after_hold_c: np.ndarray
    posture_hold_s: float
    time_to_limit_s: Mapping[str, float]
    success: bool = True
    status: str = "evaluated"
    multipliers: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)

    @property
    def limiting_joint(self) -> str:
        """The joint whose winding reaches the limit first (ties: the hottest after H)."""
        hot = dict(zip(self.joints, self.winding_after_hold_c))
        return min(self.joints, key=lambda j: (self.time_to_limit_s[j], -hot[j]))

    @property
    def hold_limit_s(self) -> float:
        return float(self.time_to_limit_s[self.limiting_joint])

    def to_dict(self) -> dict:
        return {"method": self.method, "status": self.status, "success": self.success, "joints": list(self.joints),
                "q_rad": self.q_rad.tolist(), "payload_point_m": self.payload_point_m.tolist(),
                "torque_nm": self.torque_nm.tolist(), "current_a": self.current_a.tolist(),
                "winding_after_hold_c": self.winding_after_hold_c.tolist(), "posture_hold_s": self.posture_hold_s,
                "time_to_limit_s": {j: _finite_or_none(t) for j, t in self.time_to_limit_s.items()},
                "limiting_joint": self.limiting_joint, "hold_limit_s": _finite_or_none(self.hold_limit_s)}


def _finite_or_none(value: float):
    return None if not math.isfinite(value) else float(value)


def evaluate_posture(model: ActuatedArm, q, limit_c: float, posture_hold_s: float, method: str = "given",
                     success: bool = True, status: str = "evaluated", multipliers=None) -> PostureChoice:
    """Torques (Pinocchio), static currents, winding after ``posture_hold_s`` and time to ``limit_c``
    of holding ``q`` from the idle state."""
    q = np.asarray(q, float)
    current = model.static_current_a(q)
    idle = model.idle_temperatures()
    _, temps = hold_temperatures(model, current, idle, posture_hold_s, HOLD_DT_S)
    point = np.array(payload_point_function(model)(q)).ravel()
    return PostureChoice(method, model.joints, q, point, model.arm.gravity_torque_nm(q), current,
                         temps[-1, winding_indices(model)], posture_hold_s,
                         time_to_limit_by_joint(model, current, idle, limit_c), success, status, multipliers or {})


def naive_posture(model: ActuatedArm) -> np.ndarray:
    """Every planned joint at 0 but the elbow at -pi/2: the forearm horizontal by the elbow alone."""
    return np.array([-math.pi / 2 if j == ELBOW else 0.0 for j in model.joints])


def hanging_posture(model: ActuatedArm, margin_rad: float) -> np.ndarray:
    """q = 0 (the arm hanging) moved ``margin_rad`` inside joint ranges that end at 0."""
    lo, hi = model.arm.model.lowerPositionLimit, model.arm.model.upperPositionLimit
    return np.clip(np.zeros(model.nu), lo + margin_rad, hi - margin_rad)


def _posture_nlp(model: ActuatedArm, posture_hold_s: float) -> tuple[ca.Function, ca.Function]:
    """The epigraph NLP (IPOPT) and ``hold_winding(q_rad) -> winding_c`` after ``posture_hold_s``."""
    q, t = ca.SX.sym("q_rad", model.nu), ca.SX.sym("t_c")
    current = static_current_function(model)(q)
    steps = max(1, round(posture_hold_s / HOLD_DT_S))
    step = thermal_step_function(thermal_rhs_function(model), posture_hold_s / steps)
    temps = ca.DM(model.idle_temperatures())
    for _ in range(steps):
        temps = step(temps, current, ca.DM.zeros(model.nu), model.ambient_c)
    winding = temps[winding_indices(model)]
    point = payload_point_function(model)(q)
    nlp = {"x": ca.vertcat(q, t), "f": t, "g": ca.vertcat(winding - t, point)}
    opts = {"ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10, "max_iter": 500}, "print_time": False}
    return (ca.nlpsol("posture", "ipopt", nlp, opts),
            ca.Function("hold_winding", [q], [winding], ["q_rad"], ["winding_c"]))


def optimal_posture(model: ActuatedArm, target_m, tolerance_m: float, limit_c: float, posture_hold_s: float,
                    margin_rad: float = 0.05, starts: int = 8, seed: int = 0) -> PostureChoice:
    """The posture minimising the hottest winding after ``posture_hold_s`` with the payload within
    ``tolerance_m`` (per axis) of ``target_m``; IPOPT from the naive posture and ``starts - 1``
    uniform random postures, the best converged one kept."""
    solver, _ = _posture_nlp(model, posture_hold_s)
    lo = model.arm.model.lowerPositionLimit + margin_rad
    hi = model.arm.model.upperPositionLimit - margin_rad
    target = np.asarray(target_m, float)
    n = model.nu
    bounds = {"lbx": np.r_[lo, -np.inf], "ubx": np.r_[hi, np.inf],
              "lbg": np.r_[np.full(n, -np.inf), target - tolerance_m], "ubg": np.r_[np.zeros(n), target + tolerance_m]}
    rng = np.random.default_rng(seed)
    guesses = [np.clip(naive_posture(model), lo, hi)] + [rng.uniform(lo, hi) for _ in range(starts - 1)]
    best = None
    for q0 in tqdm(guesses, desc="posture starts", unit="start", leave=False, disable=None):
        sol = solver(x0=np.r_[q0, 200.0], **bounds)
        stats = solver.stats()
        x = np.array(sol["x"]).ravel()
        log.debug("posture start: %s, max winding %.2f °C", stats["return_status"], x[-1])
        if stats["success"] and (best is None or x[-1] < best[0][-1]):
            best = (x, np.array(sol["lam_g"]).ravel(), np.array(sol["lam_x"]).ravel(), stats["return_status"])
    if best is None:
        return dataclasses.replace(evaluate_posture(model, guesses[0], limit_c, posture_hold_s, "ipopt"),
                                   success=False, status="no start converged")
    x, lam_g, lam_x, status = best
    return evaluate_posture(model, x[:n], limit_c, posture_hold_s, "ipopt", True, status,
                            {"lam_g": lam_g, "lam_x": lam_x, "t_c": x[-1]})


# --------------------------------------------------------------------------------------------
# The dynamic plan: hanging -> posture -> hold, by DDP
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class HoldProblem:
    """The transcribed move-and-hold: OCP + data. p per knot = [q_ref (n), tracking weight, hold flag, ambient]."""

    model: ActuatedArm
    problem: OptimalControlProblem
    x0: np.ndarray
    params: np.ndarray
    time_s: np.ndarray
    dt_s: float
    hold_knot: int
    q_goal: np.ndarray
    target_m: np.ndarray


def _stage(name, x, u, p, expr, out):
    return ca.Function(name, [x, u, p], [expr], ["x", "u", "p"], [out])


def _terminal(name, x, p, expr, out):
    return ca.Function(name, [x, p], [expr], ["x", "p"], [out])


def _joint_constraints(model, x, u, p, limit_c, vmax):
    """Per joint, by name: winding_limit_<j>, bus_voltage_<j>, joint_range_<j>, joint_velocity_<j>."""
    pm, out = model.arm.model, []
    for k, j in enumerate(model.joints):
        m = model.params[j].motor
        q, v, w = x[model.index(j, "q_rad")], x[model.index(j, "v_rad_s")], x[model.index(j, "winding_c")]
        volt = motor.voltage_v(m, u[k], v, w)
        lo, hi = pm.lowerPositionLimit[k], pm.upperPositionLimit[k]
        for kind, g in (("winding_limit", w - limit_c),
                        ("bus_voltage", ca.vertcat(volt - m.bus_voltage_v, -volt - m.bus_voltage_v)),
                        ("joint_range", ca.vertcat(q - hi, lo - q)),
                        ("joint_velocity", ca.vertcat(v - vmax[k], -v - vmax[k]))):
            out.append(Constraint(f"{kind}_{j}", _stage(f"{kind}_{j}", x, u, p, g, "g")))
    return out


def build_hold_problem(model: ActuatedArm, settings: WholeArmSettings, q_goal, target_m, dt_s: float) -> HoldProblem:
    """Move from the hanging posture to ``q_goal`` in ``move_s`` (min-jerk reference), then hold ``hold_s``
    with the payload inside the ``hold_band`` around ``target_m``; every joint's limits as constraints."""
    n, s = model.nu, settings
    x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", n), ca.SX.sym("p", n + 3)
    step, jac = model.step(dt_s), model.step_jacobians(dt_s)
    dyn = _stage("hold_dynamics", x, u, p, step(x, u, p[n + 2]), "x_next")
    dyn_jac = ca.Function("hold_dynamics_jacobians", [x, u, p], list(jac(x, u, p[n + 2])), ["x", "u", "p"],
                          ["x_next", "A", "B"])
    q = x[[model.index(j, "q_rad") for j in model.joints]]
    v = x[[model.index(j, "v_rad_s") for j in model.joints]]
    w = x[[model.index(j, "winding_c") for j in model.joints]]
    res = ca.vertcat(*[motor.resistance_ohm(model.params[j].motor, w[k]) for k, j in enumerate(model.joints)])
    costs = (Cost("tracking", 1.0, _stage("tracking", x, u, p, ca.sqrt(p[n]) * (q - p[:n]), "r")),
             Cost("joule_energy", s.energy_weight, _stage("joule_energy", x, u, p, ca.sqrt(res * dt_s) * u, "r")),
             Cost("velocity", s.velocity_weight, _stage("velocity", x, u, p, v, "r")))
    tcosts = (Cost("terminal_tracking", s.tracking_weight, _terminal("terminal_tracking", x, p, q - p[:n], "r")),
              Cost("terminal_velocity", 1.0, _terminal("terminal_velocity", x, p, v, "r")))
    point = payload_point_function(model)(q)
    target, tol = ca.DM(np.asarray(target_m, float)), s.target_tolerance_m
    band = ca.vertcat(p[n + 1] * (point - target) - tol, p[n + 1] * (target - point) - tol)
    vmax = np.asarray(model.arm.model.velocityLimit, float)
    cons = tuple(_joint_constraints(model, x, u, p, s.limit_c, vmax)) + (
        Constraint("hold_band", _stage("hold_band", x, u, p, band, "g")),)
    tcons = (Constraint("terminal_winding_limit", _terminal("terminal_winding_limit", x, p, w - s.limit_c, "g")),
             Constraint("terminal_hold_band", _terminal("terminal_hold_band", x, p, band, "g")))
    peak = np.array([model.params[j].motor.current_peak_a for j in model.joints])
    move, hold = int(round(s.move_s / dt_s)), int(round(s.hold_s / dt_s))
    problem = OptimalControlProblem(dyn, move + hold, costs, tcosts, cons, tcons, u_lb=-peak, u_ub=peak,
                                    name=f"whole_arm_{n}", dynamics_jacobians=dyn_jac)
    start = hanging_posture(model, s.range_margin_rad)
    q_ref = np.vstack([start + np.outer(min_jerk(np.arange(move + 1) / move), np.asarray(q_goal) - start),
                       np.tile(q_goal, (hold, 1))])
    flag = (np.arange(move + hold + 1) >= move).astype(float)
    params = np.column_stack([q_ref, np.full(move + hold + 1, s.tracking_weight), flag,
                              np.full(move + hold + 1, model.ambient_c)])
    return HoldProblem(model, problem, model.state(q=start), params, np.arange(move + hold + 1) * dt_s, dt_s, move,
                       np.asarray(q_goal, float), np.asarray(target_m, float))


def initial_guess(hp: HoldProblem) -> WarmStart:
    """States on the reference at the idle temperatures; currents from static gravity compensation."""
    n = hp.model.nu
    xs = np.tile(hp.x0, (hp.params.shape[0], 1))
    xs[:, :n] = hp.params[:, :n]
    us = np.array([hp.model.static_current_a(q) for q in hp.params[:-1, :n]])
    return WarmStart(xs, us)


def _constraint_maxima(hp: HoldProblem, result: SolverResult) -> dict[str, float]:
    """Largest value over the plan of every constraint (g <= 0), by name; ``current_peak_<joint>`` for the box."""
    f, pr = hp.problem.functions, hp.problem
    g = np.array(f.stage_constraint.map(pr.horizon)(result.xs[:-1].T, result.us.T, hp.params[:-1].T)).T
    gn = np.array(f.terminal_constraint(result.xs[-1], hp.params[-1])).ravel()
    out: dict[str, float] = {}
    for values, items in ((g.max(axis=0), pr.constraints), (gn, pr.terminal_constraints)):
        labels = [c.name for c in items for _ in range(c.size)]
        for value, label in zip(values, labels):
            out[label] = max(out.get(label, -np.inf), float(value))
    peak = np.abs(result.us).max(axis=0) - pr.u_ub
    out.update({f"current_peak_{j}": float(v) for j, v in zip(hp.model.joints, peak)})
    return out


def binding_constraints(hp: HoldProblem, result: SolverResult, active_tol: float = 1e-3) -> list[str]:
    """Constraint names at their bound (within ``active_tol``) somewhere on the plan."""
    return sorted(k for k, v in _constraint_maxima(hp, result).items() if abs(v) <= active_tol)


def violated_constraints(hp: HoldProblem, result: SolverResult, tol: float = 1e-3) -> list[str]:
    """Constraint names violated by more than ``tol`` somewhere on the plan (an infeasible result)."""
    return sorted(k for k, v in _constraint_maxima(hp, result).items() if v > tol)


def solve_hold(hp: HoldProblem, settings: WholeArmSettings, warm_start: WarmStart | None = None):
    """Gauss-Newton iLQR (robust from the gapped initial guess), then full DDP warm-started from it when
    not yet converged (the R(T) i^2 curvature of an active winding limit). Returns (result, summary).

    Full DDP from the cold guess fails on the 4-joint arm: the dynamics-tensor term makes the value
    Hessians indefinite and Quu regularisation does not bound them."""
    stages, result = [], None
    warm = warm_start or initial_guess(hp)
    for full, iterations in ((False, settings.gauss_newton_iterations), (True, settings.max_iterations)):
        if iterations == 0 or (result is not None and _feasible(result)):
            continue
        solver = DDPSolver(hp.problem, DDPSettings(full_second_order=full, backend=settings.ddp_backend,
                                                   max_iterations=iterations))
        result = solver.solve(hp.x0, hp.params, warm)
        warm = WarmStart.from_result(result)
        stages.append({"full_second_order": full, "status": result.status, "iterations": int(result.iterations),
                       "solve_s": float(result.solve_s), "build_s": float(solver.build_s)})
    summary = {**result.summary(), "status": result.status, "iterations": sum(st["iterations"] for st in stages),
               "solve_s": sum(st["solve_s"] for st in stages), "stages": stages}
    summary["total_solve_s"], summary["solves"] = summary["solve_s"], len(stages)
    return result, summary


def _feasible(result: SolverResult) -> bool:
    return bool(result.success and result.max_constraint_violation <= FEASIBLE_TOL)


@dataclasses.dataclass(frozen=True)
class WholeArmPlan:
    """The answer of :func:`plan_whole_arm`: the chosen posture, the naive one, the DDP plan and the hold limit.

    ``to_dict()`` follows the plan JSON contract (arrays [time][joint], ``model`` echo), with extra keys
    ``violated_constraints``, ``posture``, ``naive_posture``, ``limiting_joint``, ``time_to_limit_by_joint_s``.
    Constraint names carry the joint: ``winding_limit_arm_left_2_joint``, ``current_peak_arm_left_4_joint``.
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

    @property
    def success(self) -> bool:
        return self.feasible

    @property
    def limiting_joint(self) -> str:
        t = self.time_to_limit_by_joint_s
        return min(t, key=lambda j: (t[j], -self.series("winding_c")[-1, self.model.joints.index(j)]))

    @property
    def time_to_limit_s(self) -> float:
        """How long the hold can last from the plan's state on arrival at the posture."""
        return float(self.time_to_limit_by_joint_s[self.limiting_joint])

    @property
    def gain(self) -> float:
        """Hold time at the chosen posture over the naive one (static, from idle)."""
        return self.posture.hold_limit_s / self.naive.hold_limit_s if self.naive.hold_limit_s > 0 else math.inf

    def series(self, quantity: str) -> np.ndarray:
        return self.xs[:, [self.model.index(j, quantity) for j in self.model.joints]]

    def currents(self) -> np.ndarray:
        return np.vstack([self.us, self.us[-1:]])

    def output(self, name: str) -> np.ndarray:
        out = self.model.outputs.map(self.xs.shape[0])
        amb = np.full((1, self.xs.shape[0]), self.model.ambient_c)
        return np.array(out(self.xs.T, self.currents().T, amb)[self.model.outputs.name_out().index(name)]).T

    def to_dict(self) -> dict:
        s = self.settings
        d = {"feasible": self.feasible, "status": self.status, "message": self.message, "payload_kg": s.payload_kg,
             "limit_c": s.limit_c, "hold_s": s.hold_s, "achieved_hold_s": s.hold_s if self.feasible else 0.0,
             "joints": list(self.model.joints), "time_s": self.time_s.tolist(), "q_rad": self.series("q_rad").tolist(),
             "v_rad_s": self.series("v_rad_s").tolist(), "current_a": self.currents().tolist(),
             "voltage_v": self.output("voltage_v").tolist(), "winding_c": self.series("winding_c").tolist(),
             "casing_c": self.series("casing_c").tolist()}
        if all("drive" in self.model.networks[j].nodes for j in self.model.joints):
            d["drive_c"] = self.series("drive_c").tolist()
        d["model"] = self.model.to_dict("rk4", self.dt_s)
        d["solver"] = dict(self.solver)
        d["binding_constraints"] = list(self.binding_constraints)
        d["violated_constraints"] = list(self.violated_constraints)
        d["time_to_limit_s"] = _finite_or_none(self.time_to_limit_s)
        d.update(posture=self.posture.to_dict(), naive_posture=self.naive.to_dict(), limiting_joint=self.limiting_joint,
                 time_to_limit_by_joint_s={j: _finite_or_none(t) for j, t in self.time_to_limit_by_joint_s.items()})
        return d

    def report(self) -> str:
        p, nv, s = self.posture, self.naive, self.settings
        rows = [f"{'joint':>17} {'naive q':>8} {'naive A':>8} {'naive s':>8} {'chosen q':>9} {'chosen A':>9} "
                f"{'chosen s':>9} {'plan Tw max':>11}"]
        wmax = self.series("winding_c").max(axis=0)
        for k, j in enumerate(self.model.joints):
            rows.append(f"{j:>17} {nv.q_rad[k]:8.3f} {nv.current_a[k]:8.2f} {_fmt_s(nv.time_to_limit_s[j]):>8} "
                        f"{p.q_rad[k]:9.3f} {p.current_a[k]:9.2f} {_fmt_s(p.time_to_limit_s[j]):>9} {wmax[k]:11.1f}")
        return "\n".join([
            f"whole arm ({len(self.model.joints)} joints), {s.payload_kg:g} kg at the gripper, winding limit "
            f"{s.limit_c:g} °C: {'FEASIBLE' if self.feasible else 'INFEASIBLE'} ({self.status})",
            f"  {self.message}",
            f"  task: payload at {np.round(p.payload_point_m, 3).tolist()} m (±{s.target_tolerance_m:g} m)",
            f"  naive posture: limiting joint {nv.limiting_joint}, hold {_fmt_s(nv.hold_limit_s)} from idle",
            f"  {p.method} posture: limiting joint {p.limiting_joint}, hold {_fmt_s(p.hold_limit_s)} from idle "
            f"(x{self.gain:.2f})",
            f"  plan: hold {s.hold_s:g} s after a {s.move_s:g} s move; from arrival the hold can last "
            f"{_fmt_s(self.time_to_limit_s)} (limited by {self.limiting_joint})",
            f"  binding: {', '.join(self.binding_constraints) or 'none'}"
            + ("" if self.feasible else f"; violated: {', '.join(self.violated_constraints) or 'none'}"),
            f"  solver {self.solver['name']}: {self.solver['iterations']} iterations, {self.solver['solve_s']:.2f} s, "
            f"dt {self.dt_s:.4g} s, N {self.us.shape[0]}",
            *["  " + r for r in rows]])


def _fmt_s(t: float) -> str:
    return "never" if not math.isfinite(t) else f"{t:.1f} s"


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
    result, summary = solve_hold(hp, s)
    feasible = _feasible(result)
    arrival = result.xs[hp.hold_knot]
    ttl = time_to_limit_by_joint(model, model.static_current_a(chosen.q_rad), arrival[2 * model.nu:], s.limit_c)
    binding, violated = tuple(binding_constraints(hp, result)), tuple(violated_constraints(hp, result))
    if feasible:
        status, message = "feasible", f"holds {s.hold_s:g} s under {s.limit_c:g} °C"
    else:
        status = "infeasible_hold"
        message = (f"no feasible plan for the {s.hold_s:g} s hold ({result.status}: {result.message}); "
                   f"violated: {', '.join(violated) or 'none'}")
    log.info("whole arm %s: %s", model.joints, message)
    return WholeArmPlan(feasible, status, message, s, chosen, naive, hp.time_s, result.xs, result.us, dt, model,
                        summary, binding, violated, ttl)


# --------------------------------------------------------------------------------------------
# Monitoring: per-joint winding estimates from recordings
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class JointWindingEstimate:
    """One joint's estimated winding temperature over the recording (``status`` "estimated" or why not)."""

    joint: str
    status: str
    message: str
    time_s: np.ndarray | None = None
    winding_c: np.ndarray | None = None
    casing_c: np.ndarray | None = None
    measured_casing_c: np.ndarray | None = None
    limit_c: float = 84.0
    time_to_limit_s: float = math.nan

    @property
    def estimated(self) -> bool:
        return self.status == "estimated"

    @property
    def peak_winding_c(self) -> float:
        return float(self.winding_c.max()) if self.estimated else math.nan

    @property
    def first_over_limit_s(self) -> float:
        """Recording time when the estimate first reached the limit (inf: never)."""
        return _first_crossing(self.time_s, self.winding_c, self.limit_c) if self.estimated else math.nan

    @property
    def casing_rmse_c(self) -> float:
        """RMS of the predicted minus measured casing (the model's check on the recording)."""
        return float(np.sqrt(np.mean((self.casing_c - self.measured_casing_c) ** 2))) if self.estimated else math.nan

    def to_dict(self) -> dict:
        d = {"joint": self.joint, "status": self.status, "message": self.message}
        if self.estimated:
            d.update(time_s=self.time_s.tolist(), winding_c=self.winding_c.tolist(), casing_c=self.casing_c.tolist(),
                     peak_winding_c=self.peak_winding_c, final_winding_c=float(self.winding_c[-1]),
                     first_over_limit_s=_finite_or_none(self.first_over_limit_s),
                     time_to_limit_s=_finite_or_none(self.time_to_limit_s), casing_rmse_c=self.casing_rmse_c)
        return d


def _single_joint_model(params: JointParameters):
    """Thermal-only functions of one joint: (rhs, network, winding index, sensor index)."""
    net = network_from_parameters(params.thermal)
    m = params.motor
    t, i, v, amb = (ca.SX.sym(n, k) for n, k in (("temperatures_c", len(net.nodes)), ("current_a", 1),
                                                  ("velocity_rad_s", 1), ("ambient_c", 1)))
    rhs = net.rhs(t, motor.losses_w(m, i, v, t[net.index(net.limit_node)]), amb)
    f = ca.Function("joint_thermal_rhs", [t, i, v, amb], [rhs], ["temperatures_c", "current_a", "velocity_rad_s",
                                                                  "ambient_c"], ["dtemperatures_c_dt"])
    return f, net


def _initial_temperatures(rhs: ca.Function, net, casing_c: float, current_a: float, velocity: float,
                          ambient_c: float) -> np.ndarray:
    """The sensor node at its reading, every other node in quasi-steady state with it (the network is
    linear in T for given current and velocity)."""
    n, s = len(net.nodes), net.index(net.sensor_node)
    t = ca.SX.sym("t", n)
    jac = ca.Function("lin", [t], [ca.jacobian(rhs(t, current_a, velocity, ambient_c), t),
                                   rhs(t, current_a, velocity, ambient_c)])
    a, b = (np.array(m, float) for m in jac(np.zeros(n)))
    free = [k for k in range(n) if k != s]
    temps = np.zeros(n)
    temps[s] = casing_c
    if free:
        rows = a[np.ix_(free, free)]
        temps[free] = np.linalg.solve(rows, -(b.ravel()[free] + a[free, s] * casing_c))
    return temps


def _missing_signal(recording: Recording, joint: str, limit_c: float) -> JointWindingEstimate | None:
    """A not-estimable result when the recording lacks the current or the casing temperature."""
    for column, why in (("current_a", "without a current signal the Joule heating is unknown"),
                        ("temperature_c", "without a casing temperature there is no initial state")):
        if getattr(recording, column) is None:
            return JointWindingEstimate(joint, f"no_{column.split('_')[0]}", f"cannot estimate the winding of {joint}: "
                                        f"{why} (recording {recording.name} has {', '.join(recording.columns)})",
                                        limit_c=limit_c)
    return None


def estimate_winding(recording: Recording, params: JointParameters, limit_c: float = 84.0,
                     max_step_s: float = 1.0, horizon_s: float = 3600.0) -> JointWindingEstimate:
    """Open-loop simulation of the joint's thermal network driven by the recorded current (zero-order
    hold) and velocity, started from the casing reading; plus the time to ``limit_c`` holding the last
    current. Needs ``current_a`` and ``temperature_c``; without them the status says so."""
    joint = recording.joint or params.joint
    missing = _missing_signal(recording, joint, limit_c)
    if missing is not None:
        return missing
    rhs, net = _single_joint_model(params)
    time_s = recording.time_s
    dt = np.diff(time_s)
    substeps = max(1, math.ceil(float(dt.max(initial=0.0)) / max_step_s))
    h = ca.SX.sym("dt_s")
    args = [ca.SX.sym(rhs.name_in(k), rhs.size1_in(k)) for k in range(4)]
    x = args[0]
    for _ in range(substeps):
        x = rk4(rhs, x, h / substeps, *args[1:])
    step = ca.Function("joint_thermal_step", [*args, h], [x], [*rhs.name_in(), "dt_s"], ["temperatures_next_c"])
    velocity = recording.velocity if recording.velocity is not None else np.zeros(len(recording))
    ambient = recording.ambient_c
    if ambient is None:
        ambient = np.full(len(recording), params.thermal.ambient_c)
    t0 = _initial_temperatures(rhs, net, recording.temperature_c[0], recording.current_a[0], velocity[0], ambient[0])
    temps = t0[:, None]
    if dt.size:
        sim = step.mapaccum(dt.size)
        temps = np.hstack([temps, np.array(sim(t0, recording.current_a[:-1][None, :], velocity[:-1][None, :],
                                               ambient[:-1][None, :], dt[None, :]))])
    w, c = temps[net.index(net.limit_node)], temps[net.index(net.sensor_node)]
    hold = step.mapaccum(int(horizon_s))
    ahead = np.array(hold(temps[:, -1], recording.current_a[-1], 0.0, ambient[-1], 1.0))[net.index(net.limit_node)]
    ttl = _first_crossing(np.arange(ahead.size + 1, dtype=float), np.r_[w[-1], ahead], limit_c)
    return JointWindingEstimate(joint, "estimated", f"open-loop thermal simulation of {joint} ({net.nodes})",
                                time_s, w, c, recording.temperature_c, limit_c, ttl)


@dataclasses.dataclass(frozen=True)
class ArmMonitor:
    """Every joint's winding estimate from one recording session; flags the hottest joint."""

    source: str
    limit_c: float
    estimates: tuple[JointWindingEstimate, ...]

    @property
    def estimated(self) -> tuple[JointWindingEstimate, ...]:
        return tuple(e for e in self.estimates if e.estimated)

    @property
    def success(self) -> bool:
        return bool(self.estimated)

    @property
    def status(self) -> str:
        if len(self.estimated) == len(self.estimates):
            return "estimated"
        return "partial" if self.estimated else "cannot_estimate"

    @property
    def message(self) -> str:
        missing = [e for e in self.estimates if not e.estimated]
        if not missing:
            return f"estimated the winding of {len(self.estimates)} joints"
        head = f"{len(missing)} of {len(self.estimates)} joints not estimated"
        return f"{head}: {missing[0].message}" if len(missing) == len(self.estimates) else head

    @property
    def hottest_joint(self) -> str | None:
        """The joint with the highest estimated winding at the end of the recording."""
        est = self.estimated
        return max(est, key=lambda e: e.winding_c[-1]).joint if est else None

    @property
    def first_to_limit(self) -> str | None:
        """The joint that would reach the limit first holding its last current."""
        est = self.estimated
        return min(est, key=lambda e: (e.time_to_limit_s, -e.winding_c[-1])).joint if est else None

    def __getitem__(self, joint: str) -> JointWindingEstimate:
        for e in self.estimates:
            if e.joint == joint:
                return e
        raise KeyError(joint)

    def to_dict(self) -> dict:
        return {"source": self.source, "limit_c": self.limit_c, "status": self.status, "success": self.success,
                "message": self.message, "hottest_joint": self.hottest_joint, "first_to_limit": self.first_to_limit,
                "joints": {e.joint: e.to_dict() for e in self.estimates}}

    def report(self) -> str:
        lines = [f"winding monitor, {self.source}, limit {self.limit_c:g} °C: {self.status} - {self.message}"]
        for e in self.estimates:
            if e.estimated:
                lines.append(f"  {e.joint:>17}: final {e.winding_c[-1]:6.1f} °C, peak {e.peak_winding_c:6.1f} °C, "
                             f"over limit at {_fmt_s(e.first_over_limit_s)}, "
                             f"time to limit {_fmt_s(e.time_to_limit_s)}, casing rmse {e.casing_rmse_c:.2f} °C")
            else:
                lines.append(f"  {e.joint:>17}: {e.status} ({e.message})")
        if self.hottest_joint:
            lines.append(f"  hottest: {self.hottest_joint}; first to reach the limit: {self.first_to_limit}")
        return "\n".join(lines)


def monitor_recordings(recordings: Mapping[str, Recording], limit_c: float = 84.0,
                       parameter_files: Mapping[str, str | Path] | None = None, source: str = "") -> ArmMonitor:
    """:func:`estimate_winding` for each joint's recording, with ``models/<joint>.toml`` unless given."""
    files = dict(parameter_files or {})
    out = []
    for joint, rec in tqdm(recordings.items(), desc="joints", unit="joint", leave=False, disable=None):
        path = Path(files.get(joint, packaged_parameter_file(joint)))
        missing = _missing_signal(rec, joint, limit_c)
        if missing is not None:
            out.append(missing)
        elif not path.is_file():
            out.append(JointWindingEstimate(joint, "no_model", f"cannot estimate the winding of {joint}: "
                                            f"no parameter file {path}", limit_c=limit_c))
        else:
            out.append(estimate_winding(rec, load_parameters(path), limit_c))
    return ArmMonitor(source, limit_c, tuple(out))


def monitor_bag(path: str | Path, topic_maps: Sequence[TopicMap], limit_c: float = 84.0,
                parameter_files: Mapping[str, str | Path] | None = None) -> ArmMonitor:
    """Read every joint of ``topic_maps`` from one bag and estimate each joint's winding temperature."""
    recordings = read_bag_joints(path, topic_maps)
    return monitor_recordings(recordings, limit_c, parameter_files, source=str(path))
