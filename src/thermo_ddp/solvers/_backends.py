"""The DDP passes on whole trajectories: compiled C loops over a runtime horizon, CasADi mapaccum, or numpy.

Every backend offers the same calls on whole trajectories, as C-contiguous numpy arrays with one
row per knot (X (N+1, nx), U (N, nu), P (N+1, np), Lam (N, ng), C (N, nx) gaps; rho: penalties of g, then g_N):
  backward(X, U, P, Lam, LamN, C, rho, reg) -> (policy (N, n_policy), summary [d1, d2, stat, pivot],
                                                values (N+1, n_value))
  evaluate_backward(X, U, P, Lam, LamN, rho, reg) -> ((J, G, GN, C), backward's outputs): both in
                                                one pass over the knots (the first pass of a solve)
  gradient(X, U, P, Lam, LamN, policy, rho) -> (stat, costates (N+1, nx)): first order only, with
                                                the gains of ``policy`` (a gap-free iterate)
  forward(X, U, P, policy, C, alpha)        -> (Xn, Un, J, G, GN)
  evaluate(X, U, P)                          -> (J, G, GN, C)
All are built from the same six per-knot CasADi functions (``knot_functions``). "codegen" compiles
only those (one C file each) and loops them over the horizon in a hand-written C driver
(solvers/ddp_passes.c, called through ctypes on the arrays' memory): the library depends on the
problem's structure, not on N, so a new horizon compiles nothing. "casadi" maps them over the horizon
in the CasADi VM (mapaccum: one call per pass). "numpy" (solvers/_numpy_backend.py) runs the Riccati
recursion and the rollout as numpy loops. A backward pass stops at the first (latest) knot with a
non-positive pivot in "codegen" and "numpy" (earlier knots get pivot -1); "casadi" runs on. A row-per-knot C array is exactly
CasADi's column-major (dim, knots) matrix, so no backend copies the trajectories.
"""
from __future__ import annotations

import ctypes
import logging
import subprocess
import weakref

import casadi as ca
import numpy as np

from .. import codegen
from . import _pass_cache
from ._augmented_lagrangian import phr
from ._layout import Layout
from ._riccati import SymOps, backward_step, first_order_step, gradient_step, knot_model

log = logging.getLogger(__name__)
# Common-subexpression elimination in the per-knot functions: the dynamics, its Jacobians and its
# second-order tensor share most of their work (full DDP back knot of the rk4_4 lift: 10333 -> 7028
# instructions, identical results).
_CSE = {"cse": True}


def knot_functions(problem, settings, layout, compiled: bool = False):
    """The per-knot CasADi functions (C names ``ddp_*``, all outputs dense) and the symbolic local model;
    ``compiled``: without the composed backward step (the driver composes it; saves seconds for big models)."""
    F = problem.functions
    sym = F.symbolic
    x, u, p = sym.sym("x", problem.nx), sym.sym("u", problem.nu), sym.sym("p", problem.n_params)
    lam, lamN = sym.sym("lam", problem.n_constraints), sym.sym("lamN", problem.n_terminal_constraints)
    rho = sym.sym("rho", problem.n_constraints)  # a penalty per row of g (of g_N: ``rhoN`` of the terminal knot)
    model = knot_model(F, x, u, p, lam, rho, settings.full_second_order, margin=settings.active_margin)
    second = model.pop("second_order_sym", None)
    knots = {"model": model, "second": second, "syms": (x, u, p, lam, lamN, rho)}
    knots["local"], model_in = _local_model_knot(problem, knots)
    knots["back_core"], knots["back"], knots["terminal"] = _backward_knot(problem, settings, layout, knots, model_in,
                                                                          compiled)
    knots["grad_core"], knots["grad"] = _gradient_knot(problem, layout, knots, model_in, compiled)
    knots["fwd"] = _forward_knot(problem, layout, x, p)
    knots["eval"], knots["end"] = _evaluation_knots(problem, x, u, p)
    small = len(knots["hess"]) == 1 and knots["hess"][0].n_instructions() <= FUSED_MAX_INSTRUCTIONS
    fused = _fused_knots(problem, settings, layout, knots) if compiled and small else []
    small_knot = compiled and knots["local"].n_instructions() <= SMALL_KNOT_INSTRUCTIONS
    knots["optional"] = fused + (_run_time_knots(problem, layout, knots) if small_knot else [])
    return knots


