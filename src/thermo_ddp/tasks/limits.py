"""Limits of a task, each defined once, and the range checks a request passes before any work.

- defaults: the requested hold (:data:`DEFAULT_HOLD_S`) and the winding limit, read from each joint's
  parameter file (:func:`default_limit_c`, :func:`limit_pair_c`, :func:`winding_limits_c`);
- range checks: a winding limit (:func:`check_limit_c`), the joint range (:func:`joint_range_rad`,
  :func:`check_in_joint_range`), limits on work (:data:`HOLD_S`, :data:`MAX_KNOTS`, :data:`MAX_LIMITS`,
  :func:`check_fields`, :func:`check_knots`) and a motor that settles below its limit at rest
  (:func:`check_idle_below_limits`).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .._config import require
from ..model.actuated import ActuatedArm
from ..model.parameters import Bound, JointParameters
from .thermal_hold import winding_indices

DEFAULT_HOLD_S = 60.0     # requested hold at the goal: plan, compare, demo and the API

# Limits on work, each with its reason (a request beyond one is bad input, refused before any work).
HOLD_S = Bound(0.0, 3600.0, "s", "one hour: the casing settles within tens of minutes (seed report), so a "
                                 "longer hold adds knots, not information")
MAX_KNOTS = 50_000        # knots of one transcribed horizon: memory and solve time grow linearly with them
MAX_LIMITS = 8            # winding limits compared in one run (each is a complete plan or closed loop)


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

