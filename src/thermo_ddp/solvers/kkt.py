"""First-order optimality (KKT) residuals of a solve, evaluated once for every solver.

On the problem's per-knot functions, with the Lagrangian of the multiple-shooting problem written with
costates lam_k (the value gradients of DDP; IPOPT's dynamics multipliers of x_{k+1} - f_k with the
opposite sign), inequality multipliers mu_k >= 0 (g <= 0) and control-bound multipliers z_k:

    stage    L_k = 0.5 |r(x_k, u_k)|^2 + mu_k' g(x_k, u_k) + lam_{k+1}' f(x_k, u_k)
    terminal L_N = 0.5 |r_N(x_N)|^2 + mu_N' g_N(x_N)

- stationarity: max over knots of |dL_k/dx_k - lam_k| (k >= 1; x_0 is fixed) and |dL_k/du_k + z_k|;
- primal: the largest of |x_0 - x0|, the dynamics gaps |f_k - x_{k+1}|, inequality max(g, 0) and
  control-bound violation;
- complementarity: the largest |mu g| and |z (u - bound)|, and any wrong-signed multiplier |min(mu, 0)|.

A solver that has no costates (or no bound multipliers) of its own leaves them out: the costates are then
the least-squares multipliers of the dynamics at its trajectory and inequality multipliers (the lam_1..lam_N
that minimise the Euclidean norm of every stationarity row; the controls at a bound left out of the fit), and
the bound multipliers the projection z = -dL/du on the controls at a bound (pushing outwards; zero elsewhere).
One sparse solve of the block-tridiagonal normal equations (blocks of nx), not a recursion: the exact adjoint
lam_k = dL_k/dx_k propagated backwards through A_k' grows without bound on a long horizon whose
linearisation is unstable backwards (measured 9.4e17 on a converged 40 kg lift), while the least-squares
residual stays at the size of the reduced gradient |Qu| that DDP's convergence test measures.
"""
from __future__ import annotations

import weakref

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

KKT_KEYS = ("stationarity", "primal", "complementarity")
BOUND_TOL = 1e-9  # a control this close to its bound is at it (for the projected bound multipliers)


def constraint_rows(problem) -> tuple[list[str], list[str]]:
    """The constraint name of every row of the stage g and of the terminal g_N."""
    return ([c.name for c in problem.constraints for _ in range(c.size)],
            [c.name for c in problem.terminal_constraints for _ in range(c.size)])


class _KnotFunctions:
    """The residuals' per-knot CasADi functions of one problem structure and their maps per horizon."""

    def __init__(self, problem):
        F = problem.functions
        sym = F.symbolic
        x, u, p = sym.sym("x", problem.nx), sym.sym("u", problem.nu), sym.sym("p", problem.n_params)
        mu, lam_next = sym.sym("mu", problem.n_constraints), sym.sym("lam_next", problem.nx)
        xn, muN = sym.sym("x_next", problem.nx), sym.sym("muN", problem.n_terminal_constraints)
        f, g = F.step(x, u, p), F.stage_constraint(x, u, p)
        L0 = 0.5 * ca.sumsqr(F.stage_residual(x, u, p)) + ca.dot(mu, g)
        L = L0 + ca.dot(lam_next, f)
        self.stage = ca.Function("kkt_stage", [x, u, p, mu, lam_next, xn], [ca.gradient(L, x), ca.gradient(L, u), g,
                                                                            f - xn])
        # the stationarity rows are affine in lam_next: [Lx; Lu] = [Lx; Lu](lam_next = 0) + [A'; B'] lam_next
        # (column-major vec of A, B: the row-major A', B'). One function for the fit: the dynamics evaluated once
        # and no adjoint sweep with a zero seed (measured on the 40 kg 140 °C plan, N = 645: 30 -> 16 ms)
        self.fit = ca.Function("kkt_fit", [x, u, p, mu, xn], [ca.gradient(L0, x), ca.gradient(L0, u), g, f - xn,
                                                               ca.vec(ca.jacobian(f, x)), ca.vec(ca.jacobian(f, u))])
        gN = F.terminal_constraint(x, p)
        LN = 0.5 * ca.sumsqr(F.terminal_residual(x, p)) + ca.dot(muN, gN)
        self.terminal = ca.Function("kkt_terminal", [x, p, muN], [ca.gradient(LN, x), gN])
        self.maps: dict[tuple[str, int], ca.Function] = {}


# per problem structure (its ProblemFunctions, shared by every horizon): a solver built per plan builds none
_KNOTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