def _fused_knots(problem, settings, layout, knots):
    """A small full-DDP model's Riccati step as one function with shared subexpressions, from the local model
    and the dynamics tensor contracted symbolically (knot_model's second_order_sym), and the same after the
    knot's evaluation (the first pass): ``ddp_fused_step(S, x, u, p, lam, c, rho, reg) -> (S_prev, policy)``,
    ``ddp_fused_eval_step(S, x, u, p, lam, x_next, rho, reg) -> (S_prev, policy, cost, g, gap)``."""
    sym, nx = problem.functions.symbolic, problem.nx
    x, u, p, lam, _, rho = knots["syms"]
    reg, c, S, xn = sym.sym("reg"), sym.sym("c", nx), sym.sym("S", layout.n_value), sym.sym("x_next", nx)
    v_sym, hxx, huu, hux = knots["second"]
    model = {**knots["model"], "second_order": lambda v: tuple(ca.substitute(h, v_sym, v) for h in (hxx, huu, hux))}
    st = backward_step(SymOps, model, *layout.unpack_value(S), c, u, ca.DM(problem.u_lb), ca.DM(problem.u_ub), reg,
                       settings.box_iterations, problem.has_box)
    out = [layout.pack_value(st["a"], st["b"], st["Vxx"]), layout.pack_policy(st)]
    step = _function("ddp_fused_step", [S, x, u, p, lam, c, rho, reg], out,
                     ["S", "x", "u", "p", "lam", "c", "rho", "reg"], ["S_prev", "policy"])
    cost, g, gap = knots["eval"](x, u, p, xn)
    eval_step = _function("ddp_fused_eval_step", [S, x, u, p, lam, xn, rho, reg], [*step(S, x, u, p, lam, gap, rho, reg),
                          cost, g, gap], ["S", "x", "u", "p", "lam", "x_next", "rho", "reg"],
                          ["S_prev", "policy", "cost", "g", "gap"])
    return [step, eval_step]


# The knots the C driver calls (and "hess"): the local model, then the Riccati step or the first-order step.
COMPILED = ("local", "back_core", "grad_core", "terminal", "fwd", "eval", "end")
# A model whose local model is at most this big also gets the knot functions that only save run time, not
# needed by the driver: the local model with the knot's evaluation (the first pass; else ``eval`` then ``local``)
# and the first-order step from one reverse sweep of the knot's Lagrangian (else ``local`` then ``grad_core``;
# the lift's rk4_4 knot: 2,923 instructions, its local model alone 8,154). Local models: the 4-joint arm's 22,809;
# the 7-joint arm's ~78,700, where they cost more to build than they save: gcc took 11.8 s on the one-sweep
# step's 0.9 MB of C alone (the arm's build 14.8 -> 21.9 s when it came; without them 12.7 s) for a pass that
# runs a few times per solve.
SMALL_KNOT_INSTRUCTIONS = 30_000
# Optional knot functions: the driver calls them through pointers, NULL when not generated.
OPTIONAL = ("ddp_fused_step", "ddp_fused_eval_step", "ddp_local_eval_knot", "ddp_grad_first_knot")
MODEL_PARTS = ("A", "B", "lx", "lu", "lxx", "luu", "lux", "v_shift")  # packed in this order (column-major blocks)
# Nodes of the full-DDP second-order term per C file: the 7-joint arm's (nz = 42) splits in two.
HESSIAN_CHUNK_NODES = 1_000_000
# A full-DDP model whose second-order term is at most this big also gets the whole Riccati step as one
# function (shared subexpressions; see _fused_knots): the dynamics' sweep is computed once instead of in both
# the local model and the second-order term (MPC lift, N = 200: first pass 612 -> ~445 us, as before the
# per-knot split). The 7-joint arm's term (1.1e6 instructions) is far above it.
FUSED_MAX_INSTRUCTIONS = 100_000


def _function(name, inputs, outputs, names_in, names_out, cse=True):
    """A knot function with dense outputs (the driver writes whole rows), shared subexpressions by default."""
    return ca.Function(name, inputs, [ca.densify(o) for o in outputs], names_in, names_out, _CSE if cse else {})


