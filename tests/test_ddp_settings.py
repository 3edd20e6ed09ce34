"""DDPSettings and solver input validation: bad values, unknown options and wrong shapes raise."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.ocp import Cost, OptimalControlProblem
from thermo_ddp.solvers import DDPSettings, DDPSolver, IpoptSolver, ReferenceSettings, WarmStart

x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
PROBLEM = OptimalControlProblem(
    ca.Function("f", [x, u], [ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u)], ["x", "u"], ["x_next"]), 10,
    [Cost("all", 1.0, ca.Function("r", [x, u], [ca.vertcat(x, u)], ["x", "u"], ["r"]))])


@pytest.mark.parametrize("options", [
    {"max_iterations": -1}, {"max_iterations": 2.5}, {"tolerance": 0.0}, {"tolerance": float("nan")},
    {"reg_factor": 1.0}, {"line_search_factor": 1.5}, {"backend": "fortran"}, {"full_second_order": "yes"},
    {"reg_init": 1e12}, {"penalty_init": 1e9}, {"armijo": 0.0}, {"active_margin": -1e-4},
    {"nonmonotone_memory": -1}, {"nonmonotone_memory": 2.5},
])
def test_bad_settings_raise(options):
    with pytest.raises(InputError):
        DDPSettings(**options)


def test_unknown_option_is_named():
    with pytest.raises(InputError, match="max_iter.*unknown option"):
        DDPSettings.from_mapping({"max_iter": 10})
    with pytest.raises(InputError, match="unknown option"):
        DDPSolver(PROBLEM, {"tol": 1e-3})
    with pytest.raises(InputError, match="unknown option"):
        ReferenceSettings.from_mapping({"linear_solver": "ma27"})


def test_settings_are_frozen():
    s = DDPSettings()
    with pytest.raises(Exception):
        s.tolerance = 1.0


def test_wrong_shapes_raise():
    solver = DDPSolver(PROBLEM, {"backend": "casadi"})
    with pytest.raises(InputError, match="x0"):
        solver.solve([0.0, 0.0, 0.0])
    with pytest.raises(InputError, match="params"):
        solver.solve([1.0, 0.0], params=np.zeros((11, 2)))
    with pytest.raises(InputError, match="us"):
        solver.solve([1.0, 0.0], warm_start=WarmStart(np.zeros((11, 2)), np.zeros((11, 1))))
    with pytest.raises(InputError, match="warm_start"):
        solver.solve([1.0, 0.0], warm_start=(np.zeros((11, 2)), np.zeros((10, 1))))
    with pytest.raises(InputError, match="problem"):
        DDPSolver("not a problem")
    with pytest.raises(InputError, match="x0"):
        IpoptSolver(PROBLEM).solve([np.nan, 0.0])


def test_failure_is_reported_without_nan():
    res = DDPSolver(PROBLEM, {"backend": "casadi", "max_iterations": 0}).solve([1.0, 0.0])
    assert not res.success and res.status == "failed" and res.reason == "max_iterations"
    assert np.all(np.isfinite(res.xs)) and np.isfinite(res.cost)
    assert "max_iterations" in res.report(print_out=False)


def test_non_finite_model_is_a_status_not_nan():
    y, v = ca.SX.sym("x", 2), ca.SX.sym("u")
    bad = OptimalControlProblem(
        ca.Function("f", [y, v], [ca.vertcat(y[0], ca.log(y[1] - 5.0))], ["x", "u"], ["x_next"]), 5,
        [Cost("all", 1.0, ca.Function("r", [y, v], [ca.vertcat(y, v)], ["x", "u"], ["r"]))])
    res = DDPSolver(bad, {"backend": "casadi"}).solve([1.0, 0.0])
    assert not res.success and res.status == "failed" and res.reason == "numerical_error"
    assert np.all(np.isfinite(res.xs)) and not np.isnan(res.cost)
    assert not np.isnan(res.max_constraint_violation)


def test_warm_start_shift_keeps_the_horizon_length():
    import numpy as np

    from thermo_ddp.solvers import SolverResult, WarmStart

    res = SolverResult("ddp", True, "converged", "", np.arange(4.0)[:, None], np.arange(3.0)[:, None], 0.0, 0.0,
                       1, 0.0)
    for shift in (1, 3, 10):
        warm = WarmStart.from_result(res, shift=shift)
        assert warm.xs.shape == (4, 1) and warm.us.shape == (3, 1)
        assert warm.xs[-1, 0] == 3.0 and warm.xs[0, 0] == min(shift, 3)


def test_callback_sees_every_iteration_and_may_stop_the_solve():
    """The loop's hook (crocoddyl's CallbackAbstract): one read-only view per accepted iteration, equal to the
    history; returning True stops the solve, which is then failed with reason "stopped", never a verdict."""
    import dataclasses

    from thermo_ddp.solvers.ddp import IterationView
    from thermo_ddp.testing.thermal_pendulum import thermal_pendulum, x0_of

    views, x0, goal = [], x0_of(), np.full((101, 1), 2.0)
    solver = DDPSolver(thermal_pendulum(t_max=50.0), {"backend": "casadi"})
    full = solver.solve(x0, goal, callback=views.append)
    assert full.success and len(views) == full.iterations >= 2
    assert all(isinstance(v, IterationView) for v in views)
    assert [v.cost for v in views] == full.history["cost"][: len(views)]
    with pytest.raises(dataclasses.FrozenInstanceError):
        views[0].cost = 0.0
    stopped = solver.solve(x0, goal, callback=lambda view: view.iteration >= 1)
    assert stopped.status == "failed" and stopped.reason == "stopped" and stopped.iterations == 1
    with pytest.raises(InputError, match="callback"):
        solver.solve(x0, goal, callback=3)
