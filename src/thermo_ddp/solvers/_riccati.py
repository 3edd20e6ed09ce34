"""One knot of the DDP backward pass, written once for CasADi SX (compiled, mapaccum) and numpy.

Notation (multiple shooting, crocoddyl-FDDP-like): the linearised dynamics around the current
iterate are dx' = A dx + B du + c with the gap c = f(x_k, u_k, p_k) - x_{k+1}. The value
gradient is carried in two parts, Vx = a + b: ``a`` collects the cost-gradient terms, ``b``
the terms proportional to the step (gaps and feedforward). With the policy du = alpha k + K dx
and gaps closed by a fraction alpha, the quadratic model of the cost change is exactly
alpha*d1 + 0.5*alpha^2*d2 (for a linear-quadratic problem), with
d1 = sum a'c + Qu0'k and d2 = sum 2b'c + c'Vxx c + 2 (B'(b + Vxx c))'k + k'Quu k.

Control bounds: box-QP per knot, min 0.5 du'H du + g'du on lo <= du <= hi, by projected Newton
(Bertsekas 1982, "Projected Newton methods for optimization problems with simple constraints"; as in
Box-DDP, Tassa, Mansard, Todorov, ICRA 2014): from the clipped unconstrained Newton step, up to
``box_iterations`` steps, each a Newton step on the free set (controls not held at a bound by their
gradient) searched along the projection arc clip(du + alpha d) with the Armijo test of Bertsekas
(alpha = 1, 1/2, ..., 1/2^(BOX_HALVINGS-1): the largest that passes). A step from a point that satisfies the
QP's own KKT conditions is zero, so the iteration stops there; one control is exact after the clip alone.
Feedback rows of clamped controls are zero.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

EPS_BOUND = 1e-12
BOX_HALVINGS = 4   # step lengths tried along the projection arc per projected-Newton step
BOX_ARMIJO = 1e-4  # sufficient decrease along the arc (Bertsekas 1982, eq. 18)


class SymOps:
    """Symbolic operations (CasADi SX or MX); linear solves by an unrolled LDL^T factorisation."""

    @staticmethod
    def eye(n):
        return ca.DM.eye(n)

    @staticmethod
    def diag(v):
        return ca.diag(v)

    @staticmethod
    def le(a, b):
        return a <= b

    @staticmethod
    def gt(a, b):
        return a > b

    @staticmethod
    def clip(v, lo, hi):
        return ca.fmin(ca.fmax(v, lo), hi)

    @staticmethod
    def hcat(v, m):
        return ca.horzcat(v, m)

    @staticmethod
    def where(cond, a, b):
        return ca.if_else(cond, a, b)

    @staticmethod
    def fmin(a, b):
        return ca.fmin(a, b)

    @staticmethod
    def max_abs(v):
        return ca.mmax(ca.fabs(v)) if v.numel() else ca.DM(0)

    @staticmethod
    def sym(m):
        return 0.5 * (m + m.T)

    @staticmethod
    def solve(H, rhs):
        """Solve H X = rhs by LDL^T without pivoting; also return the smallest pivot."""
        n = H.shape[0]
        L = [[None] * n for _ in range(n)]
        d = []
        for j in range(n):
            dj = H[j, j] - sum(L[j][m] ** 2 * d[m] for m in range(j))
            d.append(dj)
            for i in range(j + 1, n):
                L[i][j] = (H[i, j] - sum(L[i][m] * L[j][m] * d[m] for m in range(j))) / dj
        y = []
        for i in range(n):
            y.append(rhs[i, :] - sum(L[i][m] * y[m] for m in range(i)))
        x = [None] * n
        for i in reversed(range(n)):
            x[i] = y[i] / d[i] - sum(L[m][i] * x[m] for m in range(i + 1, n))
        min_pivot = d[0]
        for dj in d[1:]:
            min_pivot = ca.fmin(min_pivot, dj)
        return ca.vertcat(*x), min_pivot


class NumpyOps:
    """The same operations on numpy arrays (vectors are 1-D)."""

    @staticmethod
    def eye(n):
        return np.eye(n)

    @staticmethod
    def diag(v):
        return np.diag(v)

    @staticmethod
    def le(a, b):
        return (a <= b).astype(float)

    @staticmethod
    def gt(a, b):
        return (a > b).astype(float)

    @staticmethod
    def clip(v, lo, hi):
        return np.minimum(np.maximum(v, lo), hi)

    @staticmethod
    def hcat(v, m):
        return np.column_stack([v, m])

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def fmin(a, b):
        return np.minimum(a, b)

    @staticmethod
    def max_abs(v):
        return float(np.max(np.abs(v))) if v.size else 0.0

    @staticmethod
    def sym(m):
        return 0.5 * (m + m.T)

    @staticmethod
    def solve(H, rhs):
        try:
            L = np.linalg.cholesky(H)
        except np.linalg.LinAlgError:
            return np.zeros_like(rhs), -1.0
        x = np.linalg.solve(L.T, np.linalg.solve(L, rhs))
        return x, float(np.min(np.diag(L)) ** 2)


def _clamped(ops, du, grad, lo, hi):
    at_lo = ops.le(du, lo + EPS_BOUND) * ops.gt(grad, 0)
    at_hi = ops.le(hi - EPS_BOUND, du) * ops.gt(-grad, 0)
    return ops.fmin(at_lo + at_hi, 1)


def _box_qp(ops, H, g, Hux, lo, hi, iterations):
    """min 0.5 du'H du + g'du, lo <= du <= hi; returns du, feedback gain, min pivot of H."""
    sol, pivot = ops.solve(H, ops.hcat(-g, -Hux))
    du = ops.clip(sol[:, 0], lo, hi)
    if H.shape[0] > 1:
        for _ in range(iterations):
            du = _arc_search(ops, H, g, du, _free_newton(ops, H, g, Hux, du, lo, hi)[2], lo, hi)
    return du, _free_newton(ops, H, g, Hux, du, lo, hi)[1], pivot


def _qp_value(H, g, du):
    return 0.5 * (du.T @ H @ du) + g.T @ du


def _arc_search(ops, H, g, du, target, lo, hi):
    """The projected-Newton step from du towards the free-set minimiser ``target``: the largest alpha of
    1, 1/2, ... whose point clip(du + alpha (target - du)) passes Bertsekas' Armijo test
    q(new) <= q(du) + BOX_ARMIJO grad'(new - du); du itself when none does."""
    grad, q0, d = H @ du + g, _qp_value(H, g, du), target - du
    best = du
    for i in reversed(range(BOX_HALVINGS)):  # the largest passing step is assigned last
        trial = ops.clip(du + 0.5 ** i * d, lo, hi)
        ok = _qp_value(H, g, trial) <= q0 + BOX_ARMIJO * (grad.T @ (trial - du))
        best = ops.where(ok, trial, best)
    return best


