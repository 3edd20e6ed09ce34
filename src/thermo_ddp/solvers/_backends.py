"""Batched evaluation of the DDP passes: CasADi mapaccum, compiled C, or numpy loops.

Every backend offers the same four calls on whole trajectories, as C-contiguous numpy arrays
with one row per knot (X (N+1, nx), U (N, nu), P (N+1, np), Lam (N, ng), C (N, nx) gaps):
  backward(X, U, P, Lam, LamN, C, rho, reg) -> (policy (N, n_policy), summary [d1, d2, stat, pivot],
                                                values (N+1, n_value))
  evaluate_backward(X, U, P, Lam, LamN, rho, reg) -> ((J, G, GN, C), backward's outputs): both in
                                                one pass over the knots (the first pass of a solve)
  gradient(X, U, P, Lam, LamN, policy, rho) -> (stat, costates (N+1, nx)): first order only, with
                                                the gains of ``policy`` (a gap-free iterate)
  forward(X, U, P, policy, C, alpha)        -> (Xn, Un, J, G, GN)
  evaluate(X, U, P)                          -> (J, G, GN, C)
A row-per-knot C array is exactly CasADi's column-major (dim, knots) matrix, so the "casadi"
and "codegen" backends pass the arrays' memory to CasADi without copies (Function.buffer)
and make one call per pass (no Python loop over knots).
"""
from __future__ import annotations

import logging
import subprocess

import casadi as ca
import numpy as np

from ..codegen import compile_functions
from . import _pass_cache
from ._riccati import NumpyOps, SymOps, backward_step, gradient_step, knot_model

log = logging.getLogger(__name__)
# Common-subexpression elimination in the per-knot functions: the dynamics, its Jacobians and its
# second-order tensor share most of their work (full DDP back knot of the rk4_4 lift: 10333 -> 7028
# instructions, identical results).
_CSE = {"cse": True}


class Layout:
    """Packing of per-knot values: value = [a; b; vec(Vxx)], policy = [k; vec(K); pivot; d1; d2; stat]."""

    def __init__(self, nx, nu):
        self.nx, self.nu = nx, nu
        self.n_value = 2 * nx + nx * nx
        self.n_policy = nu + nu * nx + 4

    def gains(self, policy: np.ndarray):
        """k (N, nu) and K (N, nu, nx) from a policy array (casadi vec is column-major)."""
        nx, nu = self.nx, self.nu
        k = policy[:, :nu].copy()
        K = policy[:, nu: nu + nu * nx].reshape(-1, nx, nu).transpose(0, 2, 1).copy()
        return k, K

    def costates(self, values: np.ndarray) -> np.ndarray:
        """Value gradients Vx = a + b at every knot, (N+1, nx)."""
        return values[:, : self.nx] + values[:, self.nx: 2 * self.nx]


def _symbolic_step(problem, settings, layout):
    """CasADi functions for one knot: backward, terminal, forward, evaluation."""
    F = problem.functions
    sym = F.symbolic
    x, u, p = sym.sym("x", problem.nx), sym.sym("u", problem.nu), sym.sym("p", problem.n_params)
    lam, lamN = sym.sym("lam", problem.n_constraints), sym.sym("lamN", problem.n_terminal_constraints)
    rho = sym.sym("rho")
    model = knot_model(F, x, u, p, lam, rho, settings.full_second_order)
    second = model.pop("second_order_sym", None)
    knots = {"model": model, "second": second, "syms": (x, u, p, lam, lamN, rho)}
    knots["back"], knots["terminal"] = _backward_knot(problem, settings, layout, knots)
    knots["grad"] = _gradient_knot(problem, layout, knots)
    knots["fwd"] = _forward_knot(problem, layout, x, p)
    knots["eval"], knots["end"] = _evaluation_knots(problem, x, u, p)
    knots["back_eval"] = _back_eval_knot(problem, layout, knots)
    return knots


