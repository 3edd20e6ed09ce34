"""Thermal-only holds: stacked network right-hand sides (through
:func:`thermo_ddp.model.thermal.joint_heat_rhs`), hold temperatures, first crossings and the time to the limit."""
from __future__ import annotations

import math
from typing import Mapping

import casadi as ca
import numpy as np

from .._memo import Memo
from ..model.actuated import ActuatedArm
from ..model.integrators import rk4
from ..model.thermal import ThermalNetwork, joint_heat_rhs

_THERMAL_IN = ["temperatures_c", "current_a", "velocity_rad_s", "ambient_c"]
_TRAJECTORIES = Memo()  # (structure_key, dt_s, steps) -> the mapped thermal step of thermal_trajectory


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
    current = np.tile(np.asarray(current_a, float).ravel(), (steps, 1))
    temps = thermal_trajectory(model, current, np.zeros_like(current), temperatures_c, dt_s)
    return np.arange(steps + 1) * dt_s, temps


def thermal_trajectory(model: ActuatedArm, current_a, velocity_rad_s, temperatures_c, dt_s: float) -> np.ndarray:
    """Thermal-only simulation with per-step ``current_a`` and ``velocity_rad_s`` (K, joints), each held over
    a step of ``dt_s`` (RK4): the temperatures (K+1, nodes), the first row ``temperatures_c``."""
    current, speed = (np.atleast_2d(np.asarray(a, float)) for a in (current_a, velocity_rad_s))
    steps = current.shape[0]
    f = _TRAJECTORIES.get((model.structure_key, dt_s, steps),
                          lambda: thermal_step_function(thermal_rhs_function(model), dt_s).mapaccum(steps))
    temps = np.array(f(np.asarray(temperatures_c, float), current.T, speed.T, model.ambient_c)).T
    return np.vstack([np.asarray(temperatures_c, float), temps])


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

