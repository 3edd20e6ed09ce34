"""The DDP's box QP (solvers/_riccati.py: projected Newton with an Armijo search along the projection arc)
against exact enumeration of the active sets on random small QPs with 2-7 controls, in numpy and compiled
(CasADi SX, the code the codegen backend compiles)."""
from __future__ import annotations

import itertools

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.solvers._riccati import NumpyOps, SymOps, _box_qp
from thermo_ddp.solvers.ddp import DDPSettings

ITERATIONS = DDPSettings().box_iterations


def enumerate_box_qp(H, g, lo, hi):
    """The exact minimiser of 0.5 x'Hx + g'x on lo <= x <= hi: the one active set (each control free, at its
    lower or at its upper bound) whose free-set solution is inside the box with multipliers of the right sign."""
    n = len(g)
    for sides in itertools.product((0, -1, 1), repeat=n):
        sides = np.array(sides)
        x = np.where(sides < 0, lo, np.where(sides > 0, hi, 0.0))
        free = sides == 0
        if free.any():
            x[free] = np.linalg.solve(H[np.ix_(free, free)], -(g[free] + H[np.ix_(free, ~free)] @ x[~free]))
        grad = H @ x + g
        inside = np.all(x[free] >= lo[free] - 1e-9) and np.all(x[free] <= hi[free] + 1e-9)
        signs = np.all(grad[sides < 0] >= -1e-9) and np.all(grad[sides > 0] <= 1e-9)
        if inside and signs:
            return x
    raise AssertionError("no KKT point: not a strictly convex QP")


def random_qp(rng, n):
    A = rng.normal(size=(n, n))
    H = A @ A.T + 0.05 * np.eye(n) + np.diag(rng.uniform(0, 3, n))  # SPD, condition up to ~1e3
    g = 5 * rng.normal(size=n)
    lo, hi = -rng.uniform(0.1, 2.0, n), rng.uniform(0.1, 2.0, n)
    return H, g, lo, hi, rng.normal(size=(n, 3))


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6, 7])
def test_box_qp_equals_active_set_enumeration(n):
    rng = np.random.default_rng(n)
    active = 0
    for _ in range(40):
        H, g, lo, hi, Hux = random_qp(rng, n)
        exact = enumerate_box_qp(H, g, lo, hi)
        du, K, pivot = _box_qp(NumpyOps, H, g, Hux, lo, hi, ITERATIONS)
        np.testing.assert_allclose(du, exact, atol=1e-8)
        assert pivot > 0
        clamped = (np.isclose(exact, lo) & (H @ exact + g > 1e-9)) | (np.isclose(exact, hi) & (H @ exact + g < -1e-9))
        assert np.all(K[clamped] == 0)  # no feedback on a clamped control
        free = ~clamped
        np.testing.assert_allclose(K[free], -np.linalg.solve(H[np.ix_(free, free)], Hux[free]), atol=1e-8)
        active += clamped.sum() > 1
    assert active >= 10  # most draws hold several controls at a bound: the several-control case is exercised


def test_compiled_box_qp_is_the_same_code():
    rng = np.random.default_rng(7)
    n = 5
    Hs, gs, los, his, Huxs = (ca.SX.sym(name, *shape) for name, shape in
                             (("H", (n, n)), ("g", (n, 1)), ("lo", (n, 1)), ("hi", (n, 1)), ("Hux", (n, 3))))
    du, K, _ = _box_qp(SymOps, Hs, gs, Huxs, los, his, ITERATIONS)
    f = ca.Function("box_qp", [Hs, gs, Huxs, los, his], [du, K])
    for _ in range(20):
        H, g, lo, hi, Hux = random_qp(rng, n)
        du_c, K_c = (np.asarray(v) for v in f(H, g, Hux, lo, hi))
        np.testing.assert_allclose(du_c.ravel(), enumerate_box_qp(H, g, lo, hi), atol=1e-8)
        np.testing.assert_allclose(K_c, _box_qp(NumpyOps, H, g, Hux, lo, hi, ITERATIONS)[1], atol=1e-8)
