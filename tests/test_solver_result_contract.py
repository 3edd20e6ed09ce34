"""The solver result contract (issue 23): status converged | infeasible | failed, reason, certificate and
KKT residuals evaluated the same way for DDP, IPOPT and fatrop (thermo_ddp.solvers.kkt).

Toy model: thermo_ddp.testing.thermal_pendulum (a pendulum lifted by a current, one winding node)."""
from __future__ import annotations

import numpy as np
import pytest

from thermo_ddp.solvers import DDPSettings, DDPSolver, FatropSolver, IpoptSolver, SolverResult
from thermo_ddp.solvers.reference import plugin_verdict
from thermo_ddp.testing.thermal_pendulum import thermal_pendulum, x0_of

GOAL = np.minimum(np.linspace(0.0, 4.0, 101), 2.0)[:, None]  # ramp to 2 rad, then hold
ACTIVE_C = 33.0       # the winding limit is active at the optimum
BELOW_START_C = 20.0  # below the start's winding temperature (x0 is 5 K above ambient): infeasible at x_0
FULL = DDPSettings(backend="casadi", full_second_order=True)


@pytest.fixture(scope="module")
def active():
    problem = thermal_pendulum(t_max=ACTIVE_C)
    return (problem, IpoptSolver(problem, {"tolerance": 1e-9}).solve(x0_of(), GOAL),
            DDPSolver(problem, FULL).solve(x0_of(), GOAL))


def test_ddp_and_ipopt_report_the_same_kkt_residuals(active):
    _, ipopt, ddp = active
    for result in (ipopt, ddp):
        assert result.status == "converged" and result.success and result.reason == "" and result.certificate is None
        assert set(result.kkt) == {"stationarity", "primal", "complementarity"}
        assert all(v <= 1e-6 for v in result.kkt.values()), (result.solver, result.kkt)
    # evaluated once: DDP's own multipliers at IPOPT's optimum give IPOPT's residuals within tolerance
    assert abs(ddp.kkt["primal"] - ipopt.kkt["primal"]) <= 1e-6


def test_kkt_residuals_see_a_wrong_multiplier(active):
    """The residuals are not trivially small: IPOPT's point with its constraint multipliers halved is not
    stationary (the winding limit is active, so its multiplier enters the adjoint)."""
    problem, ipopt, _ = active
    m = ipopt.multipliers
    solver = DDPSolver(problem, FULL)
    right = solver.kkt.residuals(ipopt.xs, ipopt.us, GOAL, m["constraints"], m["terminal_constraints"], x0_of())
    wrong = solver.kkt.residuals(ipopt.xs, ipopt.us, GOAL, 0.5 * m["constraints"], m["terminal_constraints"],
                                 x0_of())
    assert right["stationarity"] <= 1e-6 < 1e-2 < wrong["stationarity"]


def test_least_squares_costates_are_ipopts_dynamics_multipliers(active):
    """Without a solver's own costates the residuals use the least-squares multipliers of the dynamics: at
    IPOPT's optimum they are IPOPT's own (with the opposite sign: x_{k+1} - f_k), and the stationarity they give
    is as small as IPOPT's."""
    problem, ipopt, _ = active
    m = ipopt.multipliers
    kkt = DDPSolver(problem, FULL).kkt
    lam = kkt.costates(ipopt.xs, ipopt.us, GOAL, m["constraints"], m["terminal_constraints"])
    assert np.abs(lam[1:] + m["dynamics"]).max() <= 1e-6 * (1 + np.abs(m["dynamics"]).max())
    own = kkt.residuals(ipopt.xs, ipopt.us, GOAL, m["constraints"], m["terminal_constraints"], x0_of())
    assert own["stationarity"] <= 1e-8


