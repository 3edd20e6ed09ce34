"""The numpy backend of the DDP passes (solvers/_backends.py's calls): the knots' derivatives in one batched
CasADi call (map), the Riccati recursion and the rollout as numpy loops. Slow; the oracle of the compiled and
VM backends (tests/test_ddp_backends.py)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from ._backends import MODEL_PARTS, knot_functions, penalties
from ._riccati import NumpyOps, backward_step, gradient_step

VECTOR_PARTS = ("lx", "lu", "v_shift")  # the local model's vectors (the other parts are matrices)


class NumpyBackend:
    """Fallback: derivatives in one batched CasADi call (map), Riccati and rollout as numpy loops."""

    name = "numpy"

    def __init__(self, problem, settings, layout):
        knots = knot_functions(problem, settings, layout)
        self.problem, self.settings, self.layout = problem, settings, layout
        self._n_rho = problem.n_constraints + problem.n_terminal_constraints
        self._eval = knots["eval"].map(problem.horizon)
        self._fwd, self._end = knots["fwd"], knots["end"]
        model, (x, u, p, lam, _, rho) = knots["model"], knots["syms"]
        names = list(MODEL_PARTS)
        outs = [ca.densify(model[n]) for n in names]
        self._names = names
        self._second = None
        if knots["second"] is not None:
            v_sym, hxx, huu, hux = knots["second"]
            self._second = ca.Function("second", [x, u, p, v_sym], [hxx, huu, hux])
        derivs = ca.Function("derivs", [x, u, p, lam, rho], [ca.vec(o) for o in outs])
        self._derivs = derivs.map(problem.horizon)
        self._shapes = [o.shape for o in outs]
        self._terminal = knots["terminal"]

    def _knot_data(self, X, U, P, Lam, LamN, rho):
        """Per-knot derivatives (name -> (N, ...) arrays) and the terminal value S_N (arguments transposed)."""
        N = self.problem.horizon
        ng, rho = self.problem.n_constraints, penalties(self._n_rho, rho)
        mats = [np.asarray(m) for m in self._derivs(X[:, :N], U, P[:, :N], Lam, rho[:ng])]
        data = {n: m.T if n in VECTOR_PARTS else m.T.reshape(N, s[1], s[0]).transpose(0, 2, 1)
                for m, s, n in zip(mats, self._shapes, self._names)}
        return data, np.asarray(self._terminal(X[:, N], P[:, N], LamN, rho[ng:])).ravel()

    def evaluate_backward(self, X, U, P, Lam, LamN, rho, reg):
        evaluation = self.evaluate(X, U, P)
        return evaluation, self.backward(X, U, P, Lam, LamN, evaluation[3], rho, reg)

    def gradient(self, X, U, P, Lam, LamN, policy, rho):
        X, U, P, Lam = X.T, U.T, P.T, Lam.T
        pr, lay, N, nx = self.problem, self.layout, self.problem.horizon, self.problem.nx
        data, S = self._knot_data(X, U, P, Lam, LamN, rho)
        costates = np.zeros((N + 1, nx))
        costates[N] = a = S[:nx]
        stat = 0.0
        for t in reversed(range(N)):
            K = lay.feedback(policy[t])
            a, st = gradient_step(NumpyOps, {n: d[t] for n, d in data.items()}, a, K, U[:, t], pr.u_lb, pr.u_ub,
                                  pr.has_box)
            costates[t], stat = a, max(stat, st)
        return stat, costates

    def backward(self, X, U, P, Lam, LamN, C, rho, reg):
        X, U, P, Lam, C = X.T, U.T, P.T, Lam.T, C.T
        pr, lay, N, nx = self.problem, self.layout, self.problem.horizon, self.problem.nx
        data, S = self._knot_data(X, U, P, Lam, LamN, rho)
        a, b, Vxx = S[:nx], S[nx: 2 * nx], S[2 * nx:].reshape(nx, nx).T
        policy = np.zeros((lay.n_policy, N))
        values = np.zeros((lay.n_value, N + 1))
        values[:, N] = S
        for t in reversed(range(N)):
            model = {n: d[t] for n, d in data.items()}
            if self._second is not None:
                model["second_order"] = self._second_order(X[:, t], U[:, t], P[:, t])
            st = backward_step(NumpyOps, model, a, b, Vxx, C[:, t], U[:, t], pr.u_lb, pr.u_ub, reg,
                               self.settings.box_iterations, pr.has_box)
            a, b, Vxx = st["a"], st["b"], st["Vxx"]
            values[:, t] = lay.pack_value(a, b, Vxx)
            policy[:, t] = lay.pack_policy(st)
            if st["pivot"] <= 0:
                policy[lay.pivot, :t] = -1.0
                break
        col = lay.column
        summary = np.array([policy[col("d1")].sum(), policy[col("d2")].sum(), policy[col("stationarity")].max(),
                            policy[col("pivot")].min()])
        return policy.T.copy(), summary, values.T.copy()

    def _second_order(self, x, u, p):
        return lambda v: tuple(np.asarray(h) for h in self._second(x, u, p, v))

    def forward(self, X, U, P, policy, C, alpha):
        X, U, P, policy, C = X.T, U.T, P.T, policy.T, C.T
        N = self.problem.horizon
        Xn, Un = np.empty_like(X), np.empty_like(U)
        G = np.empty((self.problem.n_constraints, N))
        Xn[:, 0], J = X[:, 0], 0.0
        for t in range(N):
            x_next, u, cost, g = (v.full().ravel() for v in
                                  self._fwd(Xn[:, t], X[:, t], U[:, t], policy[:, t], C[:, t], P[:, t], alpha))
            Xn[:, t + 1], Un[:, t], G[:, t] = x_next, u, g
            J += float(cost[0])
        costN, gN = self._end(Xn[:, N], P[:, N])
        return Xn.T.copy(), Un.T.copy(), J + float(costN), G.T.copy(), gN.full().ravel()

    def evaluate(self, X, U, P):
        N = self.problem.horizon
        cost, G, C = self._eval(X[:N].T, U.T, P[:N].T, X[1:].T)
        costN, gN = self._end(X[N], P[N])
        return float(cost.full().sum() + costN), G.full().T.copy(), gN.full().ravel(), C.full().T.copy()
