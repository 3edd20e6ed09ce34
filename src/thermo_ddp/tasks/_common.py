"""What every task built on the OCP layer shares (the lift, the whole-arm hold).

- defaults, each defined once: the requested hold (:data:`DEFAULT_HOLD_S`) and the winding limit,
  read from each joint's parameter file (:func:`default_limit_c`, :func:`limit_pair_c`);
- range checks: a winding limit (:func:`check_limit_c`), the joint range (:func:`joint_range_rad`,
  :func:`check_in_joint_range`), limits on work (:data:`HOLD_S`, :data:`MAX_KNOTS`, :func:`check_fields`);
- per-joint constraints by kind (:func:`joint_limit_constraints`);
- the initial guess, the feasibility test, binding and violated constraints by name;
- thermal-only holds: stacked network right-hand sides (through
  :func:`thermo_ddp.model.thermal.joint_heat_rhs`), first crossings and the time to the limit;
- result helpers: series by joint, the sensor node, currents, outputs, the plan JSON's arrays.

A task problem is a :class:`TaskProblem`: its per-knot parameters start with the joints' reference
angles ``q_ref`` (one column per joint, in the model's order).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import casadi as ca
import numpy as np

from .._config import require
from .._memo import Memo
from ..model import motor
from ..model.actuated import ActuatedArm
from ..model.integrators import rk4
from ..model.parameters import Bound, JointParameters
from ..model.thermal import ThermalNetwork, joint_heat_rhs
from ..ocp import OptimalControlProblem
from ..solvers import SolverResult, WarmStart
from ..solvers.ddp import PASS_COUNTS

DEFAULT_HOLD_S = 60.0     # requested hold at the goal: plan, compare, demo and the API
FEASIBLE_TOL = 1e-4       # largest constraint violation of a plan called feasible
ACTIVE_TOL = 1e-3         # a constraint within this of its bound is binding

# Limits on work, each with its reason (a request beyond one is bad input, refused before any work).
HOLD_S = Bound(0.0, 3600.0, "s", "one hour: the casing settles within tens of minutes (seed report), so a "
                                 "longer hold adds knots, not information")
MAX_KNOTS = 50_000        # knots of one transcribed horizon: memory and solve time grow linearly with them
MAX_LIMITS = 8            # winding limits compared in one run (each is a complete plan or closed loop)


# --------------------------------------------------------------------------------------------
# Defaults and range checks
# --------------------------------------------------------------------------------------------
def default_limit_c(params: JointParameters) -> float:
    """A joint's winding limit when none is given: its file's ``[limits] safety_cutoff_c``.

    The winding is never cooler than the casing the robot's cut-off reads (seed report 4.1: 84 °C),
    so a plan under it cannot trip the cut-off. ``winding_max_c`` (about 140 °C short-term) is the
    bound a plan may use when asked (:func:`limit_pair_c`)."""
    return params.limits.safety_cutoff_c


def limit_pair_c(params: JointParameters) -> tuple[float, float]:
    """The two winding limits worth comparing: the cut-off (:func:`default_limit_c`) and the file's
    short-term ``winding_max_c``."""
    return default_limit_c(params), params.limits.winding_max_c


def winding_limits_c(model: ActuatedArm, limit_c: float | None = None) -> dict[str, float]:
    """Each joint's winding limit: ``limit_c`` when given, else the joint's own default. A limit above
    a file's ``winding_max_c`` (what the winding takes at all) or not above its ambient is refused."""
    return {j: joint_limit_c(model.params[j], limit_c) for j in model.joints}


def joint_limit_c(params: JointParameters, limit_c: float | None = None) -> float:
    """One joint's winding limit (see :func:`winding_limits_c`)."""
    value = float(limit_c) if limit_c is not None else default_limit_c(params)
    require(value <= params.limits.winding_max_c, params.path, "limit_c", value,
            f"above the winding's rated maximum [limits] winding_max_c = {params.limits.winding_max_c:g} °C")
    require(value > params.thermal.ambient_c, params.path, "limit_c", value,
            f"not above the room temperature [thermal] ambient_c = {params.thermal.ambient_c:g} °C")
    return value


LIMIT_C = Bound(-50.0, 250.0, "°C", "a winding limit; the files' own winding_max_c and ambient_c apply too")