def test_ddp_stationarity_is_finite_on_a_lift_unstable_backwards():
    """The 38.4 kg lift held 15 s at -2.0 rad (past horizontal: gravity's stiffness makes the linearisation
    unstable backwards): the exact adjoint propagated backwards gave 4e2 on DDP's converged plan and 1e4 on
    IPOPT's (measured, the code before). The least-squares costates give DDP's own |Qu| to within a factor of 10."""
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, solve

    lp = build_lift_problem(LiftSettings(payload_kg=38.4, limit_c=88.0, hold_s=15.0, goal_rad=-2.0))
    ddp = solve(lp, "ddp")
    qu = ddp.history["stationarity"][-1]
    assert ddp.status == "converged" and qu <= 1e-6
    assert ddp.kkt["stationarity"] <= 10 * qu and ddp.kkt["primal"] <= 1e-5


def test_fatrop_reports_the_kkt_residuals_of_its_duals(active):
    problem, _, _ = active
    fatrop = FatropSolver(problem, {"tolerance": 1e-9}).solve(x0_of(), GOAL)
    assert fatrop.status == "converged" and all(v <= 1e-6 for v in fatrop.kkt.values()), fatrop.kkt


def test_a_known_infeasible_problem_is_infeasible_with_a_certificate():
    problem = thermal_pendulum(t_max=BELOW_START_C)
    res = DDPSolver(problem, FULL).solve(x0_of(), GOAL)
    assert res.status == "infeasible" and not res.success and res.reason == "locally_infeasible"
    cert = res.certificate
    assert len(cert["penalty"]) == len(cert["violation"]) >= 2
    assert cert["penalty"][-1] >= 1e3 * cert["penalty"][0]  # the penalty grew a thousandfold ...
    assert cert["violation"][-1] > 0.5 * cert["violation"][0]  # ... and the violation did not halve
    assert cert["violation"][-1] == pytest.approx(x0_of()[2] - BELOW_START_C, rel=1e-6)
    assert "winding" in cert["constraints"]
    assert res.kkt["primal"] == pytest.approx(cert["violation"][-1], rel=1e-6)
    ipopt = IpoptSolver(problem).solve(x0_of(), GOAL)
    assert ipopt.status == "infeasible" and ipopt.certificate["constraints"]


def test_a_solve_stopped_early_is_failed_never_infeasible():
    res = DDPSolver(thermal_pendulum(t_max=BELOW_START_C), {**FULL.__dict__, "max_iterations": 2}).solve(
        x0_of(), GOAL)
    assert res.status == "failed" and res.reason == "max_iterations" and res.certificate is None
    assert res.summary()["status"] == "failed" and res.summary()["reason"] == "max_iterations"
    ipopt = IpoptSolver(thermal_pendulum(t_max=ACTIVE_C), {"max_iterations": 2}).solve(x0_of(), GOAL)
    assert ipopt.status == "failed" and ipopt.reason == "max_iterations"


def test_summary_carries_status_reason_and_kkt(active):
    import json
    import pickle

    summary = active[2].summary()
    assert summary["status"] == "converged" and summary["reason"] == ""
    assert set(summary["kkt"]) == {"stationarity", "primal", "complementarity"}
    json.dumps(summary)
    # the residuals are evaluated on first access; a pickled result (a sweep's worker) carries them as a dict
    for result in active[1:]:
        copy = pickle.loads(pickle.dumps(result))
        assert type(copy.kkt) is dict and copy.kkt == dict(result.kkt)


def test_the_contract_is_enforced():
    xs, us = np.zeros((3, 1)), np.zeros((2, 1))
    with pytest.raises(ValueError, match="status"):
        SolverResult("x", True, "max_iterations", "", xs, us, 0.0, 0.0, 1, 0.0)
    with pytest.raises(ValueError, match="certificate"):
        SolverResult("x", False, "infeasible", "", xs, us, 0.0, 0.0, 1, 0.0, reason="locally_infeasible")
    with pytest.raises(ValueError, match="reason"):
        SolverResult("x", False, "failed", "", xs, us, 0.0, 0.0, 1, 0.0)
    assert plugin_verdict("Maximum_Iterations_Exceeded", False) == ("failed", "max_iterations")
    assert plugin_verdict("Infeasible_Problem_Detected", False)[0] == "infeasible"
    assert plugin_verdict("Solve_Succeeded", True) == ("converged", "")