def penalties(n: int, rho) -> np.ndarray:
    """The penalty vector of the passes (``n`` rows: of g, then of g_N) from one value per row or one for all."""
    values = np.asarray(rho, dtype=float).ravel()
    return np.ascontiguousarray(values if values.size == n else np.broadcast_to(values, (n,)))


def _local_model_knot(problem, knots):
    """The knot's local model: the structural, non-constant non-zeros of A, B, lx, lu, lxx, luu, lux stacked
    (one compiled function, shared by the backward and first-order steps), and the same parts rebuilt from
    an input symbol with their sparsity and constants (so the Riccati step keeps skipping the zeros and
    folding the constant entries of A and B, e.g. RK4's identity)."""
    x, u, p, lam, _, rho = knots["syms"]
    parts = [knots["model"][name] for name in MODEL_PARTS]
    entries = [[e for e in _nonzeros(m) if not e.is_constant()] for m in parts]
    packed_model = ca.vertcat(*[e for es in entries for e in es])
    local = _function("ddp_local_knot", [x, u, p, lam, rho], [packed_model], ["x", "u", "p", "lam", "rho"], ["model"])
    knots["packed_model"] = packed_model
    packed = problem.functions.symbolic.sym("model", local.nnz_out(0))
    model_in, offset = {}, 0
    for name, m in zip(MODEL_PARTS, parts):
        values = []
        for e in _nonzeros(m):
            values.append(e if e.is_constant() else packed[offset])
            offset += not e.is_constant()
        model_in[name] = type(packed)(m.sparsity(), ca.vertcat(*values)) if values else type(packed)(m.sparsity())
    return local, (packed, model_in)


def _nonzeros(m):
    """The structural non-zeros of a symbolic matrix as scalars (an MX matrix: itself, one entry)."""
    return m.nonzeros() if isinstance(m, ca.SX) else [m.nz[i] for i in range(m.nnz())]


def _backward_knot(problem, settings, layout, knots, model_in, compiled):
    """One Riccati step from the packed local model (compiled core; composed with the local model for the
    VM unless ``compiled``) and the terminal value function. Full DDP: the core takes the dynamics'
    second-order term H = d2(v'f)/dz2 (z = [x; u], v = a + b + Vxx c + v_shift) as an input ``hess`` (empty in
    Gauss-Newton), computed by the ``hess`` chunk functions (see _hessian_chunks)."""
    F, nx, nz = problem.functions, problem.nx, problem.nx + problem.nu
    x, u, p, lam, lamN, rho = knots["syms"]
    reg, c, S = F.symbolic.sym("reg"), F.symbolic.sym("c", nx), F.symbolic.sym("S", layout.n_value)
    packed, model = model_in[0], dict(model_in[1])
    chunks = _hessian_chunks(problem, layout, x, u, p, model_in) if settings.full_second_order else []
    hess = F.symbolic.sym("hess", sum(f.nnz_out(0) for f, _ in chunks))
    if chunks:
        columns = np.concatenate([cols for _, cols in chunks])
        H = ca.reshape(hess, nz, nz)[:, np.argsort(columns).tolist()]  # chunk order -> column order
        model["second_order"] = lambda v: (H[:nx, :nx], H[nx:, nx:], H[nx:, :nx])
    st = backward_step(SymOps, model, *layout.unpack_value(S), c, u, ca.DM(problem.u_lb), ca.DM(problem.u_ub), reg,
                       settings.box_iterations, problem.has_box)
    S_prev, policy = layout.pack_value(st["a"], st["b"], st["Vxx"]), layout.pack_policy(st)
    back = _function("ddp_back_knot", [S, packed, u, c, reg, hess], [S_prev, policy],
                     ["S", "model", "u", "c", "reg", "hess"], ["S_prev", "policy"])
    knots["hess"] = [f for f, _ in chunks]
    composed = None
    if not compiled:
        local = knots["local"](x, u, p, lam, rho)
        composed = ca.Function("ddp_back_composed", [S, x, u, p, lam, c, rho, reg],
                               back(S, local, u, c, reg, ca.vertcat(*[f(S, c, x, u, p, local) for f, _ in chunks])),
                               ["S", "x", "u", "p", "lam", "c", "rho", "reg"], ["S_prev", "policy"], _CSE)
    rhoN = F.symbolic.sym("rhoN", problem.n_terminal_constraints)
    term = knot_model(F, x, None, p, lamN, rhoN, settings.full_second_order, terminal=True,
                      margin=settings.active_margin)
    S_N = layout.pack_value(term["lx"], ca.DM.zeros(nx), term["lxx"])
    terminal = _function("ddp_back_terminal", [x, p, lamN, rhoN], [S_N], ["x", "p", "lamN", "rhoN"], ["S"])
    return back, composed, terminal