def check_limit_c(source: str, limit_c: float | None) -> float | None:
    """A winding limit in °C as a float (None: the parameter files' defaults)."""
    return None if limit_c is None else LIMIT_C.check(source, "limit_c", limit_c, "out of range")


def check_fields(settings: object, source: str, bounds: Mapping[str, Bound]) -> None:
    """Each named field of a frozen ``settings`` inside its bound, stored back as a float (numpy
    scalars accepted); the first one outside raises InputError naming it, its unit and the limit."""
    for name, bound in bounds.items():
        object.__setattr__(settings, name, bound.check(source, name, getattr(settings, name), "out of range"))


def check_knots(source: str, knots: int, dt_s: float) -> None:
    """A horizon of ``knots`` steps of ``dt_s`` within :data:`MAX_KNOTS`."""
    require(knots <= MAX_KNOTS, source, "horizon", f"{knots} knots of {dt_s:g} s",
            f"at most {MAX_KNOTS} knots per horizon (memory and solve time grow with them): shorten it or raise dt_s")


def check_idle_below_limits(model: ActuatedArm, limits_c: Mapping[str, float]) -> None:
    """At rest (no current, drive idle heat only) every winding settles below its limit; otherwise the
    file cannot describe a motor that works at all (e.g. a drive idle heat of kilowatts)."""
    idle = model.idle_temperatures()[winding_indices(model)]
    for j, w in zip(model.joints, idle):
        require(w < limits_c[j], model.params[j].path, "limit_c", limits_c[j],
                f"not above the winding's temperature at rest, {w:.1f} °C (the drive's idle heat): "
                "raise the limit, or check [thermal]")


def check_in_joint_range(model: ActuatedArm, source: str, name: str, joint: str, angle_rad: float) -> None:
    """``angle_rad`` of ``joint`` inside the URDF joint range (closed)."""
    lo, hi = (float(b[model.joints.index(joint)]) for b in joint_range_rad(model))
    require(lo <= angle_rad <= hi, source, name, angle_rad,
            f"outside the {joint} range [{lo:.3f}, {hi:.3f}] rad (URDF)")


def joint_range_rad(model: ActuatedArm, margin_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) joint angles of the model's joints (URDF range), ``margin_rad`` inside it."""
    pm = model.arm.model
    return np.asarray(pm.lowerPositionLimit, float) + margin_rad, np.asarray(pm.upperPositionLimit, float) - margin_rad


def joint_limit_constraints(model: ActuatedArm, joint: str, x, current_a, limit_c: float,
                            velocity_limit_rad_s: float) -> dict[str, Any]:
    """``g <= 0`` of one joint by kind: ``winding_limit``, ``bus_voltage``, ``joint_range``, ``joint_velocity``."""
    m = model.params[joint].motor
    q, v, w = (x[model.index(joint, name)] for name in ("q_rad", "v_rad_s", "winding_c"))
    volt = motor.voltage_v(m, current_a, v, w)
    lo, hi = (bound[model.joints.index(joint)] for bound in joint_range_rad(model))
    return {"winding_limit": w - limit_c,
            "bus_voltage": ca.vertcat(volt - m.bus_voltage_v, -volt - m.bus_voltage_v),
            "joint_range": ca.vertcat(q - hi, lo - q),
            "joint_velocity": ca.vertcat(v - velocity_limit_rad_s, -v - velocity_limit_rad_s)}


def stop_approach(model: ActuatedArm, joint: str, x, stop_speed_rad_s: float, slope_per_s: float):
    """``g <= 0``: the speed near each joint stop at most ``stop_speed_rad_s + slope_per_s * distance``, so a
    joint reaches its stops slowly or not at all."""
    q, v = (x[model.index(joint, name)] for name in ("q_rad", "v_rad_s"))
    lo, hi = (bound[model.joints.index(joint)] for bound in joint_range_rad(model))
    near_hi, near_lo = stop_speed_rad_s + slope_per_s * (hi - q), stop_speed_rad_s + slope_per_s * (q - lo)
    return ca.vertcat(v - near_hi, -v - near_hi, v - near_lo, -v - near_lo)