def _free_newton(ops, H, g, Hux, du, lo, hi):
    """Newton step on the controls not clamped at du: the clipped and the unclipped minimiser over the free set
    (clamped controls kept), and its feedback gain (clamped rows zero)."""
    clamped = _clamped(ops, du, g + H @ du, lo, hi)
    M = ops.diag(1 - clamped)
    fixed = clamped * du
    Hm = M @ H @ M + ops.eye(H.shape[0]) - M
    sol, _ = ops.solve(Hm, ops.hcat(-(M @ (g + H @ fixed)), -(M @ Hux)))
    target = M @ sol[:, 0] + fixed
    return ops.clip(target, lo, hi), sol[:, 1:], target


def backward_step(ops, model, a, b, Vxx, c, u, lb, ub, reg, box_iterations, has_box):
    """One knot of the backward pass.

    ``model`` holds A, B, lx, lu, lxx, luu, lux, v_shift at the knot and, for full DDP, a callable
    ``second_order(v)`` returning (Hxx, Huu, Hux) of v'f, called with the value gradient plus ``v_shift`` (the
    gradient of the knot's terms in its end state, :func:`knot_model`). Returns a dict with the value
    parts a, b, Vxx at this knot, the policy k, K, the smallest pivot of the regularised Quu,
    this knot's d1, d2 terms and the projected stationarity |Qu0| of the controls.
    """
    A, B = model["A"], model["B"]
    Vc = Vxx @ c
    w = b + Vc
    v = a + w
    Qx0, Qu0 = model["lx"] + A.T @ a, model["lu"] + B.T @ a
    Qxx = model["lxx"] + A.T @ Vxx @ A
    Quu = model["luu"] + B.T @ Vxx @ B
    Qux = model["lux"] + B.T @ Vxx @ A
    if model.get("second_order") is not None:
        Hxx, Huu, Hux = model["second_order"](v + model["v_shift"])
        Qxx, Quu, Qux = Qxx + Hxx, Quu + Huu, Qux + Hux
    Qu = Qu0 + B.T @ w
    nu = Quu.shape[0]
    H = ops.sym(Quu) + reg * ops.eye(nu)
    if has_box:
        k, K, pivot = _box_qp(ops, H, Qu, Qux, lb - u, ub - u, box_iterations)
    else:
        sol, pivot = ops.solve(H, ops.hcat(-Qu, -Qux))
        k, K = sol[:, 0], sol[:, 1:]
    KtQuu = K.T @ Quu
    a_new = Qx0 + K.T @ Qu0
    b_new = A.T @ w + K.T @ (B.T @ w) + KtQuu @ k + Qux.T @ k
    Vxx_new = ops.sym(Qxx + KtQuu @ K + K.T @ Qux + Qux.T @ K)
    d1 = a.T @ c + Qu0.T @ k
    d2 = 2 * (b.T @ c) + c.T @ Vc + 2 * ((B.T @ w).T @ k) + k.T @ Quu @ k
    stationarity = _stationarity(ops, Qu0, u, lb, ub, has_box)
    return {"a": a_new, "b": b_new, "Vxx": Vxx_new, "k": k, "K": K, "pivot": pivot,
            "d1": d1, "d2": d2, "stationarity": stationarity}