def _hessian_chunks(problem, layout, x, u, p, model_in):
    """The full-DDP term d2(v'f)/dz2 with v = a + b + Vxx c + v_shift from (S, c) and the packed local model, as
    functions of column groups (round robin, so the costly angle columns spread evenly): for a large model each is
    its own C file, compiled in parallel. Returns [(function, its columns)]. No CSE: it saves 1 % of their
    instructions for the 7-joint arm (1.10e6 -> 1.12e6 without) and costs 11 s."""
    F, nx = problem.functions, problem.nx
    S, c = F.symbolic.sym("S", layout.n_value), F.symbolic.sym("c", nx)
    packed, model = model_in
    a, b, Vxx = layout.unpack_value(S)
    v = a + (b + Vxx @ c) + model["v_shift"]  # as backward_step
    z = ca.vertcat(x, u)
    grad = ca.gradient(ca.dot(v, F.step(x, u, p)), z)
    n_chunks = max(1, min(z.numel(), round(z.numel() * ca.n_nodes(grad) / HESSIAN_CHUNK_NODES)))
    chunks = []
    for k in range(n_chunks):
        cols = np.arange(k, z.numel(), n_chunks)
        H = ca.jacobian(grad, z[cols.tolist()])
        chunks.append((_function(f"ddp_hess_{k}", [S, c, x, u, p, packed], [ca.vec(H)],
                                 ["S", "c", "x", "u", "p", "model"], ["hess"], cse=False), cols))
    return chunks


def _gradient_knot(problem, layout, knots, model_in, compiled):
    """First-order backward step with given gains (see _riccati.gradient_step) from the packed local
    model (compiled core) and composed with the local model (VM)."""
    nx = problem.nx
    x, u, p, lam, _, rho = knots["syms"]
    a, pol = problem.functions.symbolic.sym("a", nx), problem.functions.symbolic.sym("policy", layout.n_policy)
    K = layout.feedback(pol)
    a_prev, stat = gradient_step(SymOps, model_in[1], a, K, u, ca.DM(problem.u_lb), ca.DM(problem.u_ub),
                                 problem.has_box)
    core = _function("ddp_grad_knot", [a, model_in[0], u, pol], [a_prev, stat], ["a", "model", "u", "policy"],
                     ["a_prev", "stat"])
    composed = None if compiled else ca.Function("ddp_grad_composed", [a, x, u, p, lam, rho, pol],
                           core(a, knots["local"](x, u, p, lam, rho), u, pol),
                           ["a", "x", "u", "p", "lam", "rho", "policy"], ["a_prev", "stat"], _CSE)
    return core, composed


