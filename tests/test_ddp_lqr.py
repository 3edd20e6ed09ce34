"""DDP on linear-quadratic problems against the discrete Riccati recursion and IPOPT."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.ocp import Cost, OptimalControlProblem
from thermo_ddp.solvers import DDPSettings, DDPSolver, IpoptSolver, WarmStart

NX, NU, N = 3, 2, 30
RNG = np.random.default_rng(3)
A = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 0.95]]) + 0.02 * RNG.standard_normal((NX, NX))
B = 0.2 * RNG.standard_normal((NX, NU))
Q, R, QN = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2]), 5.0
X0 = np.array([1.0, -1.0, 0.5])


def lq_problem(u_bound=None, horizon=N, jacobians=False):
    x, u = ca.SX.sym("x", NX), ca.SX.sym("u", NU)
    dyn = ca.Function("lin", [x, u], [A @ x + B @ u], ["x", "u"], ["x_next"])
    jac = ca.Function("lin_jac", [x, u], [A @ x + B @ u, A, B], ["x", "u"], ["x_next", "A", "B"]) if jacobians else None
    costs = [Cost("state", Q, ca.Function("r", [x, u], [x], ["x", "u"], ["r"])),
             Cost("control", R, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))]
    terminal = [Cost("terminal", QN, ca.Function("r", [x], [x], ["x"], ["r"]))]
    lb = None if u_bound is None else -np.asarray(u_bound)
    return OptimalControlProblem(dyn, horizon, costs, terminal, u_lb=lb, u_ub=u_bound, name="lq",
                                 dynamics_jacobians=jac)


def riccati(horizon=N):
    """Finite-horizon discrete Riccati recursion: gains K_k (u = K_k x) and the optimal rollout."""
    P = QN * np.eye(NX)
    gains = []
    for _ in range(horizon):
        K = -np.linalg.solve(np.diag(R) + B.T @ P @ B, B.T @ P @ A)
        P = np.diag(Q) + A.T @ P @ (A + B @ K)
        gains.append(K)
    gains = gains[::-1]
    xs, us = [X0], []
    for K in gains:
        us.append(K @ xs[-1])
        xs.append(A @ xs[-1] + B @ us[-1])
    return np.array(xs), np.array(us), np.array(gains)


@pytest.mark.parametrize("backend, jacobians", [("casadi", False), ("numpy", False), ("codegen", False),
                                                ("codegen", True)])
def test_unconstrained_lq_equals_riccati_in_one_iteration(backend, jacobians):
    xs, us, gains = riccati()
    res = DDPSolver(lq_problem(jacobians=jacobians), DDPSettings(backend=backend)).solve(X0)
    assert res.success and res.status == "converged"
    assert res.iterations == 1
    np.testing.assert_allclose(res.xs, xs, atol=1e-8)
    np.testing.assert_allclose(res.us, us, atol=1e-8)
    np.testing.assert_allclose(res.K, gains, atol=1e-8)


def test_infeasible_warm_start_on_lq_closes_gaps_in_one_step():
    xs, us, _ = riccati()
    guess = WarmStart(RNG.standard_normal((N + 1, NX)), RNG.standard_normal((N, NU)))
    res = DDPSolver(lq_problem(), DDPSettings(backend="casadi")).solve(X0, warm_start=guess)
    assert res.success and res.iterations == 1
    np.testing.assert_allclose(res.xs, xs, atol=1e-8)
    assert res.max_constraint_violation < 1e-10


@pytest.fixture(scope="module")
def boxed():
    problem = lq_problem(u_bound=[0.6, 0.4])
    return problem, IpoptSolver(problem, {"tolerance": 1e-10}).solve(X0)


@pytest.mark.parametrize("backend", ["casadi", "numpy"])
def test_box_constrained_lq_equals_ipopt(boxed, backend):
    problem, ref = boxed
    assert ref.success
    assert np.any(np.isclose(np.abs(ref.us), [0.6, 0.4], atol=1e-6)), "box must be active for this oracle"
    res = DDPSolver(problem, DDPSettings(backend=backend, tolerance=1e-10)).solve(X0)
    assert res.success
    np.testing.assert_allclose(res.us, ref.us, atol=1e-6)
    np.testing.assert_allclose(res.xs, ref.xs, atol=1e-6)
    assert abs(res.cost - ref.cost) <= 1e-8 * ref.cost
    assert np.all(res.us <= [0.6, 0.4]) and np.all(res.us >= [-0.6, -0.4])
    clamped = np.isclose(np.abs(res.us), [0.6, 0.4])
    assert np.all(res.K[clamped] == 0.0), "clamped controls get no feedback"


def test_backends_give_identical_iterates(boxed):
    problem, _ = boxed
    results = [DDPSolver(problem, DDPSettings(backend=b)).solve(X0) for b in ("casadi", "numpy", "codegen")]
    for other in results[1:]:
        assert other.iterations == results[0].iterations
        np.testing.assert_allclose(other.us, results[0].us, atol=1e-10)
        np.testing.assert_allclose(other.history["cost"], results[0].history["cost"], rtol=1e-10)


def test_quadratic_model_of_a_gap_closing_step_is_exact_on_lq():
    """alpha d1 + alpha^2 d2 / 2 from the backward pass equals the true cost change (LQ, gaps)."""
    problem = lq_problem()
    solver = DDPSolver(problem, DDPSettings(backend="casadi"))
    be = solver.backend
    rng = np.random.default_rng(7)
    X, U = rng.standard_normal((N + 1, NX)), rng.standard_normal((N, NU))
    X[0] = X0
    P, lam, lamN = np.zeros((N + 1, 0)), np.zeros((N, 0)), np.zeros(0)
    J0, _, _, C = be.evaluate(X, U, P)
    policy, (d1, d2, _, pivot), _ = be.backward(X, U, P, lam, lamN, C, 10.0, 0.0)
    assert pivot > 0
    for alpha in (1.0, 0.5, 0.1):
        Xn, Un, J, _, _ = be.forward(X, U, P, policy, C, alpha)
        assert J - J0 == pytest.approx(alpha * d1 + 0.5 * alpha ** 2 * d2, rel=1e-9, abs=1e-9)
        gaps = be.evaluate(Xn, Un, P)[3]
        np.testing.assert_allclose(gaps, (1 - alpha) * C, atol=1e-12)


def test_warm_start_shift_for_mpc():
    res = DDPSolver(lq_problem(), DDPSettings(backend="casadi")).solve(X0)
    warm = WarmStart.from_result(res, shift=1)
    np.testing.assert_array_equal(warm.xs[:-1], res.xs[1:])
    np.testing.assert_array_equal(warm.xs[-1], res.xs[-1])
    np.testing.assert_array_equal(warm.us[:-1], res.us[1:])


def test_mx_dynamics_that_cannot_be_expanded_still_solve():
    """A CVODES integrator stays MX (no SX, no C code): DDP falls back to the CasADi VM."""
    xs_, us_ = ca.MX.sym("x", 1), ca.MX.sym("u", 1)
    flow = ca.integrator("flow", "cvodes", {"x": xs_, "p": us_, "ode": -xs_ + us_}, 0.0, 0.1)
    step = ca.Function("step", [xs_, us_], [flow(x0=xs_, p=us_)["xf"]], ["x", "u"], ["x_next"])
    x, u = ca.MX.sym("x", 1), ca.MX.sym("u", 1)
    problem = OptimalControlProblem(step, 10, [Cost("all", 1.0, ca.Function("r", [x, u], [ca.vertcat(x, u)],
                                                                           ["x", "u"], ["r"]))])
    res = DDPSolver(problem).solve([1.0])
    ref = IpoptSolver(problem).solve([1.0])
    assert res.success and res.info["backend"] == "casadi"
    assert res.cost == pytest.approx(ref.cost, rel=1e-8)


@pytest.mark.parametrize("backend", ["casadi", "numpy", "codegen"])
def test_fused_first_pass_and_first_order_pass_agree_with_the_full_passes(boxed, backend):
    """evaluate_backward = evaluate + backward; the first-order pass with a pass's own gains gives that
    pass's stationarity and value gradient a (gap-free iterate, box active)."""
    problem, ref = boxed
    be = DDPSolver(problem, DDPSettings(backend=backend)).backend
    X, U, P = ref.xs.copy(), ref.us + 0.05, np.zeros((N + 1, 0))
    X[1:] = ref.xs[1:] + 0.01
    lam, lamN = np.zeros((N, 0)), np.zeros(0)
    evaluation, (policy, summary, values) = be.evaluate_backward(X, U, P, lam, lamN, 10.0, 0.0)
    J, G, GN, C = be.evaluate(X, U, P)
    assert evaluation[0] == pytest.approx(J, rel=1e-14)
    np.testing.assert_allclose(evaluation[3], C, rtol=0, atol=1e-14)
    reference = be.backward(X, U, P, lam, lamN, C, 10.0, 0.0)
    for got, want in zip((policy, summary, values), reference):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)
    Xf, Uf = be.forward(X, U, P, policy, C, 1.0)[:2]  # a full step closes the gaps
    policy_f, summary_f, values_f = be.backward(Xf, Uf, P, lam, lamN, np.zeros_like(C), 10.0, 0.0)
    stat, costates = be.gradient(Xf, Uf, P, lam, lamN, policy_f, 10.0)
    assert stat == pytest.approx(summary_f[2], rel=1e-10, abs=1e-14)
    np.testing.assert_allclose(costates, values_f[:, :NX], rtol=1e-10, atol=1e-12)


