"""Several models that share one control trajectory, as one :class:`~thermo_ddp.ocp.OptimalControlProblem`.

K scenarios of one model ``x+ = f(x, u, p, theta)`` differ only in their parameter vector ``theta`` (a
runtime parameter: one built, compiled solver serves any scenario values with the same count K). The
first ``shared`` states are common to every scenario, so they appear once in the stacked state::

    X = [s; z_0; z_1; ...; z_{K-1}]        (x_k = [s; z_k] is scenario k's state)
    P = [p; theta_0; ...; theta_{K-1}]     (per-knot parameters: the model's own, then each scenario's)

and the solver's state grows by the private part only (a DDP's work grows with nx^3). The shared
states' dynamics must read neither the private states nor ``theta`` (checked): e.g. the mechanical
state (q, v) of thermal scenarios, which all follow the same control.

Terms, given as for one scenario (inputs among x, u, p, theta; a stage term also ``x_next``, the scenario's state
at the knot's end):
- costs: on the nominal scenario 0 (``cost_on="nominal"``, the default), or on the mean over the
  scenarios (``"mean"``: each scenario's residual weighted by 1/K); a term that reads only the shared
  states and p is the same for every scenario and appears once;
- constraints: imposed on every scenario, the copies named ``name[s<k>]``; a constraint that reads only
  the shared states and p appears once, under its own name;
- cross-scenario costs (``cross_costs``, ``terminal_cross_costs``): residuals of every scenario at once,
  inputs among ``X`` (nx x K: scenario k's whole state in column k), u, p and ``Theta`` (n_theta x K),
  e.g. the divergence of the scenarios' predicted measurements.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Sequence

import casadi as ca
import numpy as np

from .errors import InputError
from .ocp import END_STATE, Constraint, Cost, KnotParameters, OptimalControlProblem, _try_sx, term_function

COST_ON = ("nominal", "mean")
SCENARIO_INPUTS = ("x", "u", "p", "theta")
STAGE_TERM_INPUTS = (*SCENARIO_INPUTS, END_STATE)
CROSS_INPUTS = ("X", "u", "p", "Theta")
_SRC = "MultiModelProblem"


def scenario_name(name: str, scenario: int) -> str:
    """The name of scenario ``scenario``'s copy of a term: ``winding_limit[s3]``."""
    return f"{name}[s{scenario}]"


def _inputs(fun: ca.Function, allowed: Sequence[str], where: str) -> None:
    if not isinstance(fun, ca.Function):
        raise InputError(_SRC, where, type(fun).__name__, "expected a casadi.Function")
    unknown = [n for n in fun.name_in() if n not in allowed]
    if unknown:
        raise InputError(_SRC, f"{where} inputs", fun.name_in(), f"allowed input names: {', '.join(allowed)}")


def _call(fun: ca.Function, args: dict):
    """``fun`` on the entries of ``args`` it declares (by name); its first output, dense."""
    missing = [n for n in fun.name_in() if n not in args]
    if missing:
        raise InputError(_SRC, f"{fun.name()} inputs", fun.name_in(), f"'{missing[0]}' is not available here "
                         f"(allowed: {', '.join(args)})")
    return ca.densify(fun.call({n: args[n] for n in fun.name_in()})[fun.name_out()[0]])