def _run_time_knots(problem, layout, knots):
    """The optional compiled knot functions of a small model (see SMALL_KNOT_INSTRUCTIONS): the local model with
    the knot's evaluation (the first pass: they share the dynamics), and the first-order step from one reverse
    sweep of the knot's Lagrangian l + a'f, without the local model's Jacobians and Hessians (rk4_4 lift knot:
    2,380 -> 1,918 instructions; rows composed with the step: 7,272 -> 2,964)."""
    F, nx, sym = problem.functions, problem.nx, problem.functions.symbolic
    x, u, p, lam, _, rho = knots["syms"]
    xn, a, pol = sym.sym("x_next", nx), sym.sym("a", nx), sym.sym("policy", layout.n_policy)
    evaluation = [0.5 * ca.sumsqr(F.stage_residual(x, u, p)), F.stage_constraint(x, u, p), F.step(x, u, p) - xn]
    local_eval = _function("ddp_local_eval_knot", [x, u, p, lam, rho, xn], [knots["packed_model"], *evaluation],
                           ["x", "u", "p", "lam", "rho", "x_next"], ["model", "cost", "g", "gap"])
    z = ca.vertcat(x, u)
    lagrangian = 0.5 * ca.sumsqr(F.stage_residual(x, u, p)) + ca.dot(a, F.step(x, u, p))
    if problem.n_constraints:
        lagrangian += ca.sum1(phr(F.stage_constraint(x, u, p), lam, rho, ca.fmax))
    Lz = ca.gradient(lagrangian, z)
    first = first_order_step(SymOps, Lz[:nx], Lz[nx:], layout.feedback(pol), u, ca.DM(problem.u_lb),
                             ca.DM(problem.u_ub), problem.has_box)
    grad_first = _function("ddp_grad_first_knot", [a, x, u, p, lam, rho, pol], list(first),
                           ["a", "x", "u", "p", "lam", "rho", "policy"], ["a_prev", "stat"])
    return [local_eval, grad_first]


def _forward_knot(problem, layout, x, p):
    """Nonlinear rollout step: u = clip(u_ref + alpha k + K dx), x' = f(x, u) - (1 - alpha) c; its cost and g."""
    F, nx, nu = problem.functions, problem.nx, problem.nu
    sym = F.symbolic
    xr, ur, alpha, c = sym.sym("x_ref", nx), sym.sym("u_ref", nu), sym.sym("alpha"), sym.sym("c", nx)
    pol = sym.sym("policy", layout.n_policy)
    K = layout.feedback(pol)
    u_new = ur + alpha * pol[:nu] + K @ (x - xr)
    if problem.has_box:
        u_new = ca.fmin(ca.fmax(u_new, ca.DM(problem.u_lb)), ca.DM(problem.u_ub))
    x_next = F.step(x, u_new, p) - (1 - alpha) * c
    cost, g = 0.5 * ca.sumsqr(F.stage_residual(x, u_new, p)), F.stage_constraint(x, u_new, p)
    return _function("ddp_fwd_knot", [x, xr, ur, pol, c, p, alpha], [x_next, u_new, cost, g],
                     ["x", "x_ref", "u_ref", "policy", "c", "p", "alpha"], ["x_next", "u", "cost", "g"])


def _evaluation_knots(problem, x, u, p):
    """Cost, constraints and gap of one knot; cost and constraints of the terminal knot."""
    F = problem.functions
    xn = F.symbolic.sym("x_next", problem.nx)
    ev = _function("ddp_eval_knot", [x, u, p, xn],
                   [0.5 * ca.sumsqr(F.stage_residual(x, u, p)), F.stage_constraint(x, u, p), F.step(x, u, p) - xn],
                   ["x", "u", "p", "x_next"], ["cost", "g", "gap"])
    end = _function("ddp_terminal", [x, p], [0.5 * ca.sumsqr(F.terminal_residual(x, p)), F.terminal_constraint(x, p)],
                    ["x", "p"], ["cost", "g"])
    return ev, end


def _reverse(M, N):
    return M[:, list(range(N - 1, -1, -1))]