def _backward_knot(problem, settings, layout, knots):
    """One Riccati step (with the knot's derivatives) and the terminal value function."""
    F, nx = problem.functions, problem.nx
    x, u, p, lam, lamN, rho = knots["syms"]
    reg, c, S = F.symbolic.sym("reg"), F.symbolic.sym("c", nx), F.symbolic.sym("S", layout.n_value)
    model = dict(knots["model"])
    if knots["second"] is not None:
        v_sym, hxx, huu, hux = knots["second"]
        model["second_order"] = lambda v: tuple(ca.substitute(h, v_sym, v) for h in (hxx, huu, hux))
    a, b, Vxx = S[:nx], S[nx: 2 * nx], ca.reshape(S[2 * nx:], nx, nx)
    st = backward_step(SymOps, model, a, b, Vxx, c, u, ca.DM(problem.u_lb), ca.DM(problem.u_ub), reg,
                       settings.box_iterations, problem.has_box)
    S_prev = ca.vertcat(st["a"], st["b"], ca.vec(st["Vxx"]))
    policy = ca.vertcat(st["k"], ca.vec(st["K"]), st["pivot"], st["d1"], st["d2"], st["stationarity"])
    back = ca.Function("ddp_back_knot", [S, x, u, p, lam, c, rho, reg], [S_prev, policy],
                       ["S", "x", "u", "p", "lam", "c", "rho", "reg"], ["S_prev", "policy"], _CSE)
    term = knot_model(F, x, None, p, lamN, rho, settings.full_second_order, terminal=True)
    S_N = ca.vertcat(term["lx"], ca.DM.zeros(nx), ca.vec(ca.densify(term["lxx"])))
    terminal = ca.Function("ddp_back_terminal", [x, p, lamN, rho], [S_N], ["x", "p", "lamN", "rho"], ["S"], _CSE)
    return back, terminal


def _back_eval_knot(problem, layout, knots):
    """The backward knot with the gap c = f(x, u, p) - x_next computed inside; also the knot's cost and g
    (CSE shares the dynamics and residuals between the two)."""
    sym = problem.functions.symbolic
    x, u, p, lam, _, rho = knots["syms"]
    S, xn, reg = sym.sym("S", layout.n_value), sym.sym("x_next", problem.nx), sym.sym("reg")
    cost, g, gap = knots["eval"](x, u, p, xn)
    S_prev, policy = knots["back"](S, x, u, p, lam, gap, rho, reg)
    return ca.Function("ddp_back_eval_knot", [S, x, u, p, lam, xn, rho, reg], [S_prev, policy, cost, g, gap],
                       ["S", "x", "u", "p", "lam", "x_next", "rho", "reg"], ["S_prev", "policy", "cost", "g", "gap"],
                       _CSE)


def _gradient_knot(problem, layout, knots):
    """First-order backward step with given gains (see _riccati.gradient_step)."""
    nx, nu = problem.nx, problem.nu
    x, u, p, lam, _, rho = knots["syms"]
    a, pol = problem.functions.symbolic.sym("a", nx), problem.functions.symbolic.sym("policy", layout.n_policy)
    K = ca.reshape(pol[nu: nu + nu * nx], nu, nx)
    a_prev, stat = gradient_step(SymOps, knots["model"], a, K, u, ca.DM(problem.u_lb), ca.DM(problem.u_ub),
                                 problem.has_box)
    return ca.Function("ddp_grad_knot", [a, x, u, p, lam, rho, pol], [a_prev, stat],
                       ["a", "x", "u", "p", "lam", "rho", "policy"], ["a_prev", "stat"], _CSE)


def _forward_knot(problem, layout, x, p):
    """Nonlinear rollout step: u = clip(u_ref + alpha k + K dx), x' = f(x, u) - (1 - alpha) c."""
    F, nx, nu = problem.functions, problem.nx, problem.nu
    sym = F.symbolic
    xr, ur, alpha, c = sym.sym("x_ref", nx), sym.sym("u_ref", nu), sym.sym("alpha"), sym.sym("c", nx)
    pol = sym.sym("policy", layout.n_policy)
    K = ca.reshape(pol[nu: nu + nu * nx], nu, nx)
    u_new = ur + alpha * pol[:nu] + K @ (x - xr)
    if problem.has_box:
        u_new = ca.fmin(ca.fmax(u_new, ca.DM(problem.u_lb)), ca.DM(problem.u_ub))
    x_next = F.step(x, u_new, p) - (1 - alpha) * c
    stage = ca.vertcat(u_new, 0.5 * ca.sumsqr(F.stage_residual(x, u_new, p)), F.stage_constraint(x, u_new, p))
    return ca.Function("ddp_fwd_knot", [x, xr, ur, pol, c, p, alpha], [x_next, stage],
                       ["x", "x_ref", "u_ref", "policy", "c", "p", "alpha"], ["x_next", "stage"], _CSE)