def test_compiled_passes_are_found_again_without_rebuilding(monkeypatch):
    """A second solver for the same problem loads the library through the pass index (no symbolic
    build); another control bound gives another key."""
    from thermo_ddp.solvers import _backends, _pass_cache
    first = DDPSolver(lq_problem(u_bound=[0.6, 0.4])).solve(X0)
    assert first.info["backend"] == "codegen"
    assert _pass_cache.load(_pass_cache.key(lq_problem(u_bound=[0.6, 0.4]), DDPSettings())) is not None
    monkeypatch.setattr(_backends, "knot_functions", lambda *a: pytest.fail("knot functions rebuilt"))
    again = DDPSolver(lq_problem(u_bound=[0.6, 0.4])).solve(X0)
    assert again.iterations == first.iterations
    np.testing.assert_array_equal(again.us, first.us)
    assert _pass_cache.key(lq_problem(u_bound=[0.6, 0.5]), DDPSettings()) != \
        _pass_cache.key(lq_problem(u_bound=[0.6, 0.4]), DDPSettings())


def test_a_new_horizon_calls_no_compiler(monkeypatch):
    """The compiled code depends on the structure only: after one build, problems of other horizons load
    the same library (no compiler, no symbolic build) and solve to the Riccati optimum of their horizon."""
    import subprocess

    from thermo_ddp import codegen
    from thermo_ddp.solvers import _backends, _pass_cache
    assert DDPSolver(lq_problem()).backend.name == "codegen"
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: pytest.fail("compiler called"))
    monkeypatch.setattr(codegen, "_build", lambda *a, **k: pytest.fail("library built"))
    monkeypatch.setattr(_backends, "knot_functions", lambda *a, **k: pytest.fail("knot functions rebuilt"))
    for horizon in (7, 2 * N + 3):
        assert _pass_cache.key(lq_problem(horizon=horizon), DDPSettings()) == _pass_cache.key(lq_problem(),
                                                                                              DDPSettings())
        res = DDPSolver(lq_problem(horizon=horizon)).solve(X0)
        xs, us, gains = riccati(horizon)
        assert res.success and res.info["backend"] == "codegen" and res.iterations == 1
        np.testing.assert_allclose(res.us, us, atol=1e-8)
        np.testing.assert_allclose(res.K, gains, atol=1e-8)


def test_failed_backward_pass_raises_the_regularisation_past_the_first_failed_pivot():
    solver = DDPSolver(lq_problem(), DDPSettings(backend="casadi", pivot_jump=True))
    lay = solver.layout
    policy = np.zeros((5, lay.n_policy))
    policy[:, lay.nu + lay.nu * lay.nx] = [-50.0, 1.0, -3.0, 2.0, 1.0]  # knot 2 fails first (backward in time)
    assert solver._increase(0.0, policy) == 6.0
    assert solver._increase(1.0, policy) == 10.0  # x reg_factor when that is larger
    assert solver._increase(0.0) == solver.settings.reg_min
    policy[2, lay.nu + lay.nu * lay.nx] = -1e12  # a jump past reg_max: climb instead
    assert solver._increase(1.0, policy) == 10.0
    plain = DDPSolver(lq_problem(), DDPSettings(backend="casadi"))  # default: no jump
    assert plain._increase(0.0, policy) == plain.settings.reg_min