def build_passes(problem, knots, layout):
    """MX functions for the whole horizon (CasADi VM): one call per pass, mapaccum over the knots."""
    nx, n_p, N = problem.nx, problem.n_params, problem.horizon
    ng, ngN = problem.n_constraints, problem.n_terminal_constraints
    X, U, P = ca.MX.sym("X", nx, N + 1), ca.MX.sym("U", problem.nu, N), ca.MX.sym("P", n_p, N + 1)
    Lam, LamN, C = ca.MX.sym("Lam", ng, N), ca.MX.sym("LamN", ngN), ca.MX.sym("C", nx, N)
    rho, reg, alpha = ca.MX.sym("rho", ng + ngN), ca.MX.sym("reg"), ca.MX.sym("alpha")
    rho_g, rho_N = rho[:ng], rho[ng:]
    Pol = ca.MX.sym("policy", layout.n_policy, N)

    def sweep(gaps):
        S_N = knots["terminal"](X[:, N], P[:, N], LamN, rho_N)
        S_rev, pol_rev = knots["back"].mapaccum("ddp_back_acc", N)(
            S_N, _reverse(X[:, :N], N), _reverse(U, N), _reverse(P[:, :N], N), _reverse(Lam, N), _reverse(gaps, N),
            rho_g, reg)
        return _backward_outputs(layout, S_rev, pol_rev, S_N)

    cost, G, gaps = knots["eval"].map(N)(X[:, :N], U, P[:, :N], X[:, 1:])
    costN, gN = knots["end"](X[:, N], P[:, N])
    evaluation = [ca.sum2(cost) + costN, G, gN, gaps]
    backward = ca.Function("ddp_backward", [X, U, P, Lam, LamN, C, rho, reg], sweep(C),
                           ["X", "U", "P", "Lam", "LamN", "C", "rho", "reg"], ["policy", "summary", "values"])
    evaluate_backward = ca.Function(
        "ddp_evaluate_backward", [X, U, P, Lam, LamN, rho, reg], [*sweep(gaps), *evaluation],
        ["X", "U", "P", "Lam", "LamN", "rho", "reg"], ["policy", "summary", "values", "J", "G", "GN", "C"])
    evaluate = ca.Function("ddp_evaluate", [X, U, P], evaluation, ["X", "U", "P"], ["J", "G", "GN", "C"])

    a_N = knots["terminal"](X[:, N], P[:, N], LamN, rho_N)[:nx]
    a_rev, stat = knots["grad"].mapaccum("ddp_grad_acc", N)(
        a_N, _reverse(X[:, :N], N), _reverse(U, N), _reverse(P[:, :N], N), _reverse(Lam, N), rho_g, _reverse(Pol, N))
    gradient = ca.Function("ddp_gradient", [X, U, P, Lam, LamN, Pol, rho],
                           [ca.mmax(stat), ca.horzcat(_reverse(a_rev, N), a_N)],
                           ["X", "U", "P", "Lam", "LamN", "policy", "rho"], ["stat", "costates"])

    X_new, U_new, cost, G = knots["fwd"].mapaccum("ddp_fwd_acc", N)(X[:, 0], X[:, :N], U, Pol, C, P[:, :N], alpha)
    Xn = ca.horzcat(X[:, 0], X_new)
    costN, gN = knots["end"](Xn[:, N], P[:, N])
    forward = ca.Function("ddp_forward", [X, U, P, Pol, C, alpha], [Xn, U_new, ca.sum2(cost) + costN, G, gN],
                          ["X", "U", "P", "policy", "C", "alpha"], ["X_new", "U_new", "J", "G", "GN"])
    return {"backward": backward, "evaluate_backward": evaluate_backward, "gradient": gradient, "forward": forward,
            "evaluate": evaluate}


def _backward_outputs(layout, S_rev, pol_rev, S_N):
    """policy (knot order), summary [sum d1, sum d2, max stationarity, min pivot] and values."""
    N = pol_rev.size2()
    policy = _reverse(pol_rev, N)
    column = layout.column
    summary = ca.vertcat(ca.sum2(policy[column("d1"), :]), ca.sum2(policy[column("d2"), :]),
                         ca.mmax(policy[column("stationarity"), :]), ca.mmin(policy[column("pivot"), :]))
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
    """Whole-horizon passes as CasADi functions in the VM (mapaccum over the knots)."""

    name = "casadi"

    def __init__(self, problem, settings, layout, knots=None):
        self.problem, self._n_rho = problem, problem.n_constraints + problem.n_terminal_constraints
        knots = knots or knot_functions(problem, settings, layout)
        self._f = {name: _BufferCall(f) for name, f in build_passes(problem, knots, layout).items()}

    def backward(self, X, U, P, Lam, LamN, C, rho, reg):
        policy, summary, values = self._f["backward"](X, U, P, Lam, LamN, C, penalties(self._n_rho, rho), reg)
        return policy, summary.ravel(), values

    def evaluate_backward(self, X, U, P, Lam, LamN, rho, reg):
        policy, summary, values, J, G, GN, C = self._f["evaluate_backward"](X, U, P, Lam, LamN,
                                                                            penalties(self._n_rho, rho), reg)
        return (float(J[0, 0]), G, GN.ravel(), C), (policy, summary.ravel(), values)

    def gradient(self, X, U, P, Lam, LamN, policy, rho):
        stat, costates = self._f["gradient"](X, U, P, Lam, LamN, policy, penalties(self._n_rho, rho))
        return float(stat[0, 0]), costates

    def forward(self, X, U, P, policy, C, alpha):
        Xn, Un, J, G, GN = self._f["forward"](X, U, P, policy, C, alpha)
        return Xn, Un, float(J[0, 0]), G, GN.ravel()

    def evaluate(self, X, U, P):
        J, G, GN, C = self._f["evaluate"](X, U, P)
        return float(J[0, 0]), G, GN.ravel(), C


