"""Discretisation of a continuous ODE ``ode(x, u, p) -> xdot`` into named step functions
(input names are taken from the ODE, e.g. ``step(x, current_a, ambient_c) -> x_next``)."""
from __future__ import annotations

import casadi as ca
import numpy as np

INTEGRATORS = ("rk4", "rk4_<m>", "implicit_euler")


def rk4_substeps(integrator: str) -> int | None:
    """``"rk4"`` -> 1, ``"rk4_4"`` -> 4 sub-steps per step; None for other integrators."""
    if integrator == "rk4":
        return 1
    head, _, count = integrator.partition("_")
    if head == "rk4" and count.isdigit() and int(count) >= 1:
        return int(count)
    return None


def rk4(f, x, h: float, *args):
    """One classic Runge-Kutta 4 step of x' = f(x, *args) (expressions or numbers)."""
    k1 = f(x, *args)
    k2 = f(x + h / 2 * k1, *args)
    k3 = f(x + h / 2 * k2, *args)
    k4 = f(x + h * k3, *args)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_step(ode: ca.Function, dt: float, substeps: int = 1) -> ca.Function:
    """Classic explicit Runge-Kutta 4 step ``step(x, u, p) -> x_next`` with ``substeps`` sub-steps."""
    x, u, p = (ca.SX.sym(n, ode.size1_in(i)) for i, n in enumerate(ode.name_in()))
    xn = x
    for _ in range(substeps):
        xn = rk4(ode, xn, dt / substeps, u, p)
    return ca.Function("step", [x, u, p], [xn], ode.name_in(), ["x_next"])


def implicit_euler_step(ode: ca.Function, dt: float, newton_iterations: int = 4) -> ca.Function:
    """L-stable backward Euler, x+ = x + dt f(x+, u, p), solved by a fixed number of Newton steps
    from an explicit-Euler guess. Unrolled, so it stays an SX expression: exact derivatives of the
    computed step and C code generation come for free. Stiff-safe for the thermal time scales. The fixed
    count is checked where steps are simulated (:func:`check_implicit_steps`: the Newton residual of every
    step, refused above :data:`IMPLICIT_RESIDUAL_TOL`)."""
    x, u, p = (ca.SX.sym(n, ode.size1_in(i)) for i, n in enumerate(ode.name_in()))
    z = ca.SX.sym("z", x.numel())
    residual = z - x - dt * ode(z, u, p)
    newton = ca.Function("newton", [z, x, u, p], [z - ca.solve(ca.jacobian(residual, z), residual)])
    xn = x + dt * ode(x, u, p)
    for _ in range(newton_iterations):
        xn = newton(xn, x, u, p)
    return ca.Function("step", [x, u, p], [xn], ode.name_in(), ["x_next"])


IMPLICIT_RESIDUAL_TOL = 1e-8   # largest |x+ - x - dt f(x+, u, p)| (scaled by 1 + |x+|) of an accepted step


def implicit_euler_residual(ode: ca.Function, dt: float) -> ca.Function:
    """``residual(x_next, x, u, p)``: the largest |x+ - x - dt f(x+, u, p)| / (1 + |x+|) of a backward Euler
    step, the check of :func:`implicit_euler_step`'s fixed Newton iterations (see :func:`check_implicit_steps`)."""
    x, u, p = (ca.SX.sym(n, ode.size1_in(i)) for i, n in enumerate(ode.name_in()))
    xn = ca.SX.sym("x_next", x.numel())
    r = (xn - x - dt * ode(xn, u, p)) / (1 + ca.fabs(xn))
    return ca.Function("implicit_euler_residual", [xn, x, u, p], [ca.mmax(ca.fabs(r))],
                       ["x_next", *ode.name_in()], ["residual"])