def _evaluation_knots(problem, x, u, p):
    """Cost, constraints and gap of one knot; cost and constraints of the terminal knot."""
    F = problem.functions
    xn = F.symbolic.sym("x_next", problem.nx)
    ev = ca.Function("ddp_eval_knot", [x, u, p, xn],
                     [0.5 * ca.sumsqr(F.stage_residual(x, u, p)), F.stage_constraint(x, u, p), F.step(x, u, p) - xn],
                     ["x", "u", "p", "x_next"], ["cost", "g", "gap"], _CSE)
    end = ca.Function("ddp_terminal", [x, p], [0.5 * ca.sumsqr(F.terminal_residual(x, p)), F.terminal_constraint(x, p)],
                      ["x", "p"], ["cost", "g"], _CSE)
    return ev, end


def _reverse(M, N):
    return M[:, list(range(N - 1, -1, -1))]


def build_passes(problem, settings, layout):
    """MX functions for the whole horizon: one call per pass (mapaccum over knots)."""
    knots = _symbolic_step(problem, settings, layout)
    nx, nu, n_p, N = problem.nx, problem.nu, problem.n_params, problem.horizon
    ng, ngN = problem.n_constraints, problem.n_terminal_constraints
    X, U, P = ca.MX.sym("X", nx, N + 1), ca.MX.sym("U", nu, N), ca.MX.sym("P", n_p, N + 1)
    Lam, LamN, C = ca.MX.sym("Lam", ng, N), ca.MX.sym("LamN", ngN), ca.MX.sym("C", nx, N)
    rho, reg, alpha = ca.MX.sym("rho"), ca.MX.sym("reg"), ca.MX.sym("alpha")
    Pol = ca.MX.sym("policy", layout.n_policy, N)

    S_N = knots["terminal"](X[:, N], P[:, N], LamN, rho)
    knot_args = (_reverse(X[:, :N], N), _reverse(U, N), _reverse(P[:, :N], N), _reverse(Lam, N))
    S_rev, pol_rev = knots["back"].mapaccum("ddp_back_acc", N)(S_N, *knot_args, _reverse(C, N), rho, reg)
    backward = ca.Function("ddp_backward", [X, U, P, Lam, LamN, C, rho, reg],
                           _backward_outputs(layout, S_rev, pol_rev, S_N),
                           ["X", "U", "P", "Lam", "LamN", "C", "rho", "reg"], ["policy", "summary", "values"])
    S_rev, pol_rev, cost_rev, g_rev, gap_rev = knots["back_eval"].mapaccum("ddp_back_eval_acc", N)(
        S_N, *knot_args, _reverse(X[:, 1:], N), rho, reg)
    costN, gN = knots["end"](X[:, N], P[:, N])
    evaluate_backward = ca.Function(
        "ddp_evaluate_backward", [X, U, P, Lam, LamN, rho, reg],
        [*_backward_outputs(layout, S_rev, pol_rev, S_N), ca.sum2(_reverse(cost_rev, N)) + costN,
         _reverse(g_rev, N), gN, _reverse(gap_rev, N)],
        ["X", "U", "P", "Lam", "LamN", "rho", "reg"], ["policy", "summary", "values", "J", "G", "GN", "C"])

    a_rev, stat = knots["grad"].mapaccum("ddp_grad_acc", N)(S_N[:nx], *knot_args, rho, _reverse(Pol, N))
    gradient = ca.Function("ddp_gradient", [X, U, P, Lam, LamN, Pol, rho],
                           [ca.mmax(stat), ca.horzcat(_reverse(a_rev, N), S_N[:nx])],
                           ["X", "U", "P", "Lam", "LamN", "policy", "rho"], ["stat", "costates"])

    fwd = knots["fwd"].mapaccum("ddp_fwd_acc", N)
    X_new, stage = fwd(X[:, 0], X[:, :N], U, Pol, C, P[:, :N], alpha)
    Xn = ca.horzcat(X[:, 0], X_new)
    costN, gN = knots["end"](Xn[:, N], P[:, N])
    forward = ca.Function("ddp_forward", [X, U, P, Pol, C, alpha],
                          [Xn, stage[:nu, :], ca.sum2(stage[nu, :]) + costN, stage[nu + 1:, :], gN],
                          ["X", "U", "P", "policy", "C", "alpha"], ["X_new", "U_new", "J", "G", "GN"])

    cost, G, gaps = knots["eval"].map(N)(X[:, :N], U, P[:, :N], X[:, 1:])
    costN, gN = knots["end"](X[:, N], P[:, N])
    evaluate = ca.Function("ddp_evaluate", [X, U, P], [ca.sum2(cost) + costN, G, gN, gaps],
                           ["X", "U", "P"], ["J", "G", "GN", "C"])
    return {"backward": backward, "evaluate_backward": evaluate_backward, "gradient": gradient, "forward": forward,
            "evaluate": evaluate}, knots