def compiled_library(problem, settings, layout):
    """The loaded library of the problem's compiled knot functions and driver, built if needed; None
    (with a warning) when no C can be built (no compiler; MX functions without C code, e.g. CVODES)."""
    key = _pass_cache.key(problem, settings)
    library = _pass_cache.load(key)
    if library is not None:
        return library
    knots = knot_functions(problem, settings, layout, compiled=True)
    functions = {f.name(): f for f in [knots[k] for k in COMPILED] + knots["hess"] + knots["optional"]}
    sources = {_pass_cache.DRIVER: _pass_cache.driver_source(),
               "ddp_knot_table.c": _knot_table(knots["hess"], knots["optional"])}
    try:
        path = codegen.compile_library(functions, settings.compiler_flags, sources)
    except (RuntimeError, subprocess.CalledProcessError) as err:
        log.warning("no compiled code for this problem (%s); using the CasADi VM backend", err)
        return None
    return _pass_cache.record(key, path)


def _knot_table(chunks, optional) -> str:
    """C table of the second-order chunk functions for the driver (ddp_n_hess = 0: Gauss-Newton) and the
    pointers to the ``OPTIONAL`` knot functions (NULL for those not in ``optional``)."""
    sig = "(const double **, double **, long long *, double *, int)"
    wsig = "(long long *, long long *, long long *, long long *)"
    names, present = [f.name() for f in chunks], {f.name() for f in optional}
    declared = [f"int {n}{sig};\nint {n}_work{wsig};" for n in names + sorted(present)]
    listed = lambda items: "{" + (", ".join(items) or "0") + "}"  # noqa: E731
    return "\n".join(declared + [
        f"const int ddp_n_hess = {len(names)};",
        f"int (*const ddp_hess[]){sig} = {listed(names)};",
        f"int (*const ddp_hess_work[]){wsig} = {listed(n + '_work' for n in names)};",
        f"const int ddp_hess_size[] = {listed(str(f.nnz_out(0)) for f in chunks)};",
        *[f"int (*const {n}_fn){sig} = {n if n in present else '0'};\nint (*const {n}_work_fn){wsig} = "
          f"{n + '_work' if n in present else '0'};" for n in OPTIONAL], ""])


