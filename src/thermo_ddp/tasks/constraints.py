"""Per-joint constraints (``g <= 0``) of a task, by kind, on the model's state."""
from __future__ import annotations

from typing import Any

import casadi as ca

from ..model import motor
from ..model.actuated import ActuatedArm
from .limits import joint_range_rad


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


def _stop_speeds(model: ActuatedArm, joint: str, x, stop_speed_rad_s: float, slope_per_s: float):
    """The joint's speed and its bounds near the upper and the lower stop (``stop_speed + slope * distance``)."""
    q, v = (x[model.index(joint, name)] for name in ("q_rad", "v_rad_s"))
    lo, hi = (bound[model.joints.index(joint)] for bound in joint_range_rad(model))
    return v, stop_speed_rad_s + slope_per_s * (hi - q), stop_speed_rad_s + slope_per_s * (q - lo)


def stop_approach(model: ActuatedArm, joint: str, x, stop_speed_rad_s: float, slope_per_s: float):
    """``g <= 0``: the speed near each joint stop at most ``stop_speed_rad_s + slope_per_s * distance``, so a
    joint reaches its stops slowly or not at all."""
    v, near_hi, near_lo = _stop_speeds(model, joint, x, stop_speed_rad_s, slope_per_s)
    return ca.vertcat(v - near_hi, -v - near_hi, v - near_lo, -v - near_lo)


def toward_stops(model: ActuatedArm, joint: str, x, stop_speed_rad_s: float, slope_per_s: float):
    """The rows of :func:`stop_approach` that bound the speed toward a stop (toward the upper, toward the lower)."""
    v, near_hi, near_lo = _stop_speeds(model, joint, x, stop_speed_rad_s, slope_per_s)
    return ca.vertcat(v - near_hi, -v - near_lo)

