"""Plan verdicts you can trust (issue 23): a failed solve is retried and never becomes a verdict, verdicts
name their cause with the number to change, zero weights solve, settings objects are accepted."""
import json

import casadi as ca
import numpy as np
import pytest

from thermo_ddp import InputError, LiftSettings, plan_lift
from thermo_ddp.cli import main
from thermo_ddp.solvers import DDPSettings, DDPSolver
from thermo_ddp.tasks import attempts, lift
from thermo_ddp.tasks.attempts import Outcome, solve_until_verdict
from thermo_ddp.tasks.problem import initial_guess
from thermo_ddp.tasks.verdicts import cause_class, cause_of, verdict


def _failed_ladder(monkeypatch):
    """Every solve of the ladder stops after one iteration: none reaches a verdict."""
    def solve(self, tp, guess):
        quick = DDPSolver(tp.problem, DDPSettings(max_iterations=1))
        return solve_until_verdict([("ddp", lambda: quick.solve(tp.x0, tp.params, guess)),
                                    ("ddp again", lambda: quick.solve(tp.x0, tp.params, attempts.rest_guess(tp)))])
    monkeypatch.setattr(attempts.SolverLadder, "solve", solve)


def test_a_failed_solve_is_never_a_verdict(monkeypatch, tmp_path, capsys):
    _failed_ladder(monkeypatch)
    plan = plan_lift(20.0, 84.0, 3.0)
    assert plan.status == "failed" and not plan.success and not plan.feasible and plan.cause is None
    assert "no solve reached a verdict" in plan.message and "cannot" not in plan.message
    out = tmp_path / "plan.json"
    assert main(["plan", "--payload-kg", "20", "--hold-s", "3", "--json", str(out)]) == 1
    d = json.loads(out.read_text())
    assert d["status"] == "failed" and d["success"] is False and d["solver"]["status"] == "failed"
    assert "no answer" in capsys.readouterr().out


def test_the_ladder_stops_at_the_first_verdict_and_reports_every_attempt():
    lp = lift.build_lift_problem(LiftSettings(payload_kg=20.0, limit_c=84.0, hold_s=2.0))
    one = DDPSolver(lp.problem, DDPSettings(max_iterations=1))
    full = lift.make_solver(lp)
    outcome = solve_until_verdict([("short", lambda: one.solve(lp.x0, lp.params, initial_guess(lp))),
                                   ("full", lambda: full.solve(lp.x0, lp.params, initial_guess(lp))),
                                   ("never", lambda: pytest.fail("ran past a verdict"))])
    assert isinstance(outcome, Outcome) and outcome.verdict == "feasible"
    assert [name for name, _ in outcome.attempts] == ["short", "full"]
    assert outcome.attempts[0][1].status == "failed" and verdict(outcome.attempts[0][1]) is None
    assert "short: failed (max_iterations)" in outcome.tried()


def test_a_warm_start_from_multipliers_without_a_verdict_falls_back_to_its_trajectories(monkeypatch):
    """The ladder's first rung from a guess carrying multipliers stops at the cap (here 1 iteration) without a
    verdict; the next solves the same trajectories without them: the same result as a solve from those alone."""
    lp = lift.build_lift_problem(LiftSettings(payload_kg=20.0, limit_c=84.0, hold_s=2.0))
    solver, guess = lift.make_solver(lp), initial_guess(lp)
    monkeypatch.setattr(attempts, "WARM_MULTIPLIER_ITERATIONS", 1)
    warm = attempts.WarmStart(guess.xs, guess.us, {"constraints": np.ones((lp.problem.horizon, lp.problem.n_constraints)),
                                                  "penalty": 1e4})
    outcome = attempts.SolverLadder(lp.problem, solver).solve(lp, warm)
    assert [name for name, _ in outcome.attempts] == ["ddp from the multipliers", "ddp"]
    first = outcome.attempts[0][1]
    assert first.reason == "stopped" and first.iterations == 1 and verdict(first) is None
    plain = solver.solve(lp.x0, lp.params, attempts.WarmStart(guess.xs, guess.us))
    assert outcome.verdict == verdict(plain) == "feasible"
    np.testing.assert_allclose(outcome.result.us, plain.us, atol=1e-12)