class KKTEvaluator:
    """The residuals of :data:`KKT_KEYS` at an iterate; its functions built once per problem structure (any
    horizon, every evaluator of that structure)."""

    def __init__(self, problem):
        self.problem = problem
        knots = _KNOTS.get(problem.functions)
        if knots is None:
            knots = _KNOTS[problem.functions] = _KnotFunctions(problem)
        self._knots = knots
        self._terminal = knots.terminal
        self._maps = knots.maps

    def _mapped(self, name: str, N: int):
        """The knot function ``name`` ("stage" or "fit") mapped over N knots (built once per structure and N)."""
        if (name, N) not in self._maps:
            self._maps[name, N] = getattr(self._knots, name).map(N)
        return self._maps[name, N]

    def costates(self, xs, us, params, mu, muN) -> np.ndarray:
        """The least-squares multipliers of the dynamics (N+1, nx; row 0 unused: x_0 is fixed) at the trajectory
        with inequality multipliers mu (N, ng), muN (ngN): argmin over lam_1..lam_N of the stationarity rows'
        Euclidean norm, the rows of controls at a bound left out."""
        return self._fitted(xs, us, params, mu, muN)[0]

    def _fitted(self, xs, us, params, mu, muN):
        """(:meth:`costates`, the stage rows (Lx, Lu, g, gaps) at them): the rows are affine in the costates, so
        one evaluation of the knots at lam = 0 and of the Jacobians gives both."""
        pr, N = self.problem, len(us)
        nx, nu = pr.nx, pr.nu
        *rows, A, B = self._mapped("fit", N)(xs[:-1].T, us.T, params[:-1].T, mu.T, xs[1:].T)
        Lx, Lu, G, C = (np.asarray(v).T for v in rows)
        At, Bt = (np.asarray(v).T.reshape(N, n, nx) for v, n in zip((A, B), (nx, nu)))
        LxN = np.asarray(self._terminal(xs[N], params[N], muN)[0]).ravel()
        free = ~_at_bound(us, pr.u_lb, pr.u_ub)
        M, b = _stationarity_system(At, Bt, free, np.concatenate([(Lu * free).ravel(), Lx[1:].ravel(), LxN]))
        lam = np.asarray(spla.spsolve((M.T @ M).tocsc(), -(M.T @ b))).reshape(N, nx)
        rows = (Lx + np.einsum("kij,kj->ki", At, lam), Lu + np.einsum("kij,kj->ki", Bt, lam), G, C)
        return np.vstack([np.zeros(nx), lam]), rows

    def residuals(self, xs, us, params, mu, muN, x0, costates=None, bound_multipliers=None) -> dict[str, float]:
        """The KKT residuals at the trajectory from ``x0``; ``costates`` (N+1, nx) and ``bound_multipliers``
        (N, nu) when the solver has them."""
        pr = self.problem
        xs, us, params = (np.asarray(a, dtype=float) for a in (xs, us, params))
        mu = np.asarray(mu, dtype=float).reshape(len(us), pr.n_constraints)
        muN = np.asarray(muN, dtype=float).ravel()
        if costates is None:
            costates, (Lx, Lu, G, C) = self._fitted(xs, us, params, mu, muN)
        else:
            stage = self._mapped("stage", len(us))
            Lx, Lu, G, C = (np.asarray(v).T for v in stage(xs[:-1].T, us.T, params[:-1].T, mu.T, costates[1:].T,
                                                            xs[1:].T))
        LxN, GN = (np.asarray(v).ravel() for v in self._terminal(xs[-1], params[-1], muN))
        lb, ub = np.broadcast_to(pr.u_lb, us.shape), np.broadcast_to(pr.u_ub, us.shape)
        z = _projected_bound_multipliers(Lu, us, lb, ub) if bound_multipliers is None else bound_multipliers
        stat = [np.abs(Lu + z), np.abs(Lx[1:] - costates[1:-1]), np.abs(LxN - costates[-1])]
        primal = [np.abs(xs[0] - x0), np.abs(C), np.maximum(G, 0.0), np.maximum(GN, 0.0), us - ub, lb - us]
        z_lo, z_up = np.minimum(z, 0.0), np.maximum(z, 0.0)
        comp = [np.abs(mu * G), np.abs(muN * GN), np.maximum(-mu, 0.0), np.maximum(-muN, 0.0),
                np.abs(z_lo * np.where(np.isfinite(lb), us - lb, 0.0)),
                np.abs(z_up * np.where(np.isfinite(ub), ub - us, 0.0))]
        return {"stationarity": _largest(stat), "primal": _largest(primal), "complementarity": _largest(comp)}


def _at_bound(us, lb, ub) -> np.ndarray:
    """(N, nu): the controls within :data:`BOUND_TOL` of a bound."""
    lb, ub = np.broadcast_to(lb, us.shape), np.broadcast_to(ub, us.shape)
    return (us <= lb + BOUND_TOL) | (us >= ub - BOUND_TOL)


def _stationarity_system(At, Bt, free, b):
    """The stationarity rows b + M lam (lam = [lam_1; ..; lam_N]): the controls' rows B_k' lam_{k+1} (zero
    where a control is at a bound: its multiplier takes the row), then the states' rows A_k' lam_{k+1} - lam_k
    (k = 1..N-1) and -lam_N."""
    N, nu, nx = Bt.shape
    k, i, j = np.indices((N, nu, nx))
    u_rows, u_cols, u_vals = k * nu + i, k * nx + j, Bt * free[:, :, None]
    k, i, j = np.indices((N - 1, nx, nx))
    a_rows, a_cols = N * nu + k * nx + i, (k + 1) * nx + j
    diag = np.arange(N * nx)
    rows = np.concatenate([u_rows.ravel(), a_rows.ravel(), N * nu + diag])
    cols = np.concatenate([u_cols.ravel(), a_cols.ravel(), diag])
    vals = np.concatenate([u_vals.ravel(), At[1:].ravel(), -np.ones(N * nx)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(N * (nu + nx), N * nx)), b


def _projected_bound_multipliers(Lu, us, lb, ub):
    """z = -dL/du where a control at its bound is pushed outwards (z <= 0 at the lower bound, >= 0 at the
    upper), zero elsewhere: the bound multipliers that make those rows stationary."""
    at_lo = (us <= lb + BOUND_TOL) & (Lu > 0)
    at_hi = (us >= ub - BOUND_TOL) & (Lu < 0)
    return np.where(at_lo | at_hi, -Lu, 0.0)


def _largest(parts) -> float:
    values = [float(np.max(p)) for p in parts if np.size(p)]
    value = max(values, default=0.0)
    return value if np.isfinite(value) else float("inf")
