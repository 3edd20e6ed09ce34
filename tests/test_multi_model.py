"""The multi-model problem (thermo_ddp.multi_model): scenarios that share one control, as one OCP.

Oracles: the single-model problem (K identical scenarios must give its solution), IPOPT on the same
stacked problem, and hand-evaluated residuals for the cross-scenario costs.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.multi_model import MultiModelProblem
from thermo_ddp.ocp import Constraint, Cost, OptimalControlProblem
from thermo_ddp.solvers import DDPSettings, DDPSolver, IpoptSolver

N, DT = 60, 0.05
T_AMB, T_MAX = 25.0, 33.0
NOMINAL = np.array([2.0, 0.5])          # theta = [thermal resistance K/W, capacity J/K]
GOAL = np.minimum(np.linspace(0.0, 3.0, N + 1), 1.5)[:, None]


def toy(scenario_dynamics: bool = True):
    """A pendulum lifted by a current (q, v shared) with a one-node winding whose resistance to ambient
    and capacity are theta: dynamics, costs and constraints of one scenario."""
    x, u, p, th = ca.SX.sym("x", 3), ca.SX.sym("u"), ca.SX.sym("p"), ca.SX.sym("theta", 2)
    q, v, tw = x[0], x[1], x[2]
    heat = 5.0 * (1 + 0.00393 * (tw - T_AMB)) * u ** 2

    def ode(z):
        return ca.vertcat(z[1], (2.0 * u - 2.45 * ca.sin(z[0]) - 0.1 * z[1]) / 0.3,
                          (heat - (z[2] - T_AMB) / th[0]) / th[1])

    k1 = ode(x)
    k2 = ode(x + DT / 2 * k1)
    k3 = ode(x + DT / 2 * k2)
    k4 = ode(x + DT * k3)
    step = ca.Function("step", [x, u, p, th], [x + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)], ["x", "u", "p", "theta"],
                       ["x_next"])
    costs = [Cost("goal", 10.0, ca.Function("r", [x, p], [q - p], ["x", "p"], ["r"])),
             Cost("current", 0.05, ca.Function("r", [u], [u], ["u"], ["r"])),
             Cost("heat", 0.01, ca.Function("r", [x, u], [ca.sqrt(1 + 0.00393 * (tw - T_AMB)) * u], ["x", "u"], ["r"]))]
    terminal = [Cost("goal_end", [100.0, 10.0], ca.Function("r", [x, p], [ca.vertcat(q - p, v)], ["x", "p"], ["r"]))]
    constraints = [Constraint("winding", ca.Function("g", [x], [tw - T_MAX], ["x"], ["g"])),
                   Constraint("speed", ca.Function("g", [x], [ca.vertcat(v - 3.0, -v - 3.0)], ["x"], ["g"]))]
    terminal_constraints = [Constraint("winding_end", ca.Function("g", [x], [tw - T_MAX], ["x"], ["g"]))]
    return step, costs, terminal, constraints, terminal_constraints


def multi(scenarios, **options):
    step, costs, terminal, cons, tcons = toy()
    return MultiModelProblem(step, N, scenarios, shared=2, costs=costs, terminal_costs=terminal, constraints=cons,
                             terminal_constraints=tcons, u_lb=[-4.0], u_ub=[4.0], **options)


def single(theta):
    """The one-scenario OCP with theta fixed: the oracle of K identical scenarios."""
    step, costs, terminal, cons, tcons = toy()
    x, u, p = ca.SX.sym("x", 3), ca.SX.sym("u"), ca.SX.sym("p")
    fixed = ca.Function("step", [x, u, p], [step(x, u, p, theta)], ["x", "u", "p"], ["x_next"])
    return OptimalControlProblem(fixed, N, costs, terminal, cons, tcons, u_lb=[-4.0], u_ub=[4.0])


X0 = np.array([0.0, 0.0, 30.0])
DDP = DDPSettings(backend="casadi", full_second_order=True)


def test_stacked_layout_shares_the_mechanics_and_names_scenario_constraints():
    mm = multi(3)
    assert (mm.nx, mm.problem.nx, mm.problem.n_params) == (5, 5, 1 + 3 * 2)
    names = [c.name for c in mm.problem.constraints]
    assert names == ["winding[s0]", "winding[s1]", "winding[s2]", "speed"]  # speed reads only shared states
    assert [c.name for c in mm.problem.terminal_constraints] == ["winding_end[s0]", "winding_end[s1]", "winding_end[s2]"]
    thetas = np.array([NOMINAL, NOMINAL * 1.2, NOMINAL * 0.8])
    x0 = mm.x0(np.array([[0.1, 0.2, 30.0], [0.1, 0.2, 31.0], [0.1, 0.2, 29.0]]))
    np.testing.assert_array_equal(x0, [0.1, 0.2, 30.0, 31.0, 29.0])
    params = mm.params(GOAL, thetas)
    # the stacked step equals each scenario's own step
    step = toy()[0]
    xn = np.array(mm.problem.functions.step(x0, 0.7, params[0])).ravel()
    for k, xk in enumerate(mm.scenario_states(x0)):
        np.testing.assert_allclose(mm.scenario_states(xn)[k], np.array(step(xk, 0.7, GOAL[0], thetas[k])).ravel(),
                                   rtol=1e-14)
    np.testing.assert_array_equal(mm.stack_states(mm.scenario_states(xn)), xn)


def test_identical_scenarios_give_the_nominal_solution():
    """One scenario is the single model iterate for iterate; K identical ones reach its optimum (the
    duplicated constraints change the augmented Lagrangian's path, not the solution)."""
    ref = DDPSolver(single(NOMINAL), DDP).solve(X0, GOAL)
    assert ref.success and ref.xs[:, 2].max() >= T_MAX - 1e-4  # the winding limit binds
    one = multi(1)
    res = DDPSolver(one.problem, DDP).solve(one.x0(X0), one.params(GOAL, NOMINAL[None]))
    assert res.iterations == ref.iterations and res.cost == pytest.approx(ref.cost, rel=1e-12)
    np.testing.assert_allclose(res.us, ref.us, rtol=0, atol=1e-10)
    for cost_on in ("nominal", "mean"):
        mm = multi(3, cost_on=cost_on)
        res = DDPSolver(mm.problem, DDP).solve(mm.x0(X0), mm.params(GOAL, np.tile(NOMINAL, (3, 1))))
        assert res.success, res.message
        assert abs(res.cost - ref.cost) <= 1e-6 * ref.cost  # both within the constraint tolerance 1e-6
        np.testing.assert_allclose(res.us, ref.us, atol=1e-4)
        for k in range(3):
            np.testing.assert_allclose(mm.scenario_states(res.xs)[:, k], ref.xs, atol=1e-5)


@pytest.mark.parametrize("cost_on", ["nominal", "mean"])
def test_ddp_equals_ipopt_on_a_scenario_problem(cost_on):
    mm = multi(3, cost_on=cost_on)
    thetas = np.array([NOMINAL, [2.4, 0.4], [1.6, 0.6]])  # the hottest scenario binds
    x0, params = mm.x0(X0), mm.params(GOAL, thetas)
    ref = IpoptSolver(mm.problem, {"tolerance": 1e-9}).solve(x0, params)
    res = DDPSolver(mm.problem, DDP).solve(x0, params)
    assert ref.success and res.success, res.message
    assert abs(res.cost - ref.cost) <= 1e-5 * ref.cost
    np.testing.assert_allclose(res.us, ref.us, atol=1e-3)
    windings = mm.scenario_states(res.xs)[:, :, 2]
    assert windings[:, 1].max() == pytest.approx(T_MAX, abs=1e-4)  # the hot scenario is at its limit
    assert windings[:, 0].max() < T_MAX - 0.5                       # the nominal one is not
    nominal_alone = DDPSolver(single(NOMINAL), DDP).solve(X0, GOAL)
    assert ref.cost > nominal_alone.cost  # the hot scenario costs tracking


def test_cross_scenario_cost_sees_every_scenario():
    """A cross cost (the spread of the windings) evaluated by the stacked problem equals the hand value."""
    X, th = ca.SX.sym("X", 3, 2), ca.SX.sym("Theta", 2, 2)
    spread = Cost("spread", 0.5, ca.Function("r", [X, th], [X[2, 0] - X[2, 1] + th[0, 1]], ["X", "Theta"], ["r"]))
    mm = multi(2, cross_costs=[spread])
    thetas = np.array([NOMINAL, [2.5, 0.4]])
    x0, params = mm.x0(np.array([[0.0, 0.0, 30.0], [0.0, 0.0, 34.0]])), mm.params(GOAL, thetas)
    r = np.array(mm.problem.functions.stage_residual(x0, 1.0, params[0])).ravel()
    names = [c.name for c in mm.problem.costs]
    assert names == ["goal", "current", "heat", "spread"]
    assert r[-1] == pytest.approx(np.sqrt(0.5) * (30.0 - 34.0 + 2.5))
    # the nominal heat cost reads scenario 0's winding only
    assert r[2] == pytest.approx(np.sqrt(0.01) * np.sqrt(1 + 0.00393 * 5.0) * 1.0)


def test_bad_multi_model_input_is_refused():
    step, costs, *_ = toy()
    x, u, p, th = ca.SX.sym("x", 3), ca.SX.sym("u"), ca.SX.sym("p"), ca.SX.sym("theta", 2)
    leaky = ca.Function("step", [x, u, p, th], [step(x, u, p, th) + ca.vertcat(0, 1e-3 * x[2], 0)],
                        ["x", "u", "p", "theta"], ["x_next"])  # v reads the winding: not shareable
    with pytest.raises(InputError, match="cannot be shared"):
        MultiModelProblem(leaky, N, 2, shared=2)
    with pytest.raises(InputError, match="shared"):
        MultiModelProblem(step, N, 2, shared=3)
    with pytest.raises(InputError, match="cost_on"):
        MultiModelProblem(step, N, 2, shared=2, cost_on="worst")
    with pytest.raises(InputError, match="scenarios"):
        MultiModelProblem(step, N, 0, shared=2)
    mm = multi(2)
    with pytest.raises(InputError, match="shared states differ"):
        mm.x0(np.array([[0.0, 0.0, 30.0], [0.1, 0.0, 30.0]]))
    with pytest.raises(InputError, match="thetas"):
        mm.params(GOAL, np.ones((3, 2)))


def test_scenarios_of_one_state_without_shared_states():
    """One private state per scenario and no shared one (a thermal node per explanation, issue 25): the stacked
    step is each scenario's own step, and a cross cost reads every scenario."""
    x, u, th = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("theta", 2)
    step = ca.Function("step", [x, u, th], [x + DT * (5.0 * u ** 2 - (x - T_AMB) / th[0]) / th[1]],
                       ["x", "u", "theta"], ["x_next"])
    X = ca.SX.sym("X", 1, 3)
    spread = Cost("spread", 1.0, ca.Function("r", [X], [ca.vertcat(X[0] - X[1], X[0] - X[2])], ["X"], ["r"]))
    mm = MultiModelProblem(step, N, 3, cross_costs=[spread])
    thetas = np.array([NOMINAL, [2.4, 0.4], [1.6, 0.6]])
    x0 = mm.x0(np.array([[30.0], [31.0], [29.0]]))
    params = mm.params(None, thetas)
    assert (mm.problem.nx, mm.problem.n_params) == (3, 6)
    xn = np.array(mm.problem.functions.step(x0, 0.7, params[0])).ravel()
    np.testing.assert_allclose(xn, [float(step(x0[k], 0.7, thetas[k])) for k in range(3)], rtol=1e-14)
    r = np.array(mm.problem.functions.stage_residual(x0, 0.7, params[0])).ravel()
    np.testing.assert_allclose(r, [30.0 - 31.0, 30.0 - 29.0], rtol=1e-14)
