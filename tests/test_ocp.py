"""OptimalControlProblem validation and its transcription (shared by IPOPT and fatrop)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.ocp import Constraint, Cost, OptimalControlProblem

x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 1)
DYN = ca.Function("f", [x, u, p], [ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u - p))], ["x", "u", "p"], ["x_next"])
TRACK = Cost("track", [1.0, 0.5], ca.Function("r", [x, u, p], [x - p], ["x", "u", "p"], ["r"]))
EFFORT = Cost("effort", 0.1, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))
END = Cost("end", 10.0, ca.Function("r", [x, p], [x[0] - p], ["x", "p"], ["r"]))
SPEED = Constraint("speed", ca.Function("g", [x, u], [x[1] - 1.0], ["x", "u"], ["g"]))


def problem(**changes):
    args = dict(dynamics=DYN, horizon=5, costs=[TRACK, EFFORT], terminal_costs=[END], constraints=[SPEED],
                u_lb=[-2.0], u_ub=[2.0])
    args.update(changes)
    return OptimalControlProblem(**args)


def test_sizes_are_inferred():
    pr = problem()
    assert (pr.nx, pr.nu, pr.n_params, pr.n_constraints, pr.n_terminal_constraints) == (2, 1, 1, 1, 0)
    assert pr.has_box and pr.u_lb.tolist() == [-2.0]


@pytest.mark.parametrize("changes, field", [
    (dict(horizon=0), "horizon"),
    (dict(horizon=2.5), "horizon"),
    (dict(u_lb=[3.0]), "u_lb"),
    (dict(u_ub=[1.0, 2.0]), "u_ub"),
    (dict(costs=[TRACK, TRACK]), "names"),
    (dict(costs=["track"]), "costs"),
    (dict(dynamics=ca.Function("f", [x, u], [x], ["x", "u"], ["y"])), "dynamics outputs"),
    (dict(terminal_costs=[Cost("bad", 1.0, ca.Function("r", [x, u], [u], ["x", "u"], ["r"]))]), "inputs"),
    (dict(costs=[Cost("bad", 1.0, ca.Function("r", [ca.SX.sym("x", 3)], [1], ["x"], ["r"]))]), "input x"),
    (dict(constraints=[Constraint("q", ca.Function("g", [x, ca.SX.sym("p", 2)], [x], ["x", "p"], ["g"]))]),
     "input p"),
    (dict(dynamics_jacobians=ca.Function("j", [x, u, p], [x, x, u], ["x", "u", "p"], ["x_next", "A", "B"])),
     "dynamics_jacobians outputs"),
    (dict(dynamics_jacobians=ca.Function("j", [x, u], [x], ["x", "u"], ["A"])), "dynamics_jacobians inputs"),
])
def test_bad_problems_raise_clear_errors(changes, field):
    with pytest.raises(InputError) as err:
        problem(**changes)
    assert err.value.field == field


def test_bad_weights_raise():
    fun = ca.Function("r", [x, u], [x], ["x", "u"], ["r"])
    with pytest.raises(InputError, match="weight"):
        Cost("w", [1.0, 2.0, 3.0], fun)
    with pytest.raises(InputError, match=">= 0"):
        Cost("w", -1.0, fun)


def test_data_checks():
    pr = problem()
    assert pr.check_params([0.5]).shape == (6, 1)
    with pytest.raises(InputError, match="shape"):
        pr.check_params(np.zeros((5, 1)))
    with pytest.raises(InputError) as err:
        pr.check_params(np.vstack([np.zeros((3, 1)), [[np.nan]], np.zeros((2, 1))]))
    assert err.value.row == 3
    with pytest.raises(InputError, match="x0"):
        pr.check_x0([1.0])
    with pytest.raises(InputError, match="xs"):
        pr.check_trajectory(np.zeros((5, 2)), np.zeros((5, 1)))


def test_transcription_matches_the_problem_functions():
    pr = problem()
    tr = pr.transcription
    rng = np.random.default_rng(1)
    xs, us, params = rng.standard_normal((6, 2)), rng.standard_normal((5, 1)), rng.standard_normal((6, 1))
    x0 = rng.standard_normal(2)
    w = tr.pack(xs, us)
    back = tr.unpack(w)
    np.testing.assert_array_equal(back[0], xs)
    np.testing.assert_array_equal(back[1], us)
    nlp = ca.Function("nlp", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["f"], tr.nlp["g"]])
    f, g = (np.asarray(v).ravel() for v in nlp(w, tr.parameters(x0, params)))
    cost = 0.0
    for k in range(5):  # the problem written out by hand
        track = 1.0 * (xs[k, 0] - params[k, 0]) ** 2 + 0.5 * (xs[k, 1] - params[k, 0]) ** 2
        cost += 0.5 * (track + 0.1 * us[k, 0] ** 2)
    cost += 0.5 * 10.0 * (xs[5, 0] - params[5, 0]) ** 2
    assert f[0] == pytest.approx(cost, rel=1e-12)
    np.testing.assert_allclose(g[:2], xs[0] - x0)
    gap0 = xs[1] - np.array([xs[0, 0] + 0.1 * xs[0, 1], xs[0, 1] + 0.1 * (us[0, 0] - params[0, 0])])
    np.testing.assert_allclose(g[2:4], gap0, atol=1e-14)
    assert g[4] == pytest.approx(xs[0, 1] - 1.0)
    assert tr.equality.tolist()[:5] == [True, True, True, True, False]
    assert np.all(tr.lbx[2::3][:5] == -2.0)


def test_mx_functions_are_accepted():
    X, U, P = ca.MX.sym("x", 2), ca.MX.sym("u"), ca.MX.sym("p")
    dyn = ca.Function("f", [X, U, P], [DYN(X, U, P)], ["x", "u", "p"], ["x_next"])
    pr = problem(dynamics=dyn)
    assert pr.functions.step(np.ones(2), 1.0, 0.0).shape == (2, 1)


def test_knot_parameters_by_name():
    """Blocks are read and written by name; wrong names and shapes are refused."""
    from thermo_ddp.ocp import KnotParameters
    layout = KnotParameters((("q_ref_rad", 2), ("weight", 1), ("ambient_c", 1)))
    q_ref = np.arange(10.0).reshape(5, 2)
    p = layout.values(5, q_ref_rad=q_ref, weight=3.0, ambient_c=np.linspace(20, 24, 5))
    assert p.shape == (5, 4)
    np.testing.assert_array_equal(p[:, layout.slice("q_ref_rad")], q_ref)
    np.testing.assert_array_equal(p[:, layout.slice("ambient_c")].ravel(), np.linspace(20, 24, 5))
    assert np.all(p[:, layout.slice("weight")] == 3.0)
    sym = layout.symbols(ca.SX.sym("p", 4))
    assert sym["q_ref_rad"].numel() == 2 and str(sym["ambient_c"]) == "p_3"
    with pytest.raises(InputError, match="weight"):
        layout.values(5, q_ref_rad=q_ref, ambient_c=20.0)
    with pytest.raises(InputError, match="q_ref_rad"):
        layout.values(5, q_ref_rad=np.zeros(3), weight=1.0, ambient_c=20.0)
    with pytest.raises(InputError, match="names"):
        KnotParameters((("a", 1), ("a", 2)))


def test_constraint_made_soft_or_shifted_by_name():
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p")
    c = Constraint("limit", ca.Function("limit", [x, u, p], [ca.vertcat(x[0] - p, u - 1)], ["x", "u", "p"], ["g"]))
    soft = c.penalty(50.0, "limit_soft")
    looser = c.shifted(0.5)
    rng = np.random.default_rng(0)
    for _ in range(20):
        xv, uv, pv = rng.normal(size=2), rng.normal(), rng.normal()
        g = np.array([xv[0] - pv, uv - 1])
        assert np.allclose(np.array(soft.residual(xv, uv, pv)).ravel(), np.maximum(0, g))
        assert np.allclose(np.array(looser.function(xv, uv, pv)).ravel(), g - 0.5)
    assert soft.name == "limit_soft" and soft.size == 2 and np.all(soft.weight == 50.0)
    assert looser.name == "limit" and c.penalty(1.0).name == "limit_penalty"