@dataclasses.dataclass(frozen=True)
class MotionQuality:
    """What a careful operator checks on a joint's motion: how often it reverses (speeds under
    ``still_rad_s`` ignored), how fast it moves within ``near_rad`` of a stop, whether it ends at rest and
    inside its range, and its largest acceleration."""

    reversals: int
    max_speed_near_stop_rad_s: float
    final_speed_rad_s: float
    max_acceleration_rad_s2: float
    inside_range: bool

    @classmethod
    def of(cls, time_s, q, v, lower_rad: float, upper_rad: float, near_rad: float = 0.1,
           still_rad_s: float = 0.02) -> "MotionQuality":
        q, v, t = (np.asarray(a, float).ravel() for a in (q, v, time_s))
        signs = np.sign(v[np.abs(v) > still_rad_s])
        near = (q > upper_rad - near_rad) | (q < lower_rad + near_rad)
        return cls(int(np.count_nonzero(signs[1:] != signs[:-1])),
                   float(np.abs(v[near]).max()) if near.any() else 0.0, float(abs(v[-1])),
                   float(np.abs(np.diff(v) / np.diff(t)).max()),
                   bool(np.all((q >= lower_rad - 1e-9) & (q <= upper_rad + 1e-9))))


# --------------------------------------------------------------------------------------------
# Problems and verdicts
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TaskProblem:
    """A transcribed task: the OCP and its data (initial state, per-knot parameters named by
    ``problem.parameters``, with a ``q_ref_rad`` block, and the time grid).

    ``box_names``: the name of each control's current box (``current_peak``...)."""

    model: ActuatedArm
    problem: OptimalControlProblem
    x0: np.ndarray
    params: np.ndarray
    time_s: np.ndarray
    box_names: tuple[str, ...]


def initial_guess(tp: TaskProblem) -> WarmStart:
    """States on the reference (angles, and speeds its time derivative) at the initial temperatures, currents
    from static gravity compensation.

    The speeds matter with careful motion: at rest on a moving reference, DDP started light lifts far
    from the one-way and stop-approach constraints' feasible side (20 kg, 84 °C, 40 s hold: a false
    'infeasible' after 80 iterations; with the reference's speeds: converged in 18)."""
    q_ref = tp.params[:, tp.problem.parameters.slice("q_ref_rad")]
    xs = np.tile(tp.x0, (q_ref.shape[0], 1))
    xs[:, [tp.model.index(j, "q_rad") for j in tp.model.joints]] = q_ref
    xs[:, [tp.model.index(j, "v_rad_s") for j in tp.model.joints]] = np.gradient(q_ref, tp.time_s, axis=0)
    us = tp.model.static_current_a(q_ref[:-1])
    return WarmStart(xs, us)


def is_feasible(result: SolverResult, tol: float = FEASIBLE_TOL) -> bool:
    return bool(result.success and result.max_constraint_violation <= tol)


def constraint_maxima(tp: TaskProblem, result: SolverResult) -> dict[str, float]:
    """Largest value over the plan of every constraint (g <= 0) by name, the current boxes included
    (|u| - peak)."""
    f, pr = tp.problem.functions, tp.problem
    g = np.array(f.stage_constraint.map(pr.horizon)(result.xs[:-1].T, result.us.T, tp.params[:-1].T)).T
    gn = np.array(f.terminal_constraint(result.xs[-1], tp.params[-1])).ravel()
    out: dict[str, float] = {}
    for values, items in ((g.max(axis=0) if g.size else g, pr.constraints), (gn, pr.terminal_constraints)):
        labels = [c.name for c in items for _ in range(c.size)]
        for value, label in zip(values, labels):
            out[label] = max(out.get(label, -np.inf), float(value))
    peak = np.abs(result.us).max(axis=0) - np.broadcast_to(pr.u_ub, result.us.shape[1:])
    out.update({name: float(v) for name, v in zip(tp.box_names, peak)})
    return out


def binding_constraints(tp: TaskProblem, result: SolverResult, active_tol: float = ACTIVE_TOL) -> list[str]:
    """Names of the constraints at (or past) their bound somewhere on the plan."""
    return sorted(k for k, v in constraint_maxima(tp, result).items() if v >= -active_tol)


def violated_constraints(tp: TaskProblem, result: SolverResult, tol: float = ACTIVE_TOL) -> list[str]:
    """Names of the constraints violated by more than ``tol`` somewhere on the plan."""
    return sorted(k for k, v in constraint_maxima(tp, result).items() if v > tol)