def gradient_step(ops, model, a, K, u, lb, ub, has_box):
    """The first-order part of :func:`backward_step` with given feedback gains ``K``: the value
    gradient a = lx + A'a' + K'Qu0 and the projected stationarity |Qu0| (no second derivatives)."""
    Qu0 = model["lu"] + model["B"].T @ a
    return first_order_step(ops, model["lx"] + model["A"].T @ a, Qu0, K, u, lb, ub, has_box)


def first_order_step(ops, Lx, Qu0, K, u, lb, ub, has_box):
    """:func:`gradient_step` from Lx = lx + A'a and Qu0 = lu + B'a (e.g. one reverse sweep of the knot's
    Lagrangian l + a'f, without the Jacobians A, B)."""
    return Lx + K.T @ Qu0, _stationarity(ops, Qu0, u, lb, ub, has_box)


def _stationarity(ops, Qu0, u, lb, ub, has_box):
    return ops.max_abs(_projected(ops, Qu0, u, lb, ub)) if has_box else ops.max_abs(Qu0)


def _projected(ops, grad, u, lb, ub):
    """Gradient with the components pushing against an active bound removed."""
    at_lo = ops.le(u, lb + EPS_BOUND) * ops.gt(grad, 0)
    at_hi = ops.le(ub - EPS_BOUND, u) * ops.gt(-grad, 0)
    return grad * (1 - ops.fmin(at_lo + at_hi, 1))


