"""DDP against IPOPT (and fatrop) on a small thermal pendulum resembling the elbow lift.

Toy model (thermo_ddp.testing.thermal_pendulum, not the robot): a 1-DOF pendulum driven by a current u,
torque = k u - m g l sin(q) - b v, and a one-node winding temperature
C T' = R0 (1 + alpha (T - Ta)) u^2 - (T - Ta) / Rth. Constraints: T <= Tmax and the
voltage |R(T) u + kb v| <= Vmax, box |u| <= umax. Goal: lift to the angle given as a
per-knot parameter and hold.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from thermo_ddp.testing.thermal_pendulum import thermal_pendulum, x0_of
from thermo_ddp.solvers import DDPSettings, DDPSolver, IpoptSolver, FatropSolver, WarmStart

GOAL = np.minimum(np.linspace(0.0, 4.0, 101), 2.0)[:, None]  # ramp to 2 rad, then hold
INACTIVE_C, ACTIVE_C = 50.0, 33.0


@pytest.fixture(scope="module", params=[INACTIVE_C, ACTIVE_C], ids=["limit_inactive", "limit_active"])
def case(request):
    problem = thermal_pendulum(t_max=request.param)
    reference = IpoptSolver(problem, {"tolerance": 1e-9}).solve(x0_of(), GOAL)
    assert reference.success
    return request.param, problem, reference


def active_set(problem, result, tol=1e-5):
    """Knots and rows where g >= -tol, from the constraint values of the result's trajectory."""
    g = problem.functions.stage_constraint.map(problem.horizon)(result.xs[:-1].T, result.us.T, GOAL[:-1].T)
    return np.asarray(g).T >= -tol


def test_ddp_and_ipopt_reach_the_same_optimum(case):
    t_max, problem, ref = case
    res = DDPSolver(problem, DDPSettings(backend="casadi", full_second_order=True)).solve(x0_of(), GOAL)
    assert res.success, res.message
    assert abs(res.cost - ref.cost) <= 1e-4 * ref.cost
    assert res.max_constraint_violation <= 1e-5
    winding_limit_hit = ref.xs[:, 2].max() >= t_max - 1e-6
    assert winding_limit_hit == (t_max == ACTIVE_C)
    assert np.array_equal(active_set(problem, res, 1e-4), active_set(problem, ref, 1e-4))
    voltage_active = ref.multipliers["constraints"][:, 1:] > 1e-3
    assert voltage_active.any(), "the voltage limit must be active in both cases"
    assert np.all(res.multipliers["constraints"][:, 1:][voltage_active] > 0)


def test_active_margin_and_nonmonotone_search_reach_ipopts_optimum(case):
    """The lift's line-search options (rows near their kink in the model, a nonmonotone Armijo reference) change
    the path, not the optimum: IPOPT's cost and active set."""
    t_max, problem, ref = case
    settings = DDPSettings(backend="casadi", full_second_order=True, active_margin=1e-4, nonmonotone_memory=3)
    res = DDPSolver(problem, settings).solve(x0_of(), GOAL)
    assert res.success, res.message
    assert abs(res.cost - ref.cost) <= 1e-4 * ref.cost and res.max_constraint_violation <= 1e-5
    assert np.array_equal(active_set(problem, res, 1e-4), active_set(problem, ref, 1e-4))


def test_full_ddp_needs_no_more_iterations_than_gauss_newton():
    """With the winding limit active the heating curvature (R i^2) matters: full DDP uses it."""
    problem = thermal_pendulum(t_max=ACTIVE_C)
    gn = DDPSolver(problem, DDPSettings(backend="casadi")).solve(x0_of(), GOAL)
    full = DDPSolver(problem, DDPSettings(backend="casadi", full_second_order=True)).solve(x0_of(), GOAL)
    assert gn.success and full.success
    assert full.iterations <= gn.iterations
    assert abs(full.cost - gn.cost) <= 1e-6 * gn.cost
    np.testing.assert_allclose(full.us, gn.us, atol=1e-3)


def test_infeasible_warm_start_is_accepted_and_converges(case):
    _, problem, ref = case
    N = problem.horizon
    xs = np.tile(x0_of(), (N + 1, 1))
    xs[:, 0] = np.linspace(0.0, 2.0, N + 1)  # a lifted guess that breaks the dynamics everywhere
    us = np.full((N, 1), 2.5)
    res = DDPSolver(problem, DDPSettings(backend="casadi", full_second_order=True)).solve(
        x0_of(), GOAL, warm_start=WarmStart(xs, us))
    assert res.success, res.message
    assert res.history["gap"][0] > 1e-2
    assert abs(res.cost - ref.cost) <= 1e-4 * ref.cost


def test_warm_restart_with_multipliers_converges_at_once(case):
    _, problem, _ = case
    solver = DDPSolver(problem, DDPSettings(backend="casadi", full_second_order=True))
    first = solver.solve(x0_of(), GOAL)
    again = solver.solve(x0_of(), GOAL, warm_start=first)
    assert again.success and again.iterations <= 1
    assert abs(again.cost - first.cost) <= 1e-6 * first.cost


def test_fatrop_solves_the_same_transcription(case):
    _, problem, ref = case
    fatrop = FatropSolver(problem, {"tolerance": 1e-9})
    res = fatrop.solve(x0_of(), GOAL)
    assert res.success, res.status
    assert abs(res.cost - ref.cost) <= 1e-6 * ref.cost
    assert fatrop.solve(x0_of(), GOAL, warm_start=res).iterations < res.iterations
    warm = IpoptSolver(problem).solve(x0_of(), GOAL, warm_start=ref)
    assert warm.success and warm.iterations < ref.iterations


def test_ipopt_optimum_with_its_multipliers_is_a_ddp_fixed_point(case):
    """IPOPT's KKT point (trajectory + inequality multipliers) passes DDP's convergence test."""
    _, problem, ref = case
    res = DDPSolver(problem, DDPSettings(backend="casadi", full_second_order=True)).solve(x0_of(), GOAL,
                                                                                         warm_start=ref)
    assert res.success and res.iterations <= 1
    assert abs(res.cost - ref.cost) <= 1e-7 * ref.cost


def test_a_new_direction_with_the_rows_crossed_saves_forward_passes():
    """``retry_crossed_rows``: the neighbouring limit's plan (36 °C) warm-starts the 34 °C toy; its full steps cross
    the winding rows' kinks, which the local model at the warm start lacks. With the rows the cut-short line search
    crossed put in the model, the search reaches IPOPT's optimum and active set in at most half the forward
    passes (measured 2 against 10)."""
    problem = thermal_pendulum(t_max=34.0)
    ref = IpoptSolver(problem, {"tolerance": 1e-9}).solve(x0_of(), GOAL)
    assert ref.success
    settings = DDPSettings(backend="casadi", full_second_order=True, active_margin=1e-4, nonmonotone_memory=3)
    neighbour = DDPSolver(thermal_pendulum(t_max=36.0), settings).solve(x0_of(), GOAL)
    warm = WarmStart(neighbour.xs, neighbour.us)
    runs = {retry: DDPSolver(problem, dataclasses.replace(settings, retry_crossed_rows=retry))
            .solve(x0_of(), GOAL, warm) for retry in (False, True)}
    for res in runs.values():
        assert res.success, res.message
        assert abs(res.cost - ref.cost) <= 1e-4 * ref.cost and res.max_constraint_violation <= 1e-5
        assert np.array_equal(active_set(problem, res, 1e-4), active_set(problem, ref, 1e-4))
    assert 2 * runs[True].info["forward_passes"] <= runs[False].info["forward_passes"]