def _backward_outputs(layout, S_rev, pol_rev, S_N):
    """policy (knot order), summary [sum d1, sum d2, max stationarity, min pivot] and values."""
    N = pol_rev.size2()
    policy = _reverse(pol_rev, N)
    o = layout.nu + layout.nu * layout.nx
    summary = ca.vertcat(ca.sum2(policy[o + 1, :]), ca.sum2(policy[o + 2, :]),
                         ca.mmax(policy[o + 3, :]), ca.mmin(policy[o, :]))
    return [policy, summary, ca.horzcat(_reverse(S_rev, N), S_N)]


class _BufferCall:
    """Call a CasADi Function on numpy memory (no conversion): rows of C arrays = columns."""

    def __init__(self, fun: ca.Function):
        self.fun = fun
        self.buffer, self.trigger = fun.buffer()
        self.out_shapes = [fun.size_out(i)[::-1] for i in range(fun.n_out())]

    def __call__(self, *args):
        keep = []
        for i, a in enumerate(args):
            a = np.ascontiguousarray(a, dtype=float) if isinstance(a, np.ndarray) else np.array([a], dtype=float)
            keep.append(a)
            self.buffer.set_arg(i, memoryview(a))
        outs = [np.empty(shape) for shape in self.out_shapes]
        for i, o in enumerate(outs):
            self.buffer.set_res(i, memoryview(o))
        self.trigger()
        return outs


class CasadiBackend:
    """Whole-horizon passes as CasADi functions (VM), optionally compiled to C."""

    def __init__(self, problem, settings, layout, compiled: bool):
        key = _pass_cache.key(problem, settings) if compiled else None
        funs = _pass_cache.load(key)
        if funs is None:
            funs = build_passes(problem, settings, layout)[0]
            if compiled:
                funs, compiled = self._compile(funs, settings, key)
        self.name = "codegen" if compiled else "casadi"
        self._f = {name: _BufferCall(f) for name, f in funs.items()}

    @staticmethod
    def _compile(passes, settings, key):
        flags = tuple(settings.compiler_flags)
        try:
            funs = compile_functions(passes, flags)
        except (RuntimeError, subprocess.CalledProcessError) as err:  # e.g. CVODES has no C code
            log.warning("no compiled code for this problem (%s); using the CasADi VM backend", err)
            return passes, False
        _pass_cache.record(key, passes, flags)
        return funs, True

    def backward(self, X, U, P, Lam, LamN, C, rho, reg):
        policy, summary, values = self._f["backward"](X, U, P, Lam, LamN, C, rho, reg)
        return policy, summary.ravel(), values

    def evaluate_backward(self, X, U, P, Lam, LamN, rho, reg):
        policy, summary, values, J, G, GN, C = self._f["evaluate_backward"](X, U, P, Lam, LamN, rho, reg)
        return (float(J[0, 0]), G, GN.ravel(), C), (policy, summary.ravel(), values)

    def gradient(self, X, U, P, Lam, LamN, policy, rho):
        stat, costates = self._f["gradient"](X, U, P, Lam, LamN, policy, rho)
        return float(stat[0, 0]), costates

    def forward(self, X, U, P, policy, C, alpha):
        Xn, Un, J, G, GN = self._f["forward"](X, U, P, policy, C, alpha)
        return Xn, Un, float(J[0, 0]), G, GN.ravel()

    def evaluate(self, X, U, P):
        J, G, GN, C = self._f["evaluate"](X, U, P)
        return float(J[0, 0]), G, GN.ravel(), C


