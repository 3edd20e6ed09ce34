"""The DDP's augmented-Lagrangian rules (solvers/_augmented_lagrangian.py): penalties that fall as well as
grow, infeasibility certified only by converged inner loops, and the flat stopping rule bounded by |Qu|."""
from __future__ import annotations

import numpy as np
import pytest

from thermo_ddp.solvers import _augmented_lagrangian as al
from thermo_ddp.solvers.ddp import DDPSettings

S = DDPSettings()
G, GN = np.array([[0.2, -1.0], [-0.5, 0.1]]), np.array([0.05])
LAM, LAMN = np.array([[1.0, 0.0], [0.5, 2.0]]), np.array([0.0])


def test_terms_are_the_phr_penalty():
    rho = np.array([10.0, 3.0, 50.0])  # one per row: the two stage rows, then the terminal row
    rows = np.r_[np.tile(rho[:2], 2), rho[2]]
    expected = sum((max(0.0, lam + r * g) ** 2 - lam ** 2) / (2 * r)
                   for lam, g, r in zip(np.r_[LAM.ravel(), LAMN], np.r_[G.ravel(), GN], rows))
    assert al.terms(G, GN, LAM, LAMN, rho) == pytest.approx(expected)
    # the multiplier update is the gradient of the terms: lam_new = d terms / dg
    eps, dG = 1e-6, np.zeros_like(G)
    dG[0, 0] = eps
    lam_new = al.update(S, G, GN, LAM, LAMN, rho, np.inf)[0]
    slope = (al.terms(G + dG, GN, LAM, LAMN, rho) - al.terms(G - dG, GN, LAM, LAMN, rho)) / (2 * eps)
    assert lam_new[0, 0] == pytest.approx(slope, rel=1e-6)


def test_each_row_gets_the_penalty_its_own_violation_needs():
    rho = np.full(3, 1e4)
    viol = al.row_violation(G, GN)
    np.testing.assert_array_equal(viol, [0.2, 0.1, 0.05])  # the rows' largest violations over the knots
    f = S.penalty_factor
    # rows 0 and 2 stalled, row 1 fell to a tenth: only the stalled rows' penalties grow
    prev = np.array([0.21, 1.0, 0.06])
    np.testing.assert_allclose(al.update(S, G, GN, LAM, LAMN, rho, prev)[2], [1e4 * f, 1e4, 1e4 * f])
    # fast progress (below 1 %) lowers a row's penalty, never below penalty_init
    low = np.array([1e4, S.penalty_init, 1e4])
    np.testing.assert_allclose(al.update(S, G, GN, LAM, LAMN, low, 1e3 * viol)[2],
                               [1e4 / f ** 0.5, S.penalty_init, 1e4 / f ** 0.5])
    # a satisfied row's penalty never grows; a warm start's first update (no previous violation) keeps all
    G_ok = np.minimum(G, 0.0)
    assert al.update(S, G_ok, GN, LAM, LAMN, rho, np.full(3, 0.0))[2][:2].tolist() == [1e4, 1e4]
    np.testing.assert_array_equal(al.update(S, G, GN, LAM, LAMN, rho, np.full(3, np.inf))[2], rho)


def test_infeasibility_needs_converged_inner_loops():
    growth = S.infeasibility_growth
    converged = [al.Update(100.0, 1.0, True), al.Update(100.0 * growth, 0.9, True)]
    assert al.stalled(S, converged)
    assert not al.stalled(S, [converged[0], al.Update(100.0 * growth, 0.9, False)])  # the last one unconverged
    assert not al.stalled(S, [al.Update(100.0, 1.0, False), converged[1]])  # no converged earlier evidence
    assert not al.stalled(S, [converged[0], al.Update(100.0 * growth, 0.4, True)])  # halved: progress
    cert = al.certificate(S, (["a", "b"], ["end"]), G, GN, [converged[0], al.Update(1e3, 2.0, False), converged[1]])
    assert al.Update.at(S, G, np.array([-1.0]), np.array([1.0, 7.0, 99.0]), True).penalty == 7.0  # violated rows
    assert cert == {"penalty": [100.0, 100.0 * growth], "violation": [1.0, 0.9], "constraints": ["a", "b", "end"]}


def test_infeasibility_evidence_is_per_row():
    """A certificate needs the largest violation not halving as the penalty grows and a row whose own penalty
    grew infeasibility_growth times without its own violation halving: either alone certified a lift probe one
    knot past the longest hold that IPOPT and DDP then solve feasible (benchmarks/README.md)."""
    g = S.infeasibility_growth

    def update(rho, viol):
        return al.Update(max(rho), max(viol), True, np.array(rho, float), np.array(viol, float))

    # row 0 falls to a tenth as its penalty grows; row 1, larger, is still at its first penalty
    falling = [update([100, 100], [0.1, 0.13]), update([100 * g, 100], [0.01, 0.2])]
    assert not al.stalled(S, falling)
    assert al.stalled(S, [al.Update(100.0, 0.13, True), al.Update(100.0 * g, 0.2, True)])  # the scalar rule
    assert al.stalled(S, [update([100, 100], [0.1, 0.13]), update([100 * g, 100], [0.08, 0.2])])  # row 0 stuck
    assert not al.stalled(S, [update([100, 100], [0.1, 0.13]), update([10 * g, 100], [0.08, 0.2])])  # grew < g
    # row 0 stuck at a tiny violation while the largest fell 0.13 -> 4.5e-5: progress, no certificate
    assert not al.stalled(S, [update([100, 100], [1e-5, 0.13]), update([100 * g, 100], [4.5e-5, 1e-6])])
    rows = al.Update.at(S, G, GN, np.array([1.0, 7.0, 99.0]), True)
    np.testing.assert_array_equal(rows.row_violations, [0.2, 0.1, 0.05])


