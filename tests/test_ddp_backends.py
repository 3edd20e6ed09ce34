"""The three DDP backends compute the same passes: compiled C loops over a runtime horizon ("codegen",
the oracle being the CasADi VM's mapaccum and the numpy Riccati loops), on the elbow lift (full DDP)
and on the thermal-pendulum MPC toy (Gauss-Newton), at a perturbed iterate with active multipliers."""
from __future__ import annotations

import numpy as np
import pytest

from thermo_ddp.solvers import DDPSettings, DDPSolver
from thermo_ddp.solvers import _pass_cache
from thermo_ddp.testing.thermal_pendulum import thermal_pendulum, x0_of
from thermo_ddp.tasks.problem import initial_guess
from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem

RHO = 100.0


def _lift():
    lp = build_lift_problem(LiftSettings(hold_s=2.0, limit_c=84.0))
    guess = initial_guess(lp)
    return lp.problem, guess.xs, guess.us, lp.params, True


def _pendulum():
    problem = thermal_pendulum(horizon=60, t_max=32.5, n_thermal=3)
    xs, us = np.tile(x0_of(3), (61, 1)), np.full((60, 1), 2.0)
    xs[:, 2] = 32.5  # the winding at the limit: some multipliers active
    return problem, xs, us, np.full((61, 1), 2.0), False


@pytest.fixture(scope="module", params=[_lift, _pendulum], ids=["lift_full_ddp", "mpc_toy_gauss_newton"])
def case(request):
    problem, xs, us, params, full = request.param()
    rng = np.random.default_rng(5)
    N = problem.horizon
    X = xs + 0.05 * rng.standard_normal(xs.shape)
    U = np.clip(us + 0.5 * rng.standard_normal(us.shape), problem.u_lb, problem.u_ub)
    lam = rng.uniform(0.0, 2.0, (N, problem.n_constraints)) * (rng.random((N, problem.n_constraints)) < 0.5)
    lamN = rng.uniform(0.0, 2.0, problem.n_terminal_constraints)
    backends = {b: DDPSolver(problem, DDPSettings(backend=b, full_second_order=full)).backend
                for b in ("codegen", "casadi", "numpy")}
    assert backends["codegen"].name == "codegen"
    C = backends["casadi"].evaluate(X, U, params)[3]
    reg = next(r for r in (1e-6, 1.0, 10.0, 100.0, 1e3, 1e4)  # the smallest with a successful pass
               if backends["casadi"].backward(X, U, params, lam, lamN, C, RHO, r)[1][3] > 0)
    return backends, (X, U, params, lam, lamN), reg


def _close(got, want):
    """Equal to rounding: 1e-12 of the array's scale (measured: 5e-15; Cholesky in numpy, LDL' in the others)."""
    for g, w in zip(got, want):
        g, w = np.asarray(g, float), np.asarray(w, float)
        assert g.shape == w.shape
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-12 * (1.0 + np.max(np.abs(w), initial=0.0)))


def test_every_pass_equals_the_vm_and_numpy_backends(case):
    backends, (X, U, P, lam, lamN), REG = case
    backends = dict(backends)
    compiled = backends.pop("codegen")
    J, G, GN, C = compiled.evaluate(X, U, P)
    assert np.max(np.abs(C)) > 1e-3 and np.any(lam + RHO * G > 0)  # gaps and active AL terms are exercised
    policy, summary, values = compiled.backward(X, U, P, lam, lamN, C, RHO, REG)
    assert summary[3] > 0, "the pass must succeed at this iterate"
    Xf, Uf, Jf, Gf, GNf = compiled.forward(X, U, P, policy, C, 0.5)
    fused = compiled.evaluate_backward(X, U, P, lam, lamN, RHO, REG)
    stat, costates = compiled.gradient(Xf, Uf, P, lam, lamN, policy, RHO)
    for name, other in backends.items():
        _close([J], [other.evaluate(X, U, P)[0]])
        _close((G, GN, C), other.evaluate(X, U, P)[1:])
        _close((policy, summary, values), other.backward(X, U, P, lam, lamN, C, RHO, REG))
        _close((Xf, Uf, Jf, Gf, GNf), other.forward(X, U, P, policy, C, 0.5))
        (J2, *rest), pass2 = other.evaluate_backward(X, U, P, lam, lamN, RHO, REG)
        _close([fused[0][0], *fused[0][1:], *fused[1]], [J2, *rest, *pass2])
        stat2, costates2 = other.gradient(Xf, Uf, P, lam, lamN, policy, RHO)
        _close(([stat], costates), ([stat2], costates2))


