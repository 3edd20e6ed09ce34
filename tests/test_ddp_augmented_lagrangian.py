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
    rho = 10.0
    expected = sum((max(0.0, lam + rho * g) ** 2 - lam ** 2) / (2 * rho)
                   for lam, g in zip(np.r_[LAM.ravel(), LAMN], np.r_[G.ravel(), GN]))
    assert al.terms(G, GN, LAM, LAMN, rho) == pytest.approx(expected)
    # the multiplier update is the gradient of the terms: lam_new = d terms / dg
    eps, dG = 1e-6, np.zeros_like(G)
    dG[0, 0] = eps
    lam_new = al.update(S, G, GN, LAM, LAMN, rho, np.inf)[0]
    slope = (al.terms(G + dG, GN, LAM, LAMN, rho) - al.terms(G - dG, GN, LAM, LAMN, rho)) / (2 * eps)
    assert lam_new[0, 0] == pytest.approx(slope, rel=1e-6)


def test_penalty_grows_on_slow_progress_and_falls_on_fast_progress():
    rho = 1e4
    viol = al.violation(G, GN)
    assert al.update(S, G, GN, LAM, LAMN, rho, 1.2 * viol)[2] == rho * S.penalty_factor        # not a quarter
    assert al.update(S, G, GN, LAM, LAMN, rho, 10 * viol)[2] == rho                          # a quarter, not 1 %
    assert al.update(S, G, GN, LAM, LAMN, rho, 1e3 * viol)[2] == pytest.approx(rho / S.penalty_factor ** 0.5)
    assert al.update(S, G, GN, LAM, LAMN, S.penalty_init, 1e3 * viol)[2] == S.penalty_init   # never below
    assert al.update(S, G, GN, LAM, LAMN, rho, np.inf)[2] == rho  # a warm start's first update: no evidence


def test_infeasibility_needs_converged_inner_loops():
    growth = S.infeasibility_growth
    converged = [al.Update(100.0, 1.0, True), al.Update(100.0 * growth, 0.9, True)]
    assert al.stalled(S, converged)
    assert not al.stalled(S, [converged[0], al.Update(100.0 * growth, 0.9, False)])  # the last one unconverged
    assert not al.stalled(S, [al.Update(100.0, 1.0, False), converged[1]])  # no converged earlier evidence
    assert not al.stalled(S, [converged[0], al.Update(100.0 * growth, 0.4, True)])  # halved: progress
    cert = al.certificate(S, (["a", "b"], ["end"]), G, GN, [converged[0], al.Update(1e3, 2.0, False), converged[1]])
    assert cert == {"penalty": [100.0, 100.0 * growth], "violation": [1.0, 0.9], "constraints": ["a", "b", "end"]}


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