def test_flat_rule_never_accepts_a_large_gradient():
    """A predicted decrease below rounding with |Qu| above flat_stationarity is no convergence: the toy is
    stopped at its first iterate by a huge decrement tolerance and must not report converged."""
    from thermo_ddp.solvers import DDPSolver
    from thermo_ddp.testing.thermal_pendulum import thermal_pendulum, x0_of

    problem, goal = thermal_pendulum(t_max=50.0), np.full((101, 1), 2.0)
    flat = DDPSolver(problem, {"backend": "casadi", "decrement_tolerance": 1e6, "max_iterations": 5}).solve(x0_of(),
                                                                                                           goal)
    assert not flat.success
    assert flat.kkt["stationarity"] > DDPSettings().flat_stationarity * (1 + abs(flat.cost))


def test_a_row_with_a_multiplier_just_short_of_its_kink_gets_the_penalty_curvature():
    """knot_model's Hessian: rho Jg'Jg on a row with lam + rho g > 0 (active), and with ``margin`` also on a row
    with lam > 0 within ``margin`` of g = 0; never on a row without a multiplier or beyond the margin."""
    import types

    import casadi as ca

    from thermo_ddp.solvers._riccati import knot_model

    x, u, p = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p")
    F = types.SimpleNamespace(stage_residual=lambda x, u, p: u, stage_constraint=lambda x, u, p: ca.vertcat(u - 1, u - 2),
                              step=lambda x, u, p: x + u, step_jacobians=None, stage_terms=None)
    lam, rho = ca.SX.sym("lam", 2), ca.SX.sym("rho", 2)
    luu = {m: ca.Function("luu", [u, lam, rho], [knot_model(F, x, u, p, lam, rho, False, margin=m)["luu"]])
           for m in (0.0, 1e-4)}
    rho_v = [1e4, 1e4]
    short = 1.0 - 6e-5  # row 1 at g = -6e-5: lam + rho g = 0.5 - 0.6 (not active), within the margin
    assert float(luu[0.0](short, [0.5, 0.0], rho_v)) == pytest.approx(1.0)
    assert float(luu[1e-4](short, [0.5, 0.0], rho_v)) == pytest.approx(1.0 + 1e4)
    assert float(luu[1e-4](short, [0.0, 0.0], rho_v)) == pytest.approx(1.0)          # no multiplier
    assert float(luu[1e-4](1.0 - 1e-3, [0.5, 0.0], rho_v)) == pytest.approx(1.0)     # beyond the margin
    assert float(luu[0.0](1.0 + 1e-3, [0.0, 0.0], rho_v)) == pytest.approx(1.0 + 1e4)  # violated: active


def test_a_flagged_row_is_modelled_by_its_quadratic_piece():
    """knot_model with a negative multiplier entry -m (al.flagged): the row is modelled as active wherever it is,
    curvature rho and gradient (m + rho g) (a semismooth Newton step with that active set); unflagged it has
    neither while inactive. al.crossed finds the rows a trial made active only when the kink lies early on its way."""
    import types

    import casadi as ca

    from thermo_ddp.solvers._riccati import knot_model

    x, u, p = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p")
    F = types.SimpleNamespace(stage_residual=lambda x, u, p: u, stage_constraint=lambda x, u, p: u - 1,
                              step=lambda x, u, p: x + u, step_jacobians=None, stage_terms=None)
    lam, rho = ca.SX.sym("lam"), ca.SX.sym("rho")
    m = knot_model(F, x, u, p, lam, rho, False)
    f = ca.Function("f", [u, lam, rho], [m["lu"], m["luu"]])
    g, r = 0.9 - 1, 1e3
    assert [float(v) for v in f(0.9, 0.0, r)] == pytest.approx([0.9, 1.0])  # inactive: the cost only
    flagged = float(al.flagged(np.array([[0.0]]), np.array([[True]]))[0, 0])
    assert flagged < 0
    assert [float(v) for v in f(0.9, flagged, r)] == pytest.approx([0.9 + r * g, 1.0 + r])
    assert [float(v) for v in f(0.9, -20.0, r)] == pytest.approx([0.9 + 20.0 + r * g, 1.0 + r])  # with m = 20
    G, trial = np.array([[-0.1], [-0.1]]), np.array([[0.5], [0.01]])  # kinks at 1/6 and 10/11 of the way
    early, _ = al.crossed(G, np.zeros(0), trial, np.zeros(0), np.zeros((2, 1)), np.zeros(0), np.array([r]), 0.0, 0.2)
    assert early[:, 0].tolist() == [True, False]
