"""Stage terms that read the knot's end state (input ``x_next``): DDP's local model from the chain rule through
the dynamics' A, B (and their curvature in the dynamics' second-order term) equals, to rounding, the same terms
written as functions of (x, u, p) through the step and differentiated by CasADi; every backend; the solve
reaches the same plan; the multi-model problem gives each scenario its own end state."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.multi_model import MultiModelProblem
from thermo_ddp.ocp import Constraint, Cost, OptimalControlProblem
from thermo_ddp.solvers import DDPSettings, DDPSolver, WarmStart
from thermo_ddp.testing.thermal_pendulum import K_BEMF, R0, ALPHA_CU, T_AMB, V_MAX, thermal_pendulum, x0_of

RHO = 100.0


def _end_voltage(xn, u):
    """The pendulum's voltage rows at the knot's end under its held current, and a cost on the end speed."""
    volt = R0 * (1 + ALPHA_CU * (xn[2] - T_AMB)) * u + K_BEMF * xn[1]
    return ca.vertcat(volt - V_MAX, -volt - V_MAX), 0.3 * xn[1] * u


def _problems(horizon=40):
    """The same problem twice: the end rows read ``x_next``, or are composed with the step (x, u, p)."""
    base = thermal_pendulum(horizon=horizon, t_max=32.5, n_thermal=3)
    x, u, p, xn = ca.SX.sym("x", 5), ca.SX.sym("u"), ca.SX.sym("p"), ca.SX.sym("x_next", 5)
    g, r = _end_voltage(xn, u)
    g_c, r_c = _end_voltage(base.dynamics(x, u, p), u)
    end = {"x": x, "u": u, "p": p, "x_next": xn}
    out = []
    for (gg, rr), names in (((g, r), ("x", "u", "p", "x_next")), ((g_c, r_c), ("x", "u", "p"))):
        ins = [end[n] for n in names]
        out.append(dataclasses.replace(
            base, constraints=base.constraints + (Constraint("end_voltage", ca.Function("g", ins, [gg], names, ["g"])),),
            costs=base.costs + (Cost("end_power", 1.0, ca.Function("r", ins, [rr], names, ["r"])),)))
    return out


def _iterate(problem, seed=3):
    rng = np.random.default_rng(seed)
    N = problem.horizon
    xs = np.tile(x0_of(3), (N + 1, 1)) + 0.05 * rng.standard_normal((N + 1, 5))
    xs[:, 1] += 2.0  # fast: the end rows' back-EMF matters
    us = rng.uniform(-3.0, 3.0, (N, 1))
    lam = rng.uniform(0.0, 2.0, (N, problem.n_constraints)) * (rng.random((N, problem.n_constraints)) < 0.5)
    return xs, us, np.full((N + 1, 1), 1.0), lam, rng.uniform(0.0, 1.0, problem.n_terminal_constraints)


@pytest.mark.parametrize("full", [True, False], ids=["full_ddp", "gauss_newton"])
def test_the_chain_rule_model_equals_the_composed_terms_derivatives(full):
    end, composed = _problems()
    assert end.functions.stage_terms is not None and composed.functions.stage_terms is None
    X, U, P, lam, lamN = _iterate(end)
    oracle = DDPSolver(composed, DDPSettings(backend="casadi", full_second_order=full)).backend
    C = oracle.evaluate(X, U, P)[3]
    want = oracle.backward(X, U, P, lam, lamN, C, RHO, 10.0)
    assert want[1][3] > 0  # a successful pass: the policy is defined at every knot
    for backend in ("codegen", "casadi", "numpy"):
        got = DDPSolver(end, DDPSettings(backend=backend, full_second_order=full)).backend
        np.testing.assert_allclose(got.evaluate(X, U, P)[1], oracle.evaluate(X, U, P)[1], rtol=0, atol=1e-12)
        for g, w in zip(got.backward(X, U, P, lam, lamN, C, RHO, 10.0), want):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-9 * (1.0 + np.max(np.abs(w))), err_msg=backend)


def test_the_solve_reaches_the_composed_problems_plan():
    problems, plans = _problems(horizon=60), []
    for problem in problems:
        solver = DDPSolver(problem, DDPSettings(full_second_order=True))
        guess = WarmStart(np.tile(x0_of(3), (61, 1)), np.zeros((60, 1)))
        plans.append(solver.solve(x0_of(3), np.full((61, 1), 1.0), guess))
    end, composed = plans
    assert end.success and composed.success
    assert abs(end.cost - composed.cost) <= 1e-6 * abs(composed.cost)
    np.testing.assert_allclose(end.us, composed.us, atol=1e-4)
    g = problems[0].functions.stage_constraint.map(60)(end.xs[:-1].T, end.us.T, np.ones((1, 60)))
    rows = np.asarray(g)[-2:]  # the end voltage's two rows
    assert -0.05 < rows.max() <= 1e-4  # they bind and hold


def test_terminal_terms_cannot_read_an_end_state():
    base = thermal_pendulum(horizon=5)
    x, p, xn = ca.SX.sym("x", 3), ca.SX.sym("p"), ca.SX.sym("x_next", 3)
    bad = Constraint("end", ca.Function("g", [x, p, xn], [xn[2] - x[2]], ["x", "p", "x_next"], ["g"]))
    with pytest.raises(InputError, match="x_next"):
        dataclasses.replace(base, terminal_constraints=(bad,))
    short = ca.SX.sym("x_next", 2)
    wrong = Constraint("end", ca.Function("g", [x, short], [short[0]], ["x", "x_next"], ["g"]))
    with pytest.raises(InputError, match="x_next"):
        dataclasses.replace(base, constraints=(wrong,))


def test_each_scenario_reads_its_own_end_state():
    """Two scenarios of a cooling node share the speed; a row on the end temperature is imposed per scenario at
    that scenario's own step (oracle: the scenario's dynamics evaluated by hand)."""
    x, u, th, xn = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("theta"), ca.SX.sym("x_next", 2)
    dyn = ca.Function("f", [x, u, th], [ca.vertcat(x[0] + 0.1 * u, x[1] + 0.1 * (th * u ** 2 - x[1]))],
                      ["x", "u", "theta"], ["x_next"])
    row = Constraint("hot", ca.Function("g", [x, u, xn], [xn[1] - 50.0], ["x", "u", "x_next"], ["g"]))
    mm = MultiModelProblem(dyn, 3, 2, shared=1, constraints=(row,))
    names = [c.name for c in mm.problem.constraints]
    assert names == ["hot[s0]", "hot[s1]"]
    xs, thetas = np.array([0.2, 30.0, 40.0]), np.array([[2.0], [5.0]])
    P = mm.params(None, thetas)
    g = np.asarray(mm.problem.functions.stage_constraint(xs, 3.0, P[0])).ravel()
    want = [float(dyn(np.array([0.2, t0]), 3.0, th)[1]) - 50.0 for t0, th in ((30.0, 2.0), (40.0, 5.0))]
    np.testing.assert_allclose(g, want, rtol=0, atol=1e-12)