def solver_summary(result: SolverResult, total_solve_s: float, solves: int, every_result=None, **override) -> dict:
    """The plan JSON's ``solver``: the result's summary, its status, all solves' time and count, and ``work``:
    :func:`solve_work` of every solve (``every_result``; default: the result alone)."""
    return {**result.summary(), "status": result.status, "total_solve_s": float(total_solve_s), "solves": solves,
            "work": solve_work(every_result or [result]), **override}


def solve_work(results) -> dict[str, int]:
    """Iterations and, where the solver counts them (DDP), its passes of each kind and multiplier updates
    (:data:`thermo_ddp.solvers.ddp.PASS_COUNTS`), summed over ``results``."""
    results = list(results)
    work = {"iterations": sum(int(r.iterations) for r in results)}
    work.update({k: sum(int(r.info[k]) for r in results) for k in PASS_COUNTS if all(k in r.info for r in results)})
    return work


# --------------------------------------------------------------------------------------------
# Thermal-only holds and first crossings
# --------------------------------------------------------------------------------------------
_THERMAL_IN = ["temperatures_c", "current_a", "velocity_rad_s", "ambient_c"]
_HOLD_SIMULATIONS = Memo()  # (structure_key, dt_s, steps) -> the mapped thermal step of hold_temperatures


def joint_thermal_rhs(network: ThermalNetwork, motor_params) -> ca.Function:
    """``joint_thermal_rhs(temperatures_c, current_a, velocity_rad_s, ambient_c) -> dtemperatures_c_dt``."""
    t, i, v, amb = (ca.SX.sym(name, size) for name, size in zip(_THERMAL_IN, (len(network.nodes), 1, 1, 1)))
    return ca.Function("joint_thermal_rhs", [t, i, v, amb], [joint_heat_rhs(network, motor_params, t, i, v, amb)],
                       _THERMAL_IN, ["dtemperatures_c_dt"])


def thermal_rhs_function(model: ActuatedArm) -> ca.Function:
    """``thermal_rhs(temperatures_c, current_a, velocity_rad_s, ambient_c) -> dtemperatures_c_dt`` of
    every joint's network (temperatures stacked as in the model state after q and v)."""
    sizes = [len(model.networks[j].nodes) for j in model.joints]
    temps = ca.SX.sym("temperatures_c", sum(sizes))
    i, v, amb = ca.SX.sym("current_a", model.nu), ca.SX.sym("velocity_rad_s", model.nu), ca.SX.sym("ambient_c")
    offsets = np.cumsum([0] + sizes)
    out = [joint_heat_rhs(model.networks[j], model.params[j].motor, temps[offsets[k]:offsets[k + 1]], i[k], v[k], amb)
           for k, j in enumerate(model.joints)]
    return ca.Function("thermal_rhs", [temps, i, v, amb], [ca.vertcat(*out)], _THERMAL_IN, ["dtemperatures_c_dt"])


def thermal_step_function(rhs: ca.Function, dt_s: float) -> ca.Function:
    """``thermal_step(temperatures_c, current_a, velocity_rad_s, ambient_c) -> temperatures_next_c`` (RK4)."""
    args = [ca.SX.sym(rhs.name_in(k), rhs.size1_in(k)) for k in range(4)]
    return ca.Function("thermal_step", args, [rk4(rhs, args[0], dt_s, *args[1:])], rhs.name_in(),
                       ["temperatures_next_c"])


def winding_indices(model: ActuatedArm) -> list[int]:
    """Index of each joint's winding node in the stacked temperatures (x[2n:])."""
    return [model.index(j, "winding_c") - 2 * model.nu for j in model.joints]