@dataclasses.dataclass(frozen=True, eq=False)
class MultiModelProblem:
    """K scenarios of ``dynamics(x, u, p, theta) -> x_next`` sharing the control and the first ``shared``
    states (see the module docstring). :attr:`problem` is the stacked OCP every solver takes;
    :meth:`x0`, :meth:`params` and :meth:`scenario_states` convert to and from the stacked layout.
    ``parameters`` names the blocks of the model's own p (the stacked one adds ``theta_s<k>``)."""

    dynamics: ca.Function
    horizon: int
    scenarios: int
    shared: int = 0
    costs: Sequence[Cost] = ()
    terminal_costs: Sequence[Cost] = ()
    cross_costs: Sequence[Cost] = ()
    terminal_cross_costs: Sequence[Cost] = ()
    cost_on: str = "nominal"                      # the scenarios' own costs: on the nominal one, or the mean
    constraints: Sequence[Constraint] = ()
    terminal_constraints: Sequence[Constraint] = ()
    u_lb: Sequence[float] | np.ndarray | None = None
    u_ub: Sequence[float] | np.ndarray | None = None
    parameters: KnotParameters | None = None
    name: str = "multi_model"

    def __post_init__(self):
        _inputs(self.dynamics, SCENARIO_INPUTS, "dynamics")
        if "x_next" not in self.dynamics.name_out() or "theta" not in self.dynamics.name_in():
            raise InputError(_SRC, "dynamics", self.dynamics.name_in(), "expected inputs x, u, (p,) theta -> x_next")
        if not isinstance(self.scenarios, (int, np.integer)) or isinstance(self.scenarios, bool) or self.scenarios < 1:
            raise InputError(_SRC, "scenarios", self.scenarios, "expected an integer >= 1")
        if self.cost_on not in COST_ON:
            raise InputError(_SRC, "cost_on", self.cost_on, f"choose one of {', '.join(COST_ON)}")
        sizes = {n: self.dynamics.size1_in(i) for i, n in enumerate(self.dynamics.name_in())}
        object.__setattr__(self, "_sizes", {"p": 0, **sizes})
        if not 0 <= self.shared < self.nx_scenario:
            raise InputError(_SRC, "shared", self.shared, f"expected 0 to {self.nx_scenario - 1} shared states")
        if self.parameters is not None and self.parameters.size != self.n_params:
            raise InputError(_SRC, "parameters", self.parameters.blocks, f"the dynamics take {self.n_params}")
        for field, allowed in (("costs", STAGE_TERM_INPUTS), ("terminal_costs", SCENARIO_INPUTS),
                               ("constraints", STAGE_TERM_INPUTS), ("terminal_constraints", SCENARIO_INPUTS),
                               ("cross_costs", CROSS_INPUTS), ("terminal_cross_costs", CROSS_INPUTS)):
            object.__setattr__(self, field, tuple(getattr(self, field)))
            for term in getattr(self, field):
                _inputs(term.residual if isinstance(term, Cost) else term.function, allowed, f"{field} '{term.name}'")
        self._check_shared_dynamics()

    # -- sizes and layout -------------------------------------------------------------------
    @property
    def nx_scenario(self) -> int:
        return self._sizes["x"]

    @property
    def n_private(self) -> int:
        return self.nx_scenario - self.shared

    @property
    def nu(self) -> int:
        return self._sizes["u"]

    @property
    def n_params(self) -> int:
        return self._sizes["p"]

    @property
    def n_theta(self) -> int:
        return self._sizes["theta"]

    @property
    def nx(self) -> int:
        """States of the stacked problem: the shared ones once, the private ones per scenario."""
        return self.shared + self.scenarios * self.n_private

    @functools.cached_property
    def stacked_parameters(self) -> KnotParameters:
        own = self.parameters.blocks if self.parameters is not None else ((("p", self.n_params),) if self.n_params else ())
        return KnotParameters(own + tuple((f"theta_s{k}", self.n_theta) for k in range(self.scenarios)))

    def x0(self, scenario_x0) -> np.ndarray:
        """The stacked initial state from each scenario's (K, nx) or one state (nx,) for all; the shared
        part must be the same in every scenario."""
        x = np.asarray(scenario_x0, dtype=float)
        x = np.tile(x, (self.scenarios, 1)) if x.ndim == 1 else x
        if x.shape != (self.scenarios, self.nx_scenario) or not np.all(np.isfinite(x)):
            raise InputError(_SRC, "scenario_x0", f"array of shape {x.shape}",
                             f"expected {self.scenarios} finite states of {self.nx_scenario}")
        s = self.shared
        if not np.allclose(x[:, :s], x[0, :s], rtol=0, atol=1e-12):
            raise InputError(_SRC, "scenario_x0", x[:, :s].tolist(), "the shared states differ between scenarios")
        return np.concatenate([x[0, :s], x[:, s:].reshape(-1)])

    def params(self, model_params, thetas) -> np.ndarray:
        """The stacked (N+1, n_params + K n_theta) parameters from the model's own (N+1, n_params) (None
        when it has none) and each scenario's theta (K, n_theta), constant over the knots."""
        knots = self.horizon + 1
        own = np.zeros((knots, 0)) if model_params is None else np.asarray(model_params, dtype=float)
        th = np.asarray(thetas, dtype=float)
        if own.shape != (knots, self.n_params):
            raise InputError(_SRC, "model_params", f"array of shape {own.shape}", f"expected ({knots}, {self.n_params})")
        if th.shape != (self.scenarios, self.n_theta) or not np.all(np.isfinite(th)):
            raise InputError(_SRC, "thetas", f"array of shape {th.shape}",
                             f"expected {self.scenarios} finite rows of {self.n_theta}")
        return np.hstack([own, np.tile(th.reshape(1, -1), (knots, 1))])

    def scenario_states(self, xs) -> np.ndarray:
        """(..., K, nx) every scenario's whole state from stacked states (..., nx_stacked)."""
        xs = np.asarray(xs, dtype=float)
        private = xs[..., self.shared:].reshape(*xs.shape[:-1], self.scenarios, self.n_private)
        shared = np.broadcast_to(xs[..., None, :self.shared], (*xs.shape[:-1], self.scenarios, self.shared))
        return np.concatenate([shared, private], axis=-1)

    def stack_states(self, scenario_xs) -> np.ndarray:
        """Stacked states (..., nx_stacked) from every scenario's (..., K, nx) (the shared part of scenario 0)."""
        x = np.asarray(scenario_xs, dtype=float)
        return np.concatenate([x[..., 0, :self.shared], x[..., self.shared:].reshape(*x.shape[:-2], -1)], axis=-1)

    def with_horizon(self, horizon: int) -> "MultiModelProblem":
        """The same scenarios over ``horizon`` knots, sharing the built stacked functions."""
        other = dataclasses.replace(self, horizon=horizon)
        if "problem" in self.__dict__:
            other.__dict__["problem"] = self.problem.with_horizon(horizon)
        return other

    # -- the stacked problem ------------------------------------------------------------------
    @functools.cached_property
    def problem(self) -> OptimalControlProblem:
        """The stacked OCP (states :attr:`nx`, parameters :attr:`stacked_parameters`)."""
        sym = _Symbols(self)
        return OptimalControlProblem(
            sym.function("dynamics", self._stacked_step(sym), "x_next"), self.horizon,
            self._costs(sym, self.costs, False) + self._cross(sym, self.cross_costs, False),
            self._costs(sym, self.terminal_costs, True) + self._cross(sym, self.terminal_cross_costs, True),
            self._constraints(sym, self.constraints, False), self._constraints(sym, self.terminal_constraints, True),
            u_lb=self.u_lb, u_ub=self.u_ub, name=self.name, parameters=self.stacked_parameters)

    def _check_shared_dynamics(self):
        x, u = ca.SX.sym("x", self.nx_scenario), ca.SX.sym("u", self.nu)
        p, theta = ca.SX.sym("p", self.n_params), ca.SX.sym("theta", self.n_theta)
        out = _call(_try_sx(self.dynamics), {"x": x, "u": u, "p": p, "theta": theta})
        if out.shape != (self.nx_scenario, 1):
            raise InputError(_SRC, "dynamics x_next", out.shape, f"expected ({self.nx_scenario}, 1)")
        if self.shared and ca.depends_on(out[:self.shared], ca.vertcat(x[self.shared:], theta)):
            raise InputError(_SRC, "shared", self.shared, "the shared states' dynamics read the private states or "
                             "theta: they cannot be shared")

    def _stacked_step(self, sym) -> ca.SX:
        nexts = [_call(_try_sx(self.dynamics), sym.scenario(k, stage=True)) for k in range(self.scenarios)]
        return ca.vertcat(nexts[0][:self.shared, 0], *[xn[self.shared:, 0] for xn in nexts])

    def _depends_on_scenario(self, fun: ca.Function) -> bool:
        x, xn = ca.SX.sym("x", self.nx_scenario), ca.SX.sym(END_STATE, self.nx_scenario)
        th = ca.SX.sym("theta", self.n_theta)
        args = {"x": x, "u": ca.SX.sym("u", self.nu), "p": ca.SX.sym("p", self.n_params), "theta": th, END_STATE: xn}
        return bool(ca.depends_on(_call(_try_sx(fun), args), ca.vertcat(x[self.shared:], xn[self.shared:], th)))

    def _costs(self, sym, costs, terminal: bool) -> tuple[Cost, ...]:
        out = []
        for c in costs:
            if self.cost_on == "nominal" or not self._depends_on_scenario(c.residual):
                r, w = _call(_try_sx(c.residual), sym.scenario(0, not terminal)), c.weight
            else:  # the mean over the scenarios: 0.5 w |r_k|^2 / K summed over k
                r = ca.vertcat(*[_call(_try_sx(c.residual), sym.scenario(k, not terminal)) / np.sqrt(self.scenarios)
                                 for k in range(self.scenarios)])
                w = np.tile(c.weight, self.scenarios)
            out.append(Cost(c.name, w, sym.function(c.name, r, "r", terminal)))
        return tuple(out)

    def _cross(self, sym, costs, terminal: bool) -> tuple[Cost, ...]:
        return tuple(Cost(c.name, c.weight, sym.function(c.name, _call(_try_sx(c.residual), sym.cross(not terminal)),
                                                         "r", terminal)) for c in costs)

    def _constraints(self, sym, constraints, terminal: bool) -> tuple[Constraint, ...]:
        out = []
        for c in constraints:
            copies = range(self.scenarios) if self._depends_on_scenario(c.function) else (None,)
            for k in copies:
                g = _call(_try_sx(c.function), sym.scenario(k or 0, not terminal))
                name = c.name if k is None else scenario_name(c.name, k)
                out.append(Constraint(name, sym.function(f"{c.name}_s{k or 0}", g, "g", terminal)))
        return tuple(out)