class CompiledBackend:
    """The passes as the C driver's loops over compiled knot functions (solvers/ddp_passes.c), any horizon."""

    name = "codegen"

    def __init__(self, problem, library: ctypes.CDLL, layout: Layout):
        self._lib, self.problem = library, problem
        self._n_rho = problem.n_constraints + problem.n_terminal_constraints
        _bind(library)
        nx, nu = problem.nx, problem.nu
        self._dims = {"x": nx, "u": nu, "p": problem.n_params, "g": problem.n_constraints,
                      "gN": problem.n_terminal_constraints, "policy": layout.n_policy, "value": layout.n_value,
                      "rho": problem.n_constraints + problem.n_terminal_constraints}
        self._work = library.ddp_work_new(nx, nu, self._dims["p"], self._dims["g"], self._dims["gN"],
                                          *layout.c_sizes())
        if not self._work:
            raise MemoryError("no memory for the DDP work arrays")
        weakref.finalize(self, library.ddp_work_free, self._work)

    def _call(self, name, N, args, outs):
        """Run pass ``name`` on horizon N. ``args``: (array, rows, dimension name) or a float each; ``outs``:
        (rows, dimension name) each, rows 0 for a vector (then the dimension may be a size). Arrays are
        checked against the sizes the C driver will read (kept alive in ``keep`` during the call)."""
        keep, ptrs = [], []
        for value in args:
            if isinstance(value, tuple):
                arr, rows, dim = value
                arr = np.ascontiguousarray(arr, dtype=float)
                if arr.size != rows * self._dims[dim]:
                    raise ValueError(f"{name}: an argument of shape {arr.shape}, expected {rows} x {self._dims[dim]}")
                keep.append(arr)
                ptrs.append(arr.ctypes.data)
            else:
                ptrs.append(float(value))
        results = [np.empty((rows, self._dims[dim]) if rows else self._dims.get(dim, dim)) for rows, dim in outs]
        status = getattr(self._lib, name)(self._work, N, *ptrs, *(r.ctypes.data for r in results))
        if status:
            raise RuntimeError(f"{name}: a compiled knot function returned {status}")
        return results

    def backward(self, X, U, P, Lam, LamN, C, rho, reg):
        N, rho = len(U), (penalties(self._n_rho, rho), 1, "rho")
        return tuple(self._call("ddp_backward", N, _knots(N, X, U, P, Lam, LamN) + [(C, N, "x"), rho, reg],
                                [(N, "policy"), (0, 4), (N + 1, "value")]))

    def evaluate_backward(self, X, U, P, Lam, LamN, rho, reg):
        N, rho = len(U), (penalties(self._n_rho, rho), 1, "rho")
        policy, summary, values, J, G, GN, C = self._call(
            "ddp_evaluate_backward", N, _knots(N, X, U, P, Lam, LamN) + [rho, reg],
            [(N, "policy"), (0, 4), (N + 1, "value"), (0, 1), (N, "g"), (0, "gN"), (N, "x")])
        return (float(J[0]), G, GN, C), (policy, summary, values)

    def gradient(self, X, U, P, Lam, LamN, policy, rho):
        N, rho = len(U), (penalties(self._n_rho, rho), 1, "rho")
        stat, costates = self._call("ddp_gradient", N, _knots(N, X, U, P, Lam, LamN) + [(policy, N, "policy"), rho],
                                    [(0, 1), (N + 1, "x")])
        return float(stat[0]), costates

    def forward(self, X, U, P, policy, C, alpha):
        N = len(U)
        Xn, Un, J, G, GN = self._call("ddp_forward", N, _knots(N, X, U, P) + [(policy, N, "policy"), (C, N, "x"), alpha],
                                      [(N + 1, "x"), (N, "u"), (0, 1), (N, "g"), (0, "gN")])
        return Xn, Un, float(J[0]), G, GN

    def evaluate(self, X, U, P):
        N = len(U)
        J, G, GN, C = self._call("ddp_evaluate", N, _knots(N, X, U, P), [(0, 1), (N, "g"), (0, "gN"), (N, "x")])
        return float(J[0]), G, GN, C


def _knots(N, X, U, P, Lam=None, LamN=None):
    """The per-knot arguments with their expected sizes."""
    args = [(X, N + 1, "x"), (U, N, "u"), (P, N + 1, "p")]
    return args if Lam is None else args + [(Lam, N, "g"), (LamN, 1, "gN")]


def _bind(library: ctypes.CDLL) -> None:
    """Argument types of the driver's entry points: pointers, the horizon (int) and scalars (double)."""
    if getattr(library, "_ddp_bound", False):
        return
    ptr, dbl = ctypes.c_void_p, ctypes.c_double
    library.ddp_work_new.restype = ptr
    library.ddp_work_new.argtypes = [ctypes.c_int] * 8
    library.ddp_work_free.argtypes = [ptr]
    counts = {"ddp_backward": (7, 1, 3), "ddp_evaluate_backward": (6, 1, 7), "ddp_gradient": (7, 0, 2),
              "ddp_forward": (5, 1, 5), "ddp_evaluate": (3, 0, 4)}  # input arrays, doubles, output arrays
    for name, (arrays, doubles, outputs) in counts.items():
        fn = getattr(library, name)
        fn.restype = ctypes.c_int
        fn.argtypes = [ptr, ctypes.c_int] + [ptr] * arrays + [dbl] * doubles + [ptr] * outputs
    library._ddp_bound = True