class NumpyBackend:
    """Fallback: derivatives in one batched CasADi call (map), Riccati and rollout as numpy loops."""

    name = "numpy"

    def __init__(self, problem, settings, layout):
        passes, knots = build_passes(problem, settings, layout)
        self.problem, self.settings, self.layout = problem, settings, layout
        self._evaluate = passes["evaluate"]
        self._fwd, self._end = knots["fwd"], knots["end"]
        model, (x, u, p, lam, _, rho) = knots["model"], knots["syms"]
        names = ["A", "B", "lx", "lu", "lxx", "luu", "lux"]
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
        mats = [np.asarray(m) for m in self._derivs(X[:, :N], U, P[:, :N], Lam, rho)]
        data = {n: m.T if n in ("lx", "lu") else m.T.reshape(N, s[1], s[0]).transpose(0, 2, 1)
                for m, s, n in zip(mats, self._shapes, self._names)}
        return data, np.asarray(self._terminal(X[:, N], P[:, N], LamN, rho)).ravel()

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
            K = policy[t, lay.nu: lay.nu + lay.nu * nx].reshape(nx, lay.nu).T
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
            values[:, t] = np.concatenate([a, b, Vxx.T.ravel()])
            policy[:, t] = np.concatenate([st["k"], st["K"].T.ravel(),
                                           [st["pivot"], st["d1"], st["d2"], st["stationarity"]]])
            if st["pivot"] <= 0:
                policy[lay.nu + lay.nu * nx, :t] = -1.0
                break
        o = lay.nu + lay.nu * nx
        summary = np.array([policy[o + 1].sum(), policy[o + 2].sum(), policy[o + 3].max(), policy[o].min()])
        return policy.T.copy(), summary, values.T.copy()

    def _second_order(self, x, u, p):
        return lambda v: tuple(np.asarray(h) for h in self._second(x, u, p, v))

    def forward(self, X, U, P, policy, C, alpha):
        X, U, P, policy, C = X.T, U.T, P.T, policy.T, C.T
        N, nu = self.problem.horizon, self.problem.nu
        Xn = np.empty_like(X)
        Xn[:, 0] = X[:, 0]
        stages = []
        for t in range(N):
            x_next, stage = self._fwd(Xn[:, t], X[:, t], U[:, t], policy[:, t], C[:, t], P[:, t], alpha)
            Xn[:, t + 1] = np.asarray(x_next).ravel()
            stages.append(np.asarray(stage).ravel())
        stage = np.array(stages).T
        costN, gN = self._end(Xn[:, N], P[:, N])
        return (Xn.T.copy(), stage[:nu].T.copy(), float(stage[nu].sum() + costN), stage[nu + 1:].T.copy(),
                np.asarray(gN).ravel())

    def evaluate(self, X, U, P):
        J, G, GN, C = self._evaluate(X.T, U.T, P.T)
        return float(J), G.full().T.copy(), GN.full().ravel(), C.full().T.copy()


def make_backend(problem, settings, layout):
    if settings.backend == "numpy":
        return NumpyBackend(problem, settings, layout)
    return CasadiBackend(problem, settings, layout, compiled=settings.backend == "codegen")