class _Symbols:
    """Symbols of the stacked problem and each scenario's view of them."""

    def __init__(self, mm: MultiModelProblem):
        self.mm = mm
        self.x = ca.SX.sym("x", mm.nx)
        self.u = ca.SX.sym("u", mm.nu)
        self.p = ca.SX.sym("p", mm.n_params + mm.scenarios * mm.n_theta)
        self.x_next = ca.SX.sym(END_STATE, mm.nx)

    def state(self, k: int, stacked=None):
        """Scenario ``k``'s whole state in the stacked state ``stacked`` (default: the knot's x)."""
        mm, s, x = self.mm, self.mm.shared, self.x if stacked is None else stacked
        return ca.vertcat(x[:s, 0], x[s + k * mm.n_private: s + (k + 1) * mm.n_private])

    def theta(self, k: int):
        start = self.mm.n_params + k * self.mm.n_theta
        return self.p[start: start + self.mm.n_theta]

    def scenario(self, k: int, stage: bool) -> dict:
        args = {"x": self.state(k), "p": self.p[:self.mm.n_params], "theta": self.theta(k)}
        return args | {"u": self.u, END_STATE: self.state(k, self.x_next)} if stage else args

    def cross(self, stage: bool) -> dict:
        K = range(self.mm.scenarios)
        args = {"X": ca.horzcat(*[self.state(k) for k in K]), "p": self.p[:self.mm.n_params],
                "Theta": ca.horzcat(*[self.theta(k) for k in K])}
        return args | {"u": self.u} if stage else args

    def function(self, name: str, expr, out: str, terminal: bool = False) -> ca.Function:
        name = f"{name}_stacked".replace("[", "_").replace("]", "")
        if terminal:
            return term_function(name, expr, out, self.x, self.p)
        return term_function(name, expr, out, self.x, self.p, self.u, self.x_next)
