"""The longest-hold search's helpers (tasks/hold_search.py): the thermal prediction's bracket and the warm start
of a probe from its neighbour's solution."""
from __future__ import annotations

import types

import numpy as np
import pytest

from thermo_ddp.tasks.hold_search import _gallop, boundary_warm_start, stretched_warm_start
from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess


def test_gallop_brackets_the_last_fitting_hold_from_any_start():
    """Against the answer of a monotone predicate (fits up to ``answer``), from every start: lo fits (or -1),
    hi does not (or top + 1), only holds inside [0, top] asked."""
    rng = np.random.default_rng(0)
    for _ in range(500):
        top = int(rng.integers(0, 40))
        answer, start = int(rng.integers(-1, top + 1)), int(rng.integers(0, top + 1))
        asked = []
        lo, hi = _gallop(lambda k: asked.append(k) or k <= answer, start, top)
        assert lo <= answer < hi and -1 <= lo and hi <= top + 1
        assert all(0 <= k <= top for k in asked)


@pytest.fixture(scope="module")
def lift():
    return build_lift_problem(LiftSettings(payload_kg=20.0, limit_c=140.0, hold_s=6.0))


@pytest.mark.parametrize("shift", [-7, -1, 1, 5])
def test_a_stretched_solution_lowers_where_the_probe_lowers(lift, shift):
    """The initial guess of a probe (angles on its reference, static currents) stretched to another hold is that
    hold's own guess: the lowering moves with the hold's end, the horizon stays."""
    knots = 30
    src = lift.with_hold(knots * lift.settings.dt_s)
    guess = initial_guess(src)
    warm = stretched_warm_start((src, types.SimpleNamespace(xs=guess.xs, us=guess.us)), knots + shift)
    want = initial_guess(lift.with_hold((knots + shift) * lift.settings.dt_s))
    q = lift.model.index(lift.model.joints[0], "q_rad")
    assert warm.xs.shape == want.xs.shape and warm.us.shape == want.us.shape
    np.testing.assert_allclose(warm.xs[:, q], want.xs[:, q], atol=1e-12)
    np.testing.assert_allclose(warm.us, want.us, atol=1e-12)
    assert not warm.multipliers


@pytest.mark.parametrize("shift", [-3, 1])
def test_the_boundary_warm_start_moves_the_multipliers_with_the_holds_end(lift, shift):
    """Multipliers marked with the source's reference angle per knot, moved to another hold, carry the target's
    reference angle (the rows of the lowering move with the hold's end); each row's penalty is the geometric
    mean of its own and the smallest; the trajectories are :func:`stretched_warm_start`'s."""
    knots, ng = 30, lift.problem.n_constraints
    src, dst = (lift.with_hold(k * lift.settings.dt_s) for k in (knots, knots + shift))
    q_ref = lift.problem.parameters.slice("q_ref_rad")
    guess, rho = initial_guess(src), np.geomspace(1e2, 1e6, ng + lift.problem.n_terminal_constraints)
    result = types.SimpleNamespace(xs=guess.xs, us=guess.us, multipliers={
        "constraints": np.repeat(src.params[:-1, q_ref], ng, axis=1), "terminal_constraints": np.ones(2),
        "penalty": rho})
    warm = boundary_warm_start((src, result), knots + shift)
    np.testing.assert_allclose(warm.multipliers["constraints"], np.repeat(dst.params[:-1, q_ref], ng, axis=1))
    np.testing.assert_allclose(warm.multipliers["penalty"], np.sqrt(rho * 1e2))
    np.testing.assert_array_equal(warm.xs, stretched_warm_start((src, result), knots + shift).xs)


def test_the_boundary_verdict_is_confirmed_from_the_longest_holds_plan(lift, monkeypatch):
    """A false infeasible verdict one knot past the longest hold (reached from a cold start, as on four random
    requests, benchmarks/README.md) is solved again from the feasible neighbour's plan stretched, and the search
    goes on past it. The oracle: feasible up to 42 knots, but 41 and 42 read infeasible unless warm-started
    from the hold one knot shorter (each fake plan is filled with its hold, so its stretched copy says where
    it came from)."""
    from thermo_ddp.tasks import hold_search
    from thermo_ddp.tasks.attempts import Outcome

    def solve(probe, warm):
        k = probe.hold_knots[1] - probe.hold_knots[0]
        source = None if warm is None else warm.xs[0, 0]
        feasible = k <= 40 or (k <= 42 and source == k - 1)
        plan = types.SimpleNamespace(xs=np.full_like(lift.x0, k, shape=(lift.params.shape[0], lift.x0.size)),
                                     us=np.full((lift.params.shape[0] - 1, 1), float(k)), multipliers={})
        return Outcome(plan, "feasible" if feasible else "infeasible", ())

    monkeypatch.setattr(hold_search, "_next_guess",
                        lambda lp, knots, outcome, lo, hi, step, first=False: knots + 1 if outcome.feasible else 40)
    search = hold_search.longest_feasible_hold(lift, solve, 42)
    assert search.knots == 42 and search.probes[43][1].verdict == "infeasible"
    assert sorted(search.probes) == [40, 41, 42, 43] and len(search.replaced) == 1  # 42 solved twice


@pytest.mark.parametrize("rungs, cold_cost, cost, cold_solves", [
    (("ddp", "ddp"), 1.0, 1.0, 2), (("ddp", "ddp"), 3.0, 2.0, 2), (("ddp",), 1.0, 2.0, 1),
    (("ddp", "ipopt"), 1.0, 2.0, 1)])
def test_a_longest_hold_reached_by_the_fallback_is_solved_again_from_the_cold_guess(lift, monkeypatch, rungs,
                                                                                      cold_cost, cost, cold_solves):
    """The longest feasible hold (40 knots), reached from its neighbour's plan only at the ladder's second rung
    of the same solver, is solved once more from the cold guess and the lower-cost feasible plan kept (the
    other counted as replaced); reached at the first rung, or by the reference solver (the ladder's last), it
    is not solved again. The oracle: feasible up to 40 knots, cost 2 from a warm start, ``cold_cost`` from the
    cold guess (``warm`` None)."""
    from thermo_ddp.tasks import hold_search
    from thermo_ddp.tasks.attempts import Outcome
    cold = []

    def solve(probe, warm):
        k = probe.hold_knots[1] - probe.hold_knots[0]
        cold.extend([k] if warm is None else [])
        tries = rungs if warm is not None and k == 40 else ("ddp",)
        plans = [types.SimpleNamespace(xs=np.full((lift.params.shape[0], lift.x0.size), float(k)),
                                       us=np.full((lift.params.shape[0] - 1, 1), float(k)), multipliers={},
                                       cost=cold_cost if warm is None else 2.0, solver=name) for name in tries]
        return Outcome(plans[-1], "feasible" if k <= 40 else "infeasible", tuple(zip(tries, plans)))

    monkeypatch.setattr(hold_search, "_next_guess",
                        lambda lp, knots, outcome, lo, hi, step, first=False: knots + 1 if outcome.feasible else 40)
    search = hold_search.longest_feasible_hold(lift, solve, 42)
    assert search.knots == 40 and sorted(search.probes) == [40, 41, 42]
    assert search.best[1].result.cost == cost and cold == [42, 40][:cold_solves]
    assert len(search.replaced) == cold_solves - 1
