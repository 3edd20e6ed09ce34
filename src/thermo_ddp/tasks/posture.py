"""The holding posture: hold ``payload_kg`` at a task point with the posture whose hottest winding
stays coolest.

A small NLP (IPOPT) over the joint angles q and an epigraph variable t::

    min t   s.t.  T_w,j(q; H) <= t            for every joint j
                  |p(q) - p_target| <= tol     (payload point, per axis, base frame)
                  q_lo + margin <= q <= q_hi - margin

where T_w,j(q; H) is joint j's winding temperature after holding q for H s from the idle state
(its thermal network driven by the static current i_j = g_j(q) / (N K_m), RK4), and p(q) the
payload point. The default task point (:mod:`thermo_ddp.tasks.whole_arm`) is where the *naive*
posture (every joint at 0, forearm horizontal by the elbow alone) holds the payload: the same point
in space, reached by another posture.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Mapping

import casadi as ca
import numpy as np
from tqdm import tqdm

from ..model import motor
from ..model.actuated import ActuatedArm
from ..model.arm import ELBOW
from ..model.rigid_body import RigidBodyDynamics
from .limits import joint_range_rad, winding_limits_c
from .series import finite_or_none
from .thermal_hold import (hold_temperatures, limiting_joint, thermal_rhs_function, thermal_step_function,
                           time_to_limit_by_joint, winding_indices)

log = logging.getLogger(__name__)
HOLD_DT_S = 2.0           # thermal-only RK4 step of the posture objective (winding tau >= 30 s)


# --------------------------------------------------------------------------------------------
# Named CasADi functions of the model (kinematics, statics)
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


# --------------------------------------------------------------------------------------------
# Postures and what holding them costs
# --------------------------------------------------------------------------------------------
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
        """The joint whose winding reaches its limit first (ties: the hottest after H)."""
        return limiting_joint(self.time_to_limit_s, dict(zip(self.joints, self.winding_after_hold_c)))

    @property
    def hold_limit_s(self) -> float:
        return float(self.time_to_limit_s[self.limiting_joint])

    def to_dict(self) -> dict:
        return {"method": self.method, "status": self.status, "success": self.success, "joints": list(self.joints),
                "q_rad": self.q_rad.tolist(), "payload_point_m": self.payload_point_m.tolist(),
                "torque_nm": self.torque_nm.tolist(), "current_a": self.current_a.tolist(),
                "winding_after_hold_c": self.winding_after_hold_c.tolist(), "posture_hold_s": self.posture_hold_s,
                "time_to_limit_s": {j: finite_or_none(t) for j, t in self.time_to_limit_s.items()},
                "limiting_joint": self.limiting_joint, "hold_limit_s": finite_or_none(self.hold_limit_s)}


def evaluate_posture(model: ActuatedArm, q, limit_c: float | None, posture_hold_s: float, method: str = "given",
                     success: bool = True, status: str = "evaluated", multipliers=None) -> PostureChoice:
    """Torques (Pinocchio), static currents, winding after ``posture_hold_s`` and time to the winding
    limit (``limit_c``, None: each joint's own) of holding ``q`` from the idle state."""
    q = np.asarray(q, float)
    current = model.static_current_a(q)
    idle = model.idle_temperatures()
    _, temps = hold_temperatures(model, current, idle, posture_hold_s, HOLD_DT_S)
    point = np.array(payload_point_function(model)(q)).ravel()
    ttl = time_to_limit_by_joint(model, current, idle, winding_limits_c(model, limit_c))
    return PostureChoice(method, model.joints, q, point, model.arm.gravity_torque_nm(q), current,
                         temps[-1, winding_indices(model)], posture_hold_s, ttl, success, status, multipliers or {})


def naive_posture(model: ActuatedArm) -> np.ndarray:
    """Every planned joint at 0 but the elbow at -pi/2: the forearm horizontal by the elbow alone."""
    return np.array([-math.pi / 2 if j == ELBOW else 0.0 for j in model.joints])


def hanging_posture(model: ActuatedArm, margin_rad: float) -> np.ndarray:
    """q = 0 (the arm hanging) moved ``margin_rad`` inside joint ranges that end at 0."""
    return np.clip(np.zeros(model.nu), *joint_range_rad(model, margin_rad))


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


def optimal_posture(model: ActuatedArm, target_m, tolerance_m: float, limit_c: float | None, posture_hold_s: float,
                    margin_rad: float = 0.05, starts: int = 8, seed: int = 0) -> PostureChoice:
    """The posture minimising the hottest winding after ``posture_hold_s`` with the payload within
    ``tolerance_m`` (per axis) of ``target_m``; IPOPT from the naive posture and ``starts - 1``
    uniform random postures, the best converged one kept."""
    solver, _ = _posture_nlp(model, posture_hold_s)
    lo, hi = joint_range_rad(model, margin_rad)
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