def check_implicit_steps(ode: ca.Function, dt: float, xs, us, ps) -> float:
    """The largest Newton residual of the backward Euler steps xs[k] -> xs[k+1] (rows; ``us``, ``ps`` per step);
    ArithmeticError when one is above :data:`IMPLICIT_RESIDUAL_TOL` (the fixed Newton iterations did not converge:
    the step's result is not a backward Euler step)."""
    xs, us, ps = (np.atleast_2d(np.asarray(a, float)) for a in (xs, us, ps))
    steps = us.shape[0]
    res = np.asarray(implicit_euler_residual(ode, dt).map(steps)(xs[1:].T, xs[:-1].T, us.T, ps.T)).ravel()
    worst = int(np.argmax(res)) if res.size else 0
    if res.size and not res[worst] <= IMPLICIT_RESIDUAL_TOL:
        raise ArithmeticError(f"implicit Euler step {worst}: Newton residual {res[worst]:.3g} > "
                              f"{IMPLICIT_RESIDUAL_TOL:g} after a fixed number of iterations: shorten dt_s or use rk4")
    return float(res.max(initial=0.0))


def make_step(ode: ca.Function, dt: float, integrator: str = "rk4") -> ca.Function:
    """``integrator``: "rk4", "rk4_<m>" (m RK4 sub-steps of dt/m) or "implicit_euler"."""
    substeps = rk4_substeps(integrator)
    if substeps is not None:
        return rk4_step(ode, dt, substeps)
    if integrator == "implicit_euler":
        return implicit_euler_step(ode, dt)
    raise ValueError(f"integrator {integrator!r}: choose one of {', '.join(INTEGRATORS)}")


def _rk4_jacobians_once(ode_jacobians: ca.Function, dt: float, x, u, p):
    eye = ca.SX.eye(x.numel())
    f, kx, ku = ode_jacobians(x, u, p)
    fs, kxs, kus = [f], [kx], [ku]
    for c in (0.5, 0.5, 1.0):
        f, a, b = ode_jacobians(x + dt * c * fs[-1], u, p)
        kxs.append(a @ (eye + dt * c * kxs[-1]))
        kus.append(a @ (dt * c * kus[-1]) + b)
        fs.append(f)
    w = (1 / 6, 1 / 3, 1 / 3, 1 / 6)
    return (x + dt * sum(wi * fi for wi, fi in zip(w, fs)), eye + dt * sum(wi * ki for wi, ki in zip(w, kxs)),
            dt * sum(wi * ki for wi, ki in zip(w, kus)))


def rk4_step_jacobians(ode_jacobians: ca.Function, dt: float, substeps: int = 1) -> ca.Function:
    """RK4 step (``substeps`` sub-steps) and its Jacobians by the chain rule through the stages, from
    ``ode_jacobians(x, u, p) -> (xdot, dxdot_dx, dxdot_du)`` (equal to AD of the RK4 step)."""
    x, u, p = (ca.SX.sym(n, ode_jacobians.size1_in(i)) for i, n in enumerate(ode_jacobians.name_in()))
    one = ca.SX.sym("xs", x.numel())
    sub = ca.Function("rk4_substep", [one, u, p], list(_rk4_jacobians_once(ode_jacobians, dt / substeps, one, u, p)))
    xn, a, b = x, ca.SX.eye(x.numel()), ca.SX.zeros(x.numel(), u.numel())
    for _ in range(substeps):
        xn, ak, bk = sub(xn, u, p)
        a, b = ak @ a, ak @ b + bk
    return ca.Function("step_jacobians", [x, u, p], [xn, a, b], ode_jacobians.name_in(), ["x_next", "A", "B"])


def step_jacobians(step: ca.Function) -> ca.Function:
    """``step_jacobians(x, u, p) -> (x_next, A, B)`` with A = d x_next/dx, B = d x_next/du."""
    x, u, p = (ca.SX.sym(n, step.size1_in(i)) for i, n in enumerate(step.name_in()))
    xn = step(x, u, p)
    return ca.Function("step_jacobians", [x, u, p], [xn, ca.jacobian(xn, x), ca.jacobian(xn, u)],
                       step.name_in(), ["x_next", "A", "B"])
