"""Per-joint constraints (``g <= 0``) of a task, by kind, on the model's state."""
from __future__ import annotations

from typing import Any

import casadi as ca

from ..model import motor
from ..model.actuated import ActuatedArm
from .limits import joint_range_rad


def joint_limit_constraints(model: ActuatedArm, joint: str, x, current_a, limit_c: float,
                            velocity_limit_rad_s: float, x_next=None) -> dict[str, Any]:
    """``g <= 0`` of one joint by kind: ``winding_limit``, ``bus_voltage`` (:func:`bus_voltage`; over the whole
    knot when its end state ``x_next`` is given), ``joint_range``, ``joint_velocity``."""
    q, v, w = (x[model.index(joint, name)] for name in ("q_rad", "v_rad_s", "winding_c"))
    lo, hi = (bound[model.joints.index(joint)] for bound in joint_range_rad(model))
    return {"winding_limit": w - limit_c,
            "bus_voltage": bus_voltage(model, joint, x, current_a, x_next),
            "joint_range": ca.vertcat(q - hi, lo - q),
            "joint_velocity": ca.vertcat(v - velocity_limit_rad_s, -v - velocity_limit_rad_s)}


def bus_voltage(model: ActuatedArm, joint: str, x, current_a, x_next=None):
    """``g <= 0``: the motor voltage ``R(T_w) i + K_b N v`` within the bus voltage at the knot's start and, when the
    knot's end state ``x_next`` is given, at its end under the same (held) current. The current is held over the
    knot, so the voltage is affine in the speed and peaks at an end of the knot unless the speed turns inside it: a
    fast knot's end is where it peaks when the joint accelerates (measured, branch mpc7: a re-plan's -20 A at
    -2.3 rad/s gave 41.5 V at the knot's start, 55.9 V at its end, over the 48 V bus)."""
    m = model.params[joint].motor
    ends = [x] if x_next is None else [x, x_next]
    rows = []
    for state in ends:
        volt = motor.voltage_v(m, current_a, *(state[model.index(joint, n)] for n in ("v_rad_s", "winding_c")))
        rows += [volt - m.bus_voltage_v, -volt - m.bus_voltage_v]
    return ca.vertcat(*rows)


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

