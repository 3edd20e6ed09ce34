"""General discrete-time optimal control problems and their multiple-shooting transcription.

Models are separate from data (as in crocoddyl): an ``OptimalControlProblem`` holds only
CasADi functions, sizes and bounds; the initial state ``x0`` and the per-knot parameters
``params`` (shape ``(N+1, np)``) are given at solve time, so one built problem serves many
MPC re-solves.

The problem, with knots k = 0..N-1 and terminal knot N::

    min   sum_k sum_c 0.5 w_c |r_c(x_k, u_k, p_k)|^2  +  sum_c 0.5 w_c |r_c(x_N, p_N)|^2
    s.t.  x_0 = x0,   x_{k+1} = f(x_k, u_k, p_k),
          g(x_k, u_k, p_k) <= 0,   g_N(x_N, p_N) <= 0,   u_lb <= u_k <= u_ub.

A stage term may also read the knot's end state: an input named ``x_next`` is f(x_k, u_k, p_k) (e.g. a
voltage at the end of a knot under its held current). Every solver evaluates it there; DDP takes its
derivatives through the dynamics' Jacobians A, B and folds its curvature into the dynamics' second-order
term, instead of differentiating the composition (:func:`thermo_ddp.solvers._riccati.knot_model`).

Every solver (DDP, IPOPT, fatrop) works on the functions built here, so all solve the
identical problem.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
import re
from typing import Sequence

import casadi as ca
import numpy as np

from .errors import InputError

log = logging.getLogger(__name__)

STAGE_INPUTS = ("x", "u", "p")
TERMINAL_INPUTS = ("x", "p")
END_STATE = "x_next"  # a stage term's optional input: the knot's end state f(x, u, p)
_SRC = "OptimalControlProblem"


def _weight_vector(weight, size: int, where: str) -> np.ndarray:
    w = np.asarray(weight, dtype=float)
    if w.ndim == 0:
        w = np.full(size, float(w))
    if w.shape != (size,):
        raise InputError(where, "weight", weight, f"expected a scalar or {size} values (one per residual)")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError(where, "weight", weight, "weights must be finite and >= 0")
    return w


def _output_index(fun: ca.Function, preferred: str, where: str) -> int:
    names = fun.name_out()
    if preferred in names:
        return names.index(preferred)
    if fun.n_out() == 1:
        return 0
    raise InputError(where, "outputs", names, f"expected one output or an output named '{preferred}'")


@dataclasses.dataclass(frozen=True)
class KnotParameters:
    """Names and sizes of the per-knot parameter vector ``p``: what a problem reads by name, and how a
    caller builds the (N+1, np) array the solvers take, also by name."""

    blocks: tuple[tuple[str, int], ...]

    def __post_init__(self):
        names = [name for name, _ in self.blocks]
        if len(set(names)) != len(names) or any(not isinstance(n, str) or not n.isidentifier() for n in names):
            raise InputError("KnotParameters", "names", names, "expected distinct identifier-like names")
        if any(not isinstance(size, int) or size < 1 for _, size in self.blocks):
            raise InputError("KnotParameters", "sizes", self.blocks, "expected sizes >= 1")

    @property
    def size(self) -> int:
        return sum(size for _, size in self.blocks)

    def slice(self, name: str) -> slice:
        start = 0
        for block, size in self.blocks:
            if block == name:
                return slice(start, start + size)
            start += size
        raise InputError("KnotParameters", "name", name, f"unknown parameter; known: {', '.join(self.names)}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.blocks)

    def symbols(self, p) -> dict[str, object]:
        """``{name: p[its entries]}`` of a symbolic (or numeric) parameter vector."""
        return {name: p[self.slice(name)] for name in self.names}

    def values(self, knots: int, **values) -> np.ndarray:
        """The (knots, size) array from every block by name: a scalar or a (size,) row for all knots, a
        (knots,) column for a size-1 block, or a (knots, size) array."""
        missing, unknown = set(self.names) - set(values), set(values) - set(self.names)
        if missing or unknown:
            name = sorted(missing or unknown)[0]
            raise InputError("KnotParameters", name, "<missing>" if missing else values[name],
                             f"expected exactly the parameters {', '.join(self.names)}")
        out = np.empty((knots, self.size))
        for name, size in self.blocks:
            self.assign(out, name, values[name])
        return out

    def assign(self, params: np.ndarray, name: str, value) -> None:
        """Set block ``name`` of a (knots, size) array in place (shapes as in :meth:`values`)."""
        cols = self.slice(name)
        size, knots = cols.stop - cols.start, params.shape[0]
        arr = np.asarray(value, dtype=float)
        if arr.shape in ((), (size,)):
            arr = np.broadcast_to(arr, (knots, size))
        elif arr.shape == (knots,) and size == 1:
            arr = arr[:, None]
        if arr.shape != (knots, size):
            raise InputError("KnotParameters", name, f"array of shape {np.shape(value)}",
                             f"expected a scalar, ({size},), or ({knots}, {size})")
        params[:, cols] = arr


@dataclasses.dataclass(frozen=True, eq=False)
class Cost:
    """Least-squares cost term 0.5 * sum(weight * r**2).

    ``residual`` is a casadi.Function with named inputs (x, u, p, optionally x_next: the knot's end state) for a
    stage cost or (x, p) for a terminal cost (p may be omitted) and one output ``r`` (a column vector).
    ``weight`` is a scalar or one non-negative value per residual entry.
    """

    name: str
    weight: float | Sequence[float] | np.ndarray
    residual: ca.Function

    def __post_init__(self):
        out = _check_term("Cost", self.name, "residual", self.residual, "r")
        size = self.residual.size1_out(out) * self.residual.size2_out(out)
        object.__setattr__(self, "weight", _weight_vector(self.weight, size, f"Cost '{self.name}'"))

    @property
    def size(self) -> int:
        return int(self.weight.size)


@dataclasses.dataclass(frozen=True, eq=False)
class Constraint:
    """Inequality g <= 0 (elementwise); ``function`` maps (x, u, p, optionally x_next: the knot's end state) or
    (x, p) to ``g``."""

    name: str
    function: ca.Function

    def __post_init__(self):
        _check_term("Constraint", self.name, "function", self.function, "g")

    @property
    def size(self) -> int:
        out = _output_index(self.function, "g", self.name)
        return self.function.size1_out(out) * self.function.size2_out(out)

    def shifted(self, offset: float, name: str | None = None) -> "Constraint":
        """The constraint ``g - offset <= 0`` (looser by ``offset`` > 0), same inputs."""
        inputs, g = _symbolic_call(self.function, "g", self.name)
        return Constraint(name or self.name, ca.Function(name or self.name, inputs, [g - offset],
                                                         self.function.name_in(), ["g"]))

    def penalty(self, weight, name: str | None = None) -> Cost:
        """This constraint made soft: the cost ``0.5 * weight * |max(0, g)|^2``, zero wherever ``g <= 0``."""
        name = name or f"{self.name}_penalty"
        inputs, g = _symbolic_call(self.function, "g", self.name)
        return Cost(name, weight, ca.Function(name, inputs, [ca.fmax(0, g)], self.function.name_in(), ["r"]))


def term_function(name: str, expr, out: str, x, p, u=None, x_next=None) -> ca.Function:
    """A term's casadi Function of (x, u, p), and of the knot's end state when ``expr`` reads ``x_next`` (a stage
    term), or of (x, p) when ``u`` is None (a terminal term); ``out``: "r" for a residual, "g" for a constraint."""
    named = [("x", x)] + ([] if u is None else [("u", u)]) + [("p", p)]
    if x_next is not None and ca.depends_on(expr, x_next):
        named.append((END_STATE, x_next))
    return ca.Function(name, [s for _, s in named], [expr], [n for n, _ in named], [out])


def _symbolic_call(fun: ca.Function, out_name: str, where: str):
    """Symbols for every input of ``fun`` and its output ``out_name`` on them."""
    inputs = [ca.SX.sym(n, fun.sparsity_in(i)) for i, n in enumerate(fun.name_in())]
    return inputs, ca.densify(fun.call(inputs)[_output_index(fun, out_name, where)])


_TERM_NAME = re.compile(r"[A-Za-z_]\w*(\[\w+\])?")


def _check_term(kind: str, name, field: str, fun, out_name: str) -> int:
    """A cost's or constraint's name and CasADi function; returns the index of its output. A name is
    identifier-like, with an optional tag in brackets (``winding_limit[s3]``: one scenario's copy)."""
    if not isinstance(name, str) or not _TERM_NAME.fullmatch(name):
        raise InputError(kind, "name", name, "expected an identifier-like string (optionally tagged: name[tag])")
    if not isinstance(fun, ca.Function):
        raise InputError(f"{kind} '{name}'", field, type(fun).__name__, "expected a casadi.Function")
    return _output_index(fun, out_name, f"{kind} '{name}'")


def _call_named(fun: ca.Function, out_name: str, args: dict, where: str):
    """Call ``fun`` by input name with the entries of ``args`` it declares; return one output."""
    call = {}
    for name in fun.name_in():
        if name not in args:
            raise InputError(where, "inputs", fun.name_in(),
                             f"unknown input '{name}'; allowed: {', '.join(args)}")
        call[name] = args[name]
    return ca.densify(fun.call(call)[fun.name_out()[_output_index(fun, out_name, where)]])


def _input_sizes(fun: ca.Function, where: str) -> dict[str, int]:
    sizes = {}
    for i, name in enumerate(fun.name_in()):
        if fun.size2_in(i) != 1 and fun.size1_in(i) != 0:
            raise InputError(where, f"input {name}", fun.size_in(i), "expected a column vector")
        sizes[name] = fun.size1_in(i)
    return sizes


@dataclasses.dataclass(frozen=True, eq=False)
class OptimalControlProblem:
    """A discrete-time optimal control problem (see the module docstring).

    ``dynamics``: casadi.Function with named inputs x, u (and optionally p) and an output
    ``x_next`` (one discretised step; the model provides it). ``horizon``: number of
    control intervals N. ``u_lb``/``u_ub``: control box (None or +-inf for no bound).
    ``dynamics_jacobians`` (optional): the same inputs -> (x_next, A, B), e.g. analytic
    rigid-body derivatives; DDP then takes A = dx_next/dx and B = dx_next/du from it instead
    of differentiating ``dynamics`` (which must describe the same step). ``parameters`` (optional)
    names the blocks of the per-knot parameter vector p (:class:`KnotParameters`).
    """

    dynamics: ca.Function
    horizon: int
    costs: Sequence[Cost] = ()
    terminal_costs: Sequence[Cost] = ()
    constraints: Sequence[Constraint] = ()
    terminal_constraints: Sequence[Constraint] = ()
    u_lb: Sequence[float] | np.ndarray | None = None
    u_ub: Sequence[float] | np.ndarray | None = None
    name: str = "ocp"
    dynamics_jacobians: ca.Function | None = None
    parameters: KnotParameters | None = None

    def __post_init__(self):
        if not isinstance(self.dynamics, ca.Function):
            raise InputError(_SRC, "dynamics", type(self.dynamics).__name__, "expected a casadi.Function")
        if "x_next" not in self.dynamics.name_out():
            raise InputError(_SRC, "dynamics outputs", self.dynamics.name_out(), "expected an output 'x_next'")
        if not isinstance(self.horizon, (int, np.integer)) or isinstance(self.horizon, bool) or self.horizon < 1:
            raise InputError(_SRC, "horizon", self.horizon, "expected an integer >= 1")
        object.__setattr__(self, "horizon", int(self.horizon))
        for field, kind in (("costs", Cost), ("terminal_costs", Cost),
                            ("constraints", Constraint), ("terminal_constraints", Constraint)):
            items = tuple(getattr(self, field))
            if not all(isinstance(i, kind) for i in items):
                raise InputError(_SRC, field, items, f"expected a sequence of {kind.__name__}")
            object.__setattr__(self, field, items)
        names = [t.name for t in self.costs + self.terminal_costs + self.constraints + self.terminal_constraints]
        if len(set(names)) != len(names):
            raise InputError(_SRC, "names", names, "cost and constraint names must be unique")
        self._check_sizes()
        if self.parameters is not None and self.parameters.size != self.n_params:
            raise InputError(_SRC, "parameters", self.parameters.blocks, f"sizes add up to {self.parameters.size}, "
                             f"the functions take {self.n_params}")
        self._set_bounds()

    # -- validation -------------------------------------------------------------------------
    def _check_sizes(self):
        dyn = _input_sizes(self.dynamics, "dynamics")
        if "x" not in dyn or "u" not in dyn:
            raise InputError(_SRC, "dynamics inputs", self.dynamics.name_in(), "expected inputs named x, u (and p)")
        nx, nu = dyn["x"], dyn["u"]
        out = self.dynamics.name_out().index("x_next")
        if self.dynamics.size_out(out) != (nx, 1):
            raise InputError(_SRC, "dynamics x_next", self.dynamics.size_out(out), f"expected shape ({nx}, 1)")
        if nx < 1 or nu < 1:
            raise InputError(_SRC, "dynamics", (nx, nu), "need at least one state and one control")
        sizes = {"x": nx, "u": nu, END_STATE: nx}
        n_p = dyn.get("p")
        for item, fun, allowed in self._functions():
            got = _input_sizes(fun, item)
            for name, size in got.items():
                if name not in allowed:
                    raise InputError(item, "inputs", fun.name_in(), f"allowed input names: {', '.join(allowed)}")
                if name == "p":
                    if n_p is not None and size != n_p:
                        raise InputError(item, "input p", size, f"expected {n_p} parameters like the others")
                    n_p = size
                elif size != sizes[name]:
                    raise InputError(item, f"input {name}", size, f"expected size {sizes[name]}")
            if isinstance(fun, ca.Function) and fun.n_out() >= 1:
                o = _output_index(fun, "g" if "Constraint" in item else "r", item)
                if fun.size2_out(o) != 1 and fun.size1_out(o) != 0:
                    raise InputError(item, "output", fun.size_out(o), "expected a column vector")
        object.__setattr__(self, "_nx", nx)
        object.__setattr__(self, "_nu", nu)
        object.__setattr__(self, "_np", int(n_p or 0))
        self._check_jacobians()

    def _check_jacobians(self):
        fun, where = self.dynamics_jacobians, "dynamics_jacobians"
        if fun is None:
            return
        if not isinstance(fun, ca.Function):
            raise InputError(_SRC, where, type(fun).__name__, "expected a casadi.Function or None")
        if fun.name_in() != self.dynamics.name_in():
            raise InputError(_SRC, f"{where} inputs", fun.name_in(), f"expected {self.dynamics.name_in()}")
        want = {"A": (self.nx, self.nx), "B": (self.nx, self.nu)}
        for name, shape in want.items():
            if name not in fun.name_out() or fun.size_out(fun.name_out().index(name)) != shape:
                raise InputError(_SRC, f"{where} outputs", fun.name_out(),
                                 f"expected outputs A {want['A']} and B {want['B']}")

    def _functions(self):
        for c in self.costs:
            yield f"Cost '{c.name}'", c.residual, (*STAGE_INPUTS, END_STATE)
        for c in self.terminal_costs:
            yield f"Cost '{c.name}' (terminal)", c.residual, TERMINAL_INPUTS
        for c in self.constraints:
            yield f"Constraint '{c.name}'", c.function, (*STAGE_INPUTS, END_STATE)
        for c in self.terminal_constraints:
            yield f"Constraint '{c.name}' (terminal)", c.function, TERMINAL_INPUTS

    def _set_bounds(self):
        for field, default in (("u_lb", -np.inf), ("u_ub", np.inf)):
            value = getattr(self, field)
            arr = np.full(self.nu, default) if value is None else np.asarray(value, dtype=float)
            if arr.ndim == 0:
                arr = np.full(self.nu, float(arr))
            if arr.shape != (self.nu,) or np.any(np.isnan(arr)):
                raise InputError(_SRC, field, value, f"expected {self.nu} numbers (use +-inf for no bound)")
            arr.setflags(write=False)
            object.__setattr__(self, field, arr)
        if np.any(self.u_lb > self.u_ub):
            raise InputError(_SRC, "u_lb", self.u_lb.tolist(), f"exceeds u_ub = {self.u_ub.tolist()}")

    # -- sizes ------------------------------------------------------------------------------
    @property
    def nx(self) -> int:
        return self._nx

    @property
    def nu(self) -> int:
        return self._nu

    @property
    def n_params(self) -> int:
        return self._np

    @property
    def n_constraints(self) -> int:
        return sum(c.size for c in self.constraints)

    @property
    def n_terminal_constraints(self) -> int:
        return sum(c.size for c in self.terminal_constraints)

    @property
    def has_box(self) -> bool:
        return bool(np.any(np.isfinite(self.u_lb)) or np.any(np.isfinite(self.u_ub)))

    # -- data checks used by every solver ---------------------------------------------------
    def check_x0(self, x0, source: str = "solve") -> np.ndarray:
        x = np.asarray(x0, dtype=float).reshape(-1) if np.ndim(x0) <= 1 else np.asarray(x0, dtype=float)
        if x.shape != (self.nx,) or not np.isfinite(x).all():
            raise InputError(source, "x0", np.asarray(x0).tolist(), f"expected {self.nx} finite numbers")
        return x

    def check_params(self, params, source: str = "solve") -> np.ndarray:
        """Return parameters as an (N+1, np) array; a single row (np,) is used at every knot."""
        shape = (self.horizon + 1, self.n_params)
        if params is None:
            if self.n_params:
                raise InputError(source, "params", None, f"expected an array of shape {shape}")
            return np.zeros(shape)
        arr = np.asarray(params, dtype=float)
        if arr.ndim == 1 and arr.shape == (self.n_params,):
            arr = np.tile(arr, (shape[0], 1))
        if arr.shape != shape:
            raise InputError(source, "params", f"array of shape {arr.shape}", f"expected shape {shape}")
        finite = np.isfinite(arr)
        if not finite.all():
            bad = np.argwhere(~finite)[0]
            raise InputError(source, "params", arr[tuple(bad)], "not finite", row=int(bad[0]))
        return arr

    def check_trajectory(self, xs, us, source: str = "warm_start") -> tuple[np.ndarray, np.ndarray]:
        N = self.horizon
        xs = np.asarray(xs, dtype=float)
        us = np.asarray(us, dtype=float)
        if xs.shape != (N + 1, self.nx):
            raise InputError(source, "xs", f"array of shape {xs.shape}", f"expected shape {(N + 1, self.nx)}")
        if us.shape != (N, self.nu):
            raise InputError(source, "us", f"array of shape {us.shape}", f"expected shape {(N, self.nu)}")
        if not (np.isfinite(xs).all() and np.isfinite(us).all()):
            raise InputError(source, "xs/us", "non-finite values", "warm start must be finite")
        return xs, us

    def with_horizon(self, horizon: int) -> "OptimalControlProblem":
        """The same problem over ``horizon`` knots, sharing the built :attr:`functions` (they do not depend
        on the horizon) and :attr:`structure_digest`."""
        other = dataclasses.replace(self, horizon=horizon)
        other.__dict__["structure_digest"] = self.structure_digest
        if "functions" in self.__dict__:
            other.__dict__["functions"] = self.functions
        return other

    @functools.cached_property
    def structure_digest(self) -> str | None:
        """Hash of everything but the horizon: the functions (serialised), the cost weights and the control
        box; None when a function cannot be serialised."""
        digest = hashlib.sha256(self.u_lb.tobytes() + self.u_ub.tobytes())
        funs = [self.dynamics, self.dynamics_jacobians] + [c.residual for c in self.costs + self.terminal_costs]
        funs += [c.function for c in self.constraints + self.terminal_constraints]
        try:
            for f in funs:
                digest.update(b"-" if f is None else f.serialize().encode())
        except RuntimeError:
            return None
        for c in self.costs + self.terminal_costs:
            digest.update(c.weight.tobytes())
        return digest.hexdigest()

    # -- symbolic building blocks (cached) --------------------------------------------------
    @functools.cached_property
    def functions(self) -> "ProblemFunctions":
        return ProblemFunctions.build(self)

    @functools.cached_property
    def transcription(self) -> "Transcription":
        return Transcription(self)


def _try_sx(fun: ca.Function) -> ca.Function:
    """Expand an MX function to SX when possible (faster evaluation and code generation)."""
    if fun.is_a("SXFunction"):
        return fun
    try:
        return fun.expand()
    except RuntimeError:
        return fun


@dataclasses.dataclass(frozen=True)
class ProblemFunctions:
    """The problem as five stacked casadi Functions, all with named inputs.

    step(x,u,p)->x_next; stage_residual(x,u,p)->r (sqrt(weight)*residual, stacked);
    stage_constraint(x,u,p)->g; terminal_residual(x,p)->r; terminal_constraint(x,p)->g.
    Costs are 0.5*|r|^2 with these weighted residuals. When a stage term reads the knot's end state,
    ``stage_terms(x,u,p,x_next)->(r,g)`` gives both with x_next free (the two above are it at x_next = step).
    """

    step: ca.Function
    stage_residual: ca.Function
    stage_constraint: ca.Function
    terminal_residual: ca.Function
    terminal_constraint: ca.Function
    symbolic: type
    step_jacobians: ca.Function | None = None
    stage_terms: ca.Function | None = None

    @staticmethod
    def build(problem: OptimalControlProblem) -> "ProblemFunctions":
        try:
            return ProblemFunctions._build(problem, ca.SX)
        except (RuntimeError, NotImplementedError):
            log.info("problem functions are not expandable to SX; using MX")
            return ProblemFunctions._build(problem, ca.MX)

    @staticmethod
    def _build(problem, sym) -> "ProblemFunctions":
        x, u, p = sym.sym("x", problem.nx), sym.sym("u", problem.nu), sym.sym("p", problem.n_params)
        xn = sym.sym(END_STATE, problem.nx)
        args = {"x": x, "u": u, "p": p, END_STATE: xn}
        targs = {"x": x, "p": p}
        fun = _try_sx if sym is ca.SX else (lambda f: f)
        x_next = _call_named(fun(problem.dynamics), "x_next", args, "dynamics")

        def stacked(items, arguments, out, weighted):
            parts = []
            for item in items:
                f = fun(item.residual if weighted else item.function)
                value = ca.vec(_call_named(f, out, arguments, item.name))
                parts.append(np.sqrt(item.weight) * value if weighted else value)
            return ca.vertcat(*parts) if parts else sym(0, 1)

        r = stacked(problem.costs, args, "r", True)
        g = stacked(problem.constraints, args, "g", False)
        terms = None
        if ca.depends_on(ca.vertcat(r, g), xn):
            terms = ca.Function("stage_terms", [x, u, p, xn], [r, g], [*STAGE_INPUTS, END_STATE], ["r", "g"])
            r, g = terms(x, u, p, x_next)
        rN = stacked(problem.terminal_costs, targs, "r", True)
        gN = stacked(problem.terminal_constraints, targs, "g", False)
        jac = None
        if problem.dynamics_jacobians is not None:
            AB = [_call_named(fun(problem.dynamics_jacobians), n, args, "dynamics_jacobians") for n in ("A", "B")]
            jac = ca.Function("step_jacobians", [x, u, p], AB, list(STAGE_INPUTS), ["A", "B"])
        return ProblemFunctions(
            step_jacobians=jac, stage_terms=terms,
            step=ca.Function("step", [x, u, p], [x_next], list(STAGE_INPUTS), ["x_next"]),
            stage_residual=ca.Function("stage_residual", [x, u, p], [r], list(STAGE_INPUTS), ["r"]),
            stage_constraint=ca.Function("stage_constraint", [x, u, p], [g], list(STAGE_INPUTS), ["g"]),
            terminal_residual=ca.Function("terminal_residual", [x, p], [rN], list(TERMINAL_INPUTS), ["r"]),
            terminal_constraint=ca.Function("terminal_constraint", [x, p], [gN], list(TERMINAL_INPUTS), ["g"]),
            symbolic=sym,
        )


class Transcription:
    """Multiple-shooting NLP of the problem, shared by IPOPT and fatrop.

    Variables in stage order w = [x_0, u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N] (as fatrop's
    structure detection needs). NLP parameters: [x0; vec(params^T)]. Constraints in stage
    order: [x_0 - x0], then per knot k [x_{k+1} - f(x_k,u_k,p_k); g(x_k,u_k,p_k)], then g_N.
    Equalities have lbg = ubg = 0; inequalities lbg = -inf, ubg = 0. Control bounds are
    variable bounds.
    """

    def __init__(self, problem: OptimalControlProblem):
        self.problem = problem
        f = problem.functions
        nx, nu, n_p, N = problem.nx, problem.nu, problem.n_params, problem.horizon
        ng, ngN = problem.n_constraints, problem.n_terminal_constraints
        self.n_w = N * (nx + nu) + nx
        w = ca.MX.sym("w", self.n_w)
        par = ca.MX.sym("par", nx + (N + 1) * n_p)
        x0, P = par[:nx], ca.reshape(par[nx:], n_p, N + 1)
        stages = ca.reshape(w[: N * (nx + nu)], nx + nu, N)
        X, U, xN = stages[:nx, :], stages[nx:, :], w[N * (nx + nu):]
        X_next = ca.horzcat(X[:, 1:], xN)
        gaps = X_next - f.step.map(N)(X, U, P[:, :N])
        G = f.stage_constraint.map(N)(X, U, P[:, :N])
        R = f.stage_residual.map(N)(X, U, P[:, :N])
        rN, gN = f.terminal_residual(xN, P[:, N]), f.terminal_constraint(xN, P[:, N])
        self.nlp = {"x": w, "p": par, "f": 0.5 * (ca.sumsqr(R) + ca.sumsqr(rN)),
                    "g": ca.vertcat(X[:, 0] - x0, ca.vec(ca.vertcat(gaps, G)), gN)}
        stage_eq = np.concatenate([np.ones(nx, bool), np.zeros(ng, bool)])
        self.equality = np.concatenate([np.ones(nx, bool), np.tile(stage_eq, N), np.zeros(ngN, bool)])
        self.lbg = np.where(self.equality, 0.0, -np.inf)
        self.ubg = np.zeros(self.equality.size)
        lb_stage = np.concatenate([np.full(nx, -np.inf), problem.u_lb])
        ub_stage = np.concatenate([np.full(nx, np.inf), problem.u_ub])
        self.lbx = np.concatenate([np.tile(lb_stage, N), np.full(nx, -np.inf)])
        self.ubx = np.concatenate([np.tile(ub_stage, N), np.full(nx, np.inf)])

    def pack(self, xs: np.ndarray, us: np.ndarray) -> np.ndarray:
        N = self.problem.horizon
        return np.concatenate([np.hstack([xs[:N], us]).reshape(-1), xs[N]])

    def unpack(self, w) -> tuple[np.ndarray, np.ndarray]:
        p = self.problem
        w = np.asarray(w, dtype=float).reshape(-1)
        stages = w[: p.horizon * (p.nx + p.nu)].reshape(p.horizon, p.nx + p.nu)
        xs = np.vstack([stages[:, : p.nx], w[None, p.horizon * (p.nx + p.nu):]])
        return xs, stages[:, p.nx:].copy()

    def parameters(self, x0: np.ndarray, params: np.ndarray) -> np.ndarray:
        return np.concatenate([x0, params.reshape(-1)])

    def split_constraint_multipliers(self, lam_g) -> dict[str, np.ndarray]:
        """Split NLP multipliers into initial, dynamics (N, nx), path (N, ng) and terminal ones."""
        p = self.problem
        lam = np.asarray(lam_g, dtype=float).reshape(-1)
        nx, ng, N = p.nx, p.n_constraints, p.horizon
        stage = lam[nx: nx + N * (nx + ng)].reshape(N, nx + ng)
        return {"initial": lam[:nx], "dynamics": stage[:, :nx], "constraints": stage[:, nx:],
                "terminal_constraints": lam[nx + N * (nx + ng):]}