def test_a_failed_backward_pass_stops_where_numpy_stops(case):
    """Quu made indefinite by a negative regularisation: the pass stops at the latest knot, earlier
    knots get pivot -1 (as the numpy loop), and the fused pass still evaluates every knot."""
    backends, (X, U, P, lam, lamN), _ = case
    compiled, numpy_ = backends["codegen"], backends["numpy"]
    C = compiled.evaluate(X, U, P)[3]
    failed = []
    for be in (compiled, numpy_):
        policy, summary, _ = be.backward(X, U, P, lam, lamN, C, RHO, -1e9)
        pivots = policy[:, -4]  # policy = [k; vec(K); pivot; d1; d2; stationarity]
        failed.append(np.flatnonzero(~(pivots > 0)))
        assert summary[3] <= 0
    np.testing.assert_array_equal(failed[0], failed[1])
    assert failed[0][-1] == len(U) - 1 and np.all(
        compiled.backward(X, U, P, lam, lamN, C, RHO, -1e9)[0][:-1, -4] == -1.0)
    evaluation, _ = compiled.evaluate_backward(X, U, P, lam, lamN, RHO, -1e9)
    _close(evaluation, compiled.evaluate(X, U, P))


def test_lift_requests_of_other_durations_share_one_library():
    """The compiled code depends on the lift's structure, not on its horizon: other hold durations give
    the same cache key."""
    keys = {_pass_cache.key(build_lift_problem(LiftSettings(hold_s=h, limit_c=84.0)).problem, DDPSettings())
            for h in (2.0, 3.5, 10.0)}
    assert len(keys) == 1 and None not in keys


def test_second_order_chunks_reassemble_the_hessian(monkeypatch):
    """Full DDP with the second-order term split into one compiled chunk per column (as a big model's
    is): the same backward pass as numpy's with the whole Hessian."""
    import ctypes

    from thermo_ddp.solvers import _backends
    monkeypatch.setattr(_backends, "HESSIAN_CHUNK_NODES", 1)
    problem, xs, us, P, _ = _pendulum()
    compiled = DDPSolver(problem, DDPSettings(backend="codegen", full_second_order=True)).backend
    vm = DDPSolver(problem, DDPSettings(backend="numpy", full_second_order=True)).backend
    assert compiled.name == "codegen"
    assert ctypes.c_int.in_dll(compiled._lib, "ddp_n_hess").value == problem.nx + problem.nu
    X, U = xs + 0.1, us - 0.5
    lam, lamN = np.full((problem.horizon, problem.n_constraints), 0.5), np.full(problem.n_terminal_constraints, 0.5)
    C = vm.evaluate(X, U, P)[3]
    got = compiled.backward(X, U, P, lam, lamN, C, RHO, 1.0)
    assert got[1][3] > 0
    _close(got, vm.backward(X, U, P, lam, lamN, C, RHO, 1.0))


@pytest.mark.parametrize("limit", [0, 10**9], ids=["big_model", "small_model"])
def test_the_optional_compiled_knots_change_no_pass(monkeypatch, limit):
    """A big model's compiled passes call only the knot functions the driver needs (the first pass: the
    evaluation, then the local model; the first-order pass: the local model, then ``ddp_grad_knot``), a small
    model's also the ones that share work (``ddp_local_eval_knot``, ``ddp_grad_first_knot``): numpy's passes
    either way."""
    import ctypes

    from thermo_ddp.solvers import _backends
    monkeypatch.setattr(_backends, "SMALL_KNOT_INSTRUCTIONS", limit)
    monkeypatch.setattr(_pass_cache, "key", lambda problem, settings: None)  # build, never the index's library
    problem, xs, us, P, _ = _pendulum()
    compiled = DDPSolver(problem, DDPSettings(backend="codegen")).backend
    numpy_ = DDPSolver(problem, DDPSettings(backend="numpy")).backend
    for name in ("ddp_local_eval_knot_fn", "ddp_grad_first_knot_fn"):
        assert bool(ctypes.c_void_p.in_dll(compiled._lib, name).value) == (limit > 0)
    X, U = xs + 0.1, us - 0.5
    lam, lamN = np.full((problem.horizon, problem.n_constraints), 0.5), np.full(problem.n_terminal_constraints, 0.5)
    (J, *evaluation), first_pass = compiled.evaluate_backward(X, U, P, lam, lamN, RHO, 1.0)
    (J2, *evaluation2), first_pass2 = numpy_.evaluate_backward(X, U, P, lam, lamN, RHO, 1.0)
    _close([J, *evaluation, *first_pass], [J2, *evaluation2, *first_pass2])
    policy, summary, _ = first_pass2
    assert summary[3] > 0
    stat, costates = compiled.gradient(X, U, P, lam, lamN, policy, RHO)
    stat2, costates2 = numpy_.gradient(X, U, P, lam, lamN, policy, RHO)
    assert stat2 > 1e-3  # not a stationary iterate: the pass has something to compare
    _close(([stat], costates), ([stat2], costates2))