def hold_temperatures(model: ActuatedArm, current_a, temperatures_c, duration_s: float,
                      dt_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Thermal-only simulation of holding still with constant ``current_a``: (time_s, temperatures)."""
    steps = max(1, int(math.ceil(duration_s / dt_s)))
    f = _HOLD_SIMULATIONS.get((model.structure_key, dt_s, steps),
                              lambda: thermal_step_function(thermal_rhs_function(model), dt_s).mapaccum(steps))
    temps = np.array(f(np.asarray(temperatures_c, float), np.asarray(current_a, float), np.zeros(model.nu),
                       model.ambient_c)).T
    return np.arange(steps + 1) * dt_s, np.vstack([np.asarray(temperatures_c, float), temps])


def first_crossing(time_s: np.ndarray, values: np.ndarray, level: float) -> float:
    """First time ``values`` reaches ``level`` (linear between samples; inf: never)."""
    hit = np.flatnonzero(values >= level)
    if hit.size == 0:
        return math.inf
    k = hit[0]
    return 0.0 if k == 0 else float(np.interp(level, values[k - 1:k + 1], time_s[k - 1:k + 1]))


def time_to_limit_by_joint(model: ActuatedArm, current_a, temperatures_c, limits_c: Mapping[str, float],
                           horizon_s: float = 3600.0, dt_s: float = 0.5) -> dict[str, float]:
    """Per joint: time until its winding reaches its limit holding ``current_a`` (inf: not within horizon)."""
    time_s, temps = hold_temperatures(model, current_a, temperatures_c, horizon_s, dt_s)
    w = temps[:, winding_indices(model)]
    return {j: first_crossing(time_s, w[:, k], limits_c[j]) for k, j in enumerate(model.joints)}


def limiting_joint(time_to_limit_s: Mapping[str, float], winding_c: Mapping[str, float]) -> str:
    """The joint whose winding reaches its limit first (ties: the hottest)."""
    return min(time_to_limit_s, key=lambda j: (time_to_limit_s[j], -winding_c[j]))


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
def finite_or_none(value: float):
    return None if not math.isfinite(value) else float(value)


def format_s(t: float) -> str:
    return "never" if not math.isfinite(t) else f"{t:.1f} s"


class PlanSeries:
    """Trajectories by name and the plan JSON of a plan with ``model``, ``time_s``, ``xs`` (N+1, nx),
    ``us`` (N, nu), ``feasible``, ``status``, ``message``, ``solver``, ``binding_constraints`` and
    ``time_to_limit_s``."""

    @property
    def success(self) -> bool:
        return self.feasible

    def series(self, quantity: str) -> np.ndarray:
        """(N+1, joints) of a state quantity (q_rad, v_rad_s, winding_c, casing_c, drive_c)."""
        return self.xs[:, [self.model.index(j, quantity) for j in self.model.joints]]

    def sensor_c(self) -> np.ndarray:
        """(N+1, joints) of the measured node: the casing, or the winding itself in a one-node model."""
        return self.xs[:, self.model.sensor_indices()]

    def currents(self) -> np.ndarray:
        """(N+1, joints): u_k holds on [t_k, t_k+1); the last value is repeated at t_N."""
        return np.vstack([self.us, self.us[-1:]])

    def output(self, name: str) -> np.ndarray:
        """(N+1, joints) of a model output (voltage_v, joule_w, ...) with :meth:`currents`."""
        out = self.model.outputs.map(self.xs.shape[0])
        amb = np.full((1, self.xs.shape[0]), self.model.ambient_c)
        return np.array(out(self.xs.T, self.currents().T, amb)[self.model.outputs.name_out().index(name)]).T

    def voltage_v(self) -> np.ndarray:
        return self.output("voltage_v")

    def contract_dict(self, payload_kg: float, limit_c: float, hold_s: float, achieved_hold_s: float,
                      integrator: str, dt_s: float) -> dict:
        """The plan JSON (contract): arrays [time][joint], ``casing_c`` the sensor node, ``drive_c`` only
        when every joint has a drive node; the ``model`` echo, ``solver``, binding constraints and the
        time to the limit (None: never)."""
        d = {"feasible": self.feasible, "status": self.status, "message": self.message, "payload_kg": payload_kg,
             "limit_c": limit_c, "hold_s": hold_s, "achieved_hold_s": achieved_hold_s,
             "joints": list(self.model.joints), "time_s": self.time_s.tolist(), "q_rad": self.series("q_rad").tolist(),
             "v_rad_s": self.series("v_rad_s").tolist(), "current_a": self.currents().tolist(),
             "voltage_v": self.voltage_v().tolist(), "winding_c": self.series("winding_c").tolist(),
             "casing_c": self.sensor_c().tolist()}
        if all("drive" in self.model.networks[j].nodes for j in self.model.joints):
            d["drive_c"] = self.series("drive_c").tolist()
        d["model"] = self.model.to_dict(integrator, dt_s)
        d["solver"] = dict(self.solver)
        d["binding_constraints"] = list(self.binding_constraints)
        d["time_to_limit_s"] = finite_or_none(self.time_to_limit_s)
        return d