def test_careful_short_lift_is_a_motion_verdict_with_the_lift_time_to_change():
    """The issue's case: 1.3 s to -1.66 rad with careful motion is infeasible because of stop_approach (not the
    heat); the remedy's lift time is the boundary: one step shorter is infeasible, that one feasible."""
    plan = plan_lift(40.0, 137.7, 20.0, lift_s=1.3, goal_rad=-1.66)
    assert plan.status == "infeasible" and plan.cause == "motion", plan.report()
    assert "careful-motion bounds decide" in plan.message and "lift_s >= 1.60 s" in plan.remedy
    assert "137.7" not in plan.remedy
    at, below = (plan_lift(40.0, 137.7, 2.0, lift_s=t, goal_rad=-1.66, find_longest_hold=False) for t in (1.6, 1.5))
    assert at.status == "feasible" and below.status == "infeasible" and below.cause == "motion"


def test_zero_weights_solve_and_match_ipopt():
    """energy_weight = 0 (and every zero weight) is valid: finite derivatives, a converged verdict, IPOPT's."""
    zero = dict(payload_kg=20.0, limit_c=140.0, hold_s=3.0, energy_weight=0.0, velocity_weight=0.0,
                acceleration_weight=0.0, find_longest_hold=False)
    lp = lift.build_lift_problem(LiftSettings(**zero))
    residual = next(c for c in lp.problem.costs if c.name == "joule_energy").residual
    x = ca.SX.sym("x", lp.problem.nx)
    jac = ca.Function("joule_jacobian", [x], [ca.jacobian(residual(x, -5.0, lp.params[0]), x)])(lp.x0)
    assert np.all(np.isfinite(np.array(jac)))  # sqrt(w R(T) dt) i had 0/0 in d/dT at w = 0
    ddp, ipopt = plan_lift(**zero), plan_lift(**zero, solver="ipopt")
    assert ddp.status == ipopt.status == "feasible", ddp.report()
    assert ddp.solver["cost"] == pytest.approx(ipopt.solver["cost"], rel=1e-3, abs=1e-6)


def test_settings_object_or_keywords_not_both():
    s = LiftSettings(payload_kg=20.0, limit_c=84.0, hold_s=2.0)
    by_settings, by_keywords = plan_lift(settings=s), plan_lift(20.0, 84.0, 2.0)
    assert by_settings.status == by_keywords.status == "feasible"
    assert by_settings.solver["cost"] == pytest.approx(by_keywords.solver["cost"], rel=1e-9)
    with pytest.raises(InputError, match="not both") as err:
        plan_lift(30.0, settings=s)
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="not both"):
        plan_lift(settings=s, careful_motion=False)


def test_report_answers_in_a_sentence_and_plot_returns_the_figure(tmp_path):
    plan = plan_lift(40.0, 84.0, 20.0)
    head = plan.report().splitlines()[0]
    assert head.startswith(f"40 kg: holds {plan.achieved_hold_s:.1f} s of the 20 s asked under 84 °C; the winding "
                           "limit decides (time to limit at the goal ")
    assert "limit_c >= " in plan.remedy and "infeasible_hold" not in plan.report()
    fig = plan.plot()
    assert fig.axes[0].get_title() == plan.headline()
    path = tmp_path / "plan.png"
    assert plan.plot(path) is not None and path.stat().st_size > 20_000


def test_cause_classes_cover_every_constraint_kind():
    assert [cause_class(k) for k in ("winding_limit", "terminal_winding_limit", "winding_limit_arm_left_2_joint",
                                     "bus_voltage", "current_peak_arm_left_4_joint", "stop_approach", "one_way",
                                     "joint_range", "hold_band", "return_band")] == [
        "thermal", "thermal", "thermal", "actuator", "actuator", "motion", "motion", "range", None, None]
    assert cause_of(["one_way", "winding_limit"]) == "thermal"
    assert cause_of(["one_way", "winding_limit"], heat_decides=False) == "motion"
    assert cause_of(["hold_band"]) is None
