"""Motor electro-mechanics (seed report eqs. 1-5), written once as CasADi-compatible expressions.

Every function takes a parameter object with the attributes of ``MotorParameters`` (floats, or
CasADi symbols for identification) and joint-side velocities in rad/s; the input is the winding
current in A. Motor-side quantities are obtained through the gear ratio.
"""
from __future__ import annotations

import casadi as ca


def resistance_ohm(m, winding_c):
    """Eq. (3): R(T_w) = R_ref (1 + alpha_Cu (T_w - T_ref))."""
    return m.resistance_ohm * (1 + m.copper_alpha_per_k * (winding_c - m.resistance_ref_c))


def smooth_sign(m, velocity_rad_s):
    """sign(v) smoothed so that derivatives exist: tanh(v / eps), eps = ``coulomb_smoothing_rad_s`` (the one
    smoothing of every |v| and sign(v) of the model)."""
    return ca.tanh(velocity_rad_s / m.coulomb_smoothing_rad_s)


def smooth_abs(m, velocity_rad_s):
    """|v| smoothed with the Coulomb friction's eps: v tanh(v / eps). Zero at rest with zero slope and
    curvature 2 / eps there (so every heat term driven by it is smooth at v = 0, where a hold keeps the
    joint); below |v| by at most 0.28 eps, and by less than 1e-8 |v| beyond 10 eps."""
    return velocity_rad_s * smooth_sign(m, velocity_rad_s)


def driver_power(value, exponent: float):
    """``value ** exponent`` of a loss driver that is 0 at rest (e.g. :func:`smooth_abs`), with finite
    derivatives there for every exponent >= 1: (x + d)^e - d^e with d = 1e-12, so that the second
    derivative e (e - 1) x^(e-2) x'^2 of an exponent in (1, 2) is not inf * 0 at x = 0 (a change below
    1e-11 in the value)."""
    if exponent == 1:
        return value
    if float(exponent).is_integer():
        return value ** exponent
    return (value + _POWER_SHIFT) ** exponent - _POWER_SHIFT ** exponent


_POWER_SHIFT = 1e-12


def friction_torque_nm(m, velocity_rad_s):
    """Joint-side friction: viscous + Coulomb smoothed (:func:`smooth_sign`) so that derivatives exist."""
    return m.viscous_friction_nm_s_per_rad * velocity_rad_s + m.coulomb_friction_nm * smooth_sign(m, velocity_rad_s)


def joint_torque_nm(m, current_a, velocity_rad_s):
    """Eq. (4) through the gear, minus friction: N K_m i - tau_f(v) (contract's joint torque)."""
    return m.gear_ratio * m.torque_constant_nm_per_a * current_a - friction_torque_nm(m, velocity_rad_s)


def back_emf_v(m, velocity_rad_s):
    """Eq. (2): V_b = K_b theta_dot_m, with theta_dot_m = N v."""
    return m.back_emf_v_s_per_rad * m.gear_ratio * velocity_rad_s


def voltage_v(m, current_a, velocity_rad_s, winding_c):
    """Eq. (4) rearranged: V = R(T_w) i + V_b; must stay within the bus voltage."""
    return resistance_ohm(m, winding_c) * current_a + back_emf_v(m, velocity_rad_s)


def joule_w(m, current_a, winding_c):
    """Eq. (5): P_J = R(T_w) i^2."""
    return resistance_ohm(m, winding_c) * current_a ** 2


def friction_w(m, velocity_rad_s):
    """Mechanical power dissipated by friction, tau_f(v) v = b v^2 + F_c |v|_smooth >= 0 (smooth at v = 0)."""
    return m.viscous_friction_nm_s_per_rad * velocity_rad_s ** 2 + m.coulomb_friction_nm * smooth_abs(m, velocity_rad_s)


def losses_w(m, current_a, velocity_rad_s, winding_c, held=None) -> dict:
    """The named losses and loss drivers a thermal network's heat sources may draw on (the heat a
    source injects from them, e.g. drive or iron losses, is the network's: ``thermal.HeatSource``).
    ``held`` replaces drivers by their means over a zero-order-hold interval; the losses that scale with
    R(T_w) (``joule_w`` = R i^2, ``ac_joule_w`` = R i^2 w^2) are R(T_w) times the held driver."""
    drivers = {"friction_w": friction_w(m, velocity_rad_s),
               "current_sq_a2": current_a ** 2,
               "speed_abs_rad_s": smooth_abs(m, velocity_rad_s),
               "current_sq_speed_sq": current_a ** 2 * velocity_rad_s ** 2} | dict(held or {})
    r = resistance_ohm(m, winding_c)
    return drivers | {"joule_w": r * drivers["current_sq_a2"], "ac_joule_w": r * drivers["current_sq_speed_sq"]}


def current_for_torque_a(m, torque_nm, velocity_rad_s=0.0):
    """Static inverse of ``joint_torque_nm``: the current that yields ``torque_nm`` at ``velocity``."""
    return (torque_nm + friction_torque_nm(m, velocity_rad_s)) / (m.gear_ratio * m.torque_constant_nm_per_a)