def knot_model(F, x, u, p, lam, rho, full: bool, terminal: bool = False, margin: float = 0.0):
    """Symbolic local model of the augmented-Lagrangian cost (and dynamics) at one knot.

    Cost 0.5|r|^2 + sum (max(0, lam + rho g)^2 - lam^2) / (2 rho) (PHR augmented Lagrangian
    for g <= 0, one penalty rho per row of g). Gauss-Newton Hessians J'J and Jg' diag(rho active) Jg; with ``full`` the
    exact Hessians (plus the residual and multiplier curvature terms). A row counts as active in the Hessian
    when it is within ``margin`` (its own units) of its kink, g > -lam/rho - margin: a step that crosses the kink
    of a row just short of it meets the penalty's curvature rho, which the model otherwise misses (measured on
    the lift's probes at rho = 1e5: a row 8e-7 short of its kink made a descent direction fail every step
    down to 1e-4, ten regularisation increases of 14 forward passes each). A negative entry -m of ``lam`` marks a
    row (multiplier m) modelled as active whatever its value: curvature rho Jg'Jg and the gradient (m + rho g) Jg
    of its quadratic piece (a semismooth Newton step with that active set; the rows a line search crossed,
    ``_augmented_lagrangian.flagged``, DDPSolver._step).

    Terms that read the knot's end state x+ = f(x, u) (``F.stage_terms``) are modelled in y = (x, u, x+) and
    mapped by the chain rule, dy = T dz with T = [I; A B]: gradient T' l_y, Hessian T' l_yy T, and (``full``) their
    curvature through f, sum_i (l_x+)_i d2 f_i, joins the dynamics' second-order term as ``v_shift`` = l_x+ added
    to its value gradient (:func:`backward_step`). No derivative of the composition is taken: it would
    differentiate the integrator again in every row (the lift's fused Riccati step with the end-of-knot voltage
    rows: 11,346 instructions that way, 7,940 by the chain rule, 7,696 without those rows).
    """
    nx = x.numel()
    if terminal:
        grad, hess = _cost_model(F.terminal_residual(x, p), F.terminal_constraint(x, p), x, lam, rho, full, margin)
        return {"lx": grad[:nx], "lxx": hess[:nx, :nx]}
    z = ca.vertcat(x, u)
    f = F.step(x, u, p)
    if F.step_jacobians is not None:  # the model's own (e.g. analytic) derivatives
        A, B = F.step_jacobians(x, u, p)
    else:
        Jf = ca.jacobian(f, z)  # one AD pass for [A B]
        A, B = Jf[:, :nx], Jf[:, nx:]
    shift = type(x)(nx, 1)
    if F.stage_terms is None:
        grad, hess = _cost_model(F.stage_residual(x, u, p), F.stage_constraint(x, u, p), z, lam, rho, full, margin)
    else:
        xn = type(x).sym("x_next", nx)
        y_grad, y_hess = _cost_model(*F.stage_terms(x, u, p, xn), ca.vertcat(z, xn), lam, rho, full, margin)
        y_grad, y_hess = ca.substitute([y_grad, y_hess], [xn], [f])
        T = ca.vertcat(ca.DM.eye(z.numel()), ca.horzcat(A, B))
        grad, hess = T.T @ y_grad, T.T @ y_hess @ T
        if full:
            shift = y_grad[z.numel():]
    out = {"lx": grad[:nx], "lxx": hess[:nx, :nx], "lu": grad[nx:], "luu": hess[nx:, nx:], "lux": hess[nx:, :nx],
           "A": A, "B": B, "v_shift": shift}
    if full:
        v = type(x).sym("v", nx)
        Hf = ca.hessian(ca.dot(v, f), z)[0]
        out["second_order_sym"] = (v, Hf[:nx, :nx], Hf[nx:, nx:], Hf[nx:, :nx])
    return out


def _cost_model(r, g, z, lam, rho, full: bool, margin: float):
    """Gradient and Hessian in ``z`` of 0.5|r|^2 plus the PHR terms of the rows g (see :func:`knot_model`)."""
    Jr = ca.jacobian(r, z)
    grad = Jr.T @ r
    hess = ca.hessian(0.5 * ca.sumsqr(r), z)[0] if full else Jr.T @ Jr
    if g.numel():
        Jg = ca.jacobian(g, z)
        flagged, lam = lam < 0, ca.fabs(lam)  # a negative entry: a row modelled as active (see knot_model)
        mult = ca.if_else(flagged, lam + rho * g, ca.fmax(0, lam + rho * g))
        active = ca.logic_or(ca.logic_or(lam + rho * g > 0, flagged), ca.logic_and(lam > 0, g > -margin))
        grad += Jg.T @ mult
        hess += Jg.T @ ca.diag(rho * active) @ Jg
        if full:
            mu = type(z).sym("mu", g.numel())
            hess += ca.substitute(ca.hessian(ca.dot(mu, g), z)[0], mu, mult)
    return grad, hess
