"""Receding-horizon control of the elbow lift: plant mismatch, observer, warm re-solves, closed loop.

Oracles: the plant's own parameter files (perturbed model), the true simulated winding, a cold
DDP solve and IPOPT from the same state, and the counterfactual closed loop without the
observer's resistance scale and back-off (which does exceed the limit).
"""
import dataclasses

import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.tasks.lift import initial_guess, make_solver
from thermo_ddp.mpc import (ExtendedKalmanFilter, MPCSettings, Plant, RecedingHorizonController, build_models,
                            mpc_solver, perturbed_model, planning_problem, run_closed_loop, scaled_ode)
from thermo_ddp.model.integrators import make_step
from thermo_ddp.solvers import DDPSettings, IpoptSolver

LIMIT_C = 84.0
HOLD_S = 12.0  # longer than the plant can hold under 84 °C (the nominal model alone allows ~12.6 s)


@pytest.fixture(scope="module")
def mismatched():
    """Plant resistances +15 %, casing noise 0.1 °C and 0.1 °C quantisation (the defaults), planned at 84."""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S)
    assert settings.plant.plant_resistance_scale == 1.15 and settings.sensors.casing_quantum_c == 0.1
    return run_closed_loop(settings, progress=False)


def test_settings_are_validated_and_unknown_options_raise():
    with pytest.raises(InputError, match="unknown option"):
        run_closed_loop(horizon=50)
    for bad in ({"backoff_c": -1.0}, {"integrator": "euler"}, {"horizon_knots": 2.5},
                {"casing_dropout_probability": 1.0}, {"plant_resistance_scale": 0.0}):
        with pytest.raises(InputError):
            MPCSettings.from_options(**bad)
    with pytest.raises(InputError, match="horizon_knots"):  # the window must hold lift + lower + settle
        planning_problem(MPCSettings.from_options(horizon_knots=40), build_models(MPCSettings())[0])


def test_plant_differs_from_the_planner_by_the_resistance_scale():
    model, plant = build_models(MPCSettings.from_options(plant_resistance_scale=1.15))
    joint = model.joints[0]
    nominal, real = model.params[joint].thermal.values, plant.params[joint].thermal.values
    for key, value in nominal.items():
        factor = 1.15 if key.endswith("_k_per_w") else 1.0
        assert real[key] == pytest.approx(factor * value, rel=1e-12)
    # every idle temperature rise above ambient scales with the resistances (network is linear)
    rise = model.idle_temperatures() - model.ambient_c
    assert np.allclose(plant.idle_temperatures() - model.ambient_c, 1.15 * rise)


def test_scaled_observer_model_is_the_model_at_its_scale():
    """The observer's augmented ODE at s = 1 is the planner's model, at s = 1.15 the plant's."""
    model, plant = build_models(MPCSettings())
    step = make_step(scaled_ode(model), 0.1, "rk4")
    rng = np.random.default_rng(1)
    for scale, reference in ((1.0, model), (1.15, plant)):
        ref = reference.step(0.1, "rk4")
        for _ in range(5):
            x = model.state(q=[rng.uniform(-2, 0)], v=[rng.uniform(-1, 1)],
                            temperatures_c=rng.uniform(30, 90, size=model.nx - 2))
            u = rng.uniform(-15, 15, size=1)
            got = np.array(step(np.append(x, scale), u, model.ambient_c)).ravel()
            want = np.array(ref(x, u, model.ambient_c)).ravel()
            assert np.allclose(got[:-1], want, rtol=1e-12, atol=1e-10) and got[-1] == scale


def test_casing_sensor_is_noisy_and_quantised():
    settings = MPCSettings.from_options(casing_noise_c=0.1, casing_quantum_c=0.1)
    model, _ = build_models(settings)
    plant = Plant(model, model.state(q=[-0.05]), settings, np.random.default_rng(0))
    samples = np.array([plant.measure().casing_c[0] for _ in range(2000)])
    assert np.allclose(samples / 0.1, np.round(samples / 0.1), atol=1e-9)
    true = model.state(q=[-0.05])[model.index(model.joints[0], "casing_c")]
    assert abs(samples.mean() - true) < 0.01 and 0.09 < samples.std() < 0.12
    delayed = Plant(model, model.state(q=[-0.05]), settings.replace(casing_delay_steps=2),
                    np.random.default_rng(0))
    assert [delayed.measure().casing_c is None for _ in range(3)] == [True, True, False]


def test_closed_loop_keeps_the_true_winding_under_the_limit_with_a_mismatched_plant(mismatched):
    r = mismatched
    assert r.success and r.status == "completed", r.report()
    assert r.peak_winding_c <= LIMIT_C and r.margin_c >= 0
    assert not r.cutoff_tripped and r.measured_casing_c.max() < r.safety_cutoff_c == 84.0
    # the winding limit was active: the loop drove the true winding to the planning limit ...
    assert r.peak_winding_c > r.settings.planning_limit_c - 0.3
    # ... and cut the requested hold (the hotter plant cannot hold 12 s) instead of overheating
    assert r.hold_s[-1] < HOLD_S and "hold_shortened" in r.step_status
    q = r.q_rad[round(2.0 / 0.1) + 3: round((2.0 + r.hold_s[-1]) / 0.1)]
    assert np.abs(q + np.pi / 2).max() < 0.03  # it did hold (hold band 0.02 rad on the planner's model)
    # the observer saw through the mismatch
    assert np.abs(r.estimation_error_c).max() < 0.3
    assert r.resistance_scale[-1] == pytest.approx(1.15, abs=0.03)
    assert np.all(np.isfinite(r.solve_s)) and "fallback" not in r.step_status


def test_without_the_resistance_scale_and_back_off_the_limit_is_exceeded(mismatched):
    """Counterfactual: the plain EKF under-estimates the hotter winding; planning right at 84 overheats."""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S, backoff_c=0.0, estimate_resistance_scale=False)
    r = run_closed_loop(settings, progress=False)
    assert r.status == "winding_limit_exceeded" and not r.success
    assert r.estimation_error_c.min() < -0.8  # biased low by the 15 % resistance mismatch
    assert r.peak_winding_c > mismatched.peak_winding_c


def test_closed_loop_with_sensor_delay_and_dropouts():
    r = run_closed_loop(MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S, casing_delay_steps=3,
                                    casing_dropout_probability=0.3, seed=3), progress=False)
    assert r.success and r.peak_winding_c <= LIMIT_C and not r.cutoff_tripped
    assert 0.5 < r.casing_received.mean() < 0.9


def test_ekf_converges_to_the_true_winding_on_a_matched_model():
    """Matched plant; the filter re-run on the recorded measurements from a 5 K wrong winding converges."""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=8.0, plant_resistance_scale=1.0, extra_s=150.0)
    r = run_closed_loop(settings, progress=False)
    assert np.abs(r.estimation_error_c).max() < 0.3  # the online filter, started at the idle equilibrium
    model, _ = build_models(settings)
    ekf = ExtendedKalmanFilter(model, settings)
    ekf.initialise(r.measurements[0])
    w = model.node_indices("winding")
    ekf.z[w] += 5.0
    ekf.P[w, w] += 25.0
    errors = [ekf.winding_c[0] - r.winding_c[0]]
    for m, true in zip(r.measurements[1:], r.winding_c[1:]):
        ekf.predict(m.current_a)
        ekf.update(m)
        errors.append(ekf.winding_c[0] - true)
    errors = np.abs(errors)
    assert errors[0] > 4.9 and errors[-1] < 0.15
    assert errors[-1] < 2 * ekf.winding_std_c[0] + 0.05  # the covariance is consistent with the error
    assert r.winding_c.max() > 70  # the convergence was through a real heating and cooling cycle


def test_warm_started_resolve_equals_a_cold_solve_from_the_same_state():
    """Mid-hold with the winding limit active, the model as plant: the re-solve warm-started from the
    previous plan shifted by one knot reaches the cold solve's cost (and IPOPT's)."""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S)
    model, _ = build_models(settings)
    lp = planning_problem(settings, model)
    controller = RecedingHorizonController(lp, settings, mpc_solver(lp, settings))
    controller.start(lp.x0)
    step = lp.problem.functions.step
    x, k = lp.x0, 100
    for j in range(1, k):
        x = np.array(step(x, controller.plan.us[0], controller.window(j - 1)[0])).ravel()
        controller.step(x)
    x = np.array(step(x, controller.plan.us[0], controller.window(k - 1)[0])).ravel()
    window = controller.window(k)
    solver = make_solver(lp, "ddp", DDPSettings(full_second_order=True))  # same problem, 200 iterations
    warm = solver.solve(x, window, controller.warm_start(1))
    cold = solver.solve(x, window, initial_guess(dataclasses.replace(lp, x0=x, params=window)))
    assert warm.success and cold.success, (warm.status, cold.status)
    assert warm.iterations < cold.iterations
    assert abs(warm.cost - cold.cost) <= 1e-6 * abs(cold.cost)
    winding = model.node_indices("winding")
    # limit active where the winding peaks, in the lowering, whose limit is lowered by the reserve the lowering keeps
    # while it lies ahead: the plan enters the soft back-off band over it only by what its penalty allows (mK)
    top = settings.planning_limit_c - settings.controller.lowering_reserve_c
    assert settings.controller.lowering_reserve_c > 0 and top <= warm.xs[:, winding].max() <= top + 0.01
    ipopt = IpoptSolver(lp.problem).solve(x, window, initial_guess(dataclasses.replace(lp, x0=x, params=window)))
    assert ipopt.success and abs(ipopt.cost - cold.cost) <= 1e-5 * abs(ipopt.cost)


def test_report_and_plot(mismatched, tmp_path):
    text = mismatched.report()
    assert "SUCCESS" in text and "margin" in text and "cut-off 84" in text
    path = tmp_path / "closed_loop.png"
    mismatched.plot(path)
    assert path.stat().st_size > 10_000
    d = mismatched.to_dict()
    assert d["peak_winding_c"] == mismatched.peak_winding_c and len(d["time_s"]) == len(d["winding_c"])


def test_perturbed_model_with_unit_scales_is_the_model():
    model, _ = build_models(MPCSettings())
    same = perturbed_model(model)
    assert np.allclose(same.idle_temperatures(), model.idle_temperatures())


def test_warm_start_moves_the_multipliers_one_knot_and_frees_the_present_states_rows():
    """The controller's warm start: stage multipliers moved on one knot (last repeated), those of the hold band and
    the winding limit at knot 0 (switched off on the measured state by the window) zero, the penalty capped."""
    from thermo_ddp.mpc.controller import shifted_warm_start
    from thermo_ddp.solvers import SolverResult
    from thermo_ddp.solvers.kkt import constraint_rows

    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S)
    pr = planning_problem(settings, build_models(settings)[0]).problem
    rng = np.random.default_rng(0)
    lam = rng.uniform(0.1, 1.0, (pr.horizon, pr.n_constraints))
    rho = np.full(pr.n_constraints + pr.n_terminal_constraints, 1e8)
    xs, us = rng.normal(size=(pr.horizon + 1, pr.nx)), rng.normal(size=(pr.horizon, pr.nu))
    result = SolverResult("ddp", True, "converged", "", xs, us, 0.0, 0.0, 1, 0.0,
                          multipliers={"constraints": lam, "terminal_constraints": np.ones(pr.n_terminal_constraints),
                                       "penalty": rho})
    warm = shifted_warm_start(result, pr, 1, penalty_max=1e6)
    band = np.isin(constraint_rows(pr)[0], ("hold_band", "winding_limit"))
    moved = warm.multipliers["constraints"]
    assert band.sum() == 3 and np.all(moved[0, band] == 0)
    np.testing.assert_array_equal(moved[0, ~band], lam[1, ~band])
    np.testing.assert_array_equal(moved[1:-1], lam[2:])
    np.testing.assert_array_equal(moved[-1], lam[-1])
    np.testing.assert_array_equal(warm.xs[:-1], xs[1:])
    assert np.all(warm.multipliers["penalty"] == 1e6)



def test_a_winding_estimated_over_the_limit_gets_the_limit_it_can_reach():
    """An estimate over the hard winding limit (the plant ran hotter than planned): no current cools the winding
    under it within a period, so with the window's limit every re-solve is infeasible at knot 1 (the sweep's
    fallback periods). The controller raises the limit, knot by knot, to the winding the warm start's currents
    reach, at most the estimate's own winding, plus 1e-4 K (oracle: the model's step rolled out here), and leaves
    a cool estimate's window as it is.
    (The closed loops: test_mpc_faults.py::test_soft_backoff_plans_a_longer_hold_through_a_hotter_plant.)"""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=HOLD_S)
    model, _ = build_models(settings)
    lp = planning_problem(settings, model)
    controller = RecedingHorizonController(lp, settings, mpc_solver(lp, settings))
    controller.start(lp.x0)
    warm, window = controller.warm_start(1), controller.window(1)
    assert controller.reachable_limit(window, lp.x0, warm) is window   # a cool estimate: nothing to raise
    hot = lp.x0.copy()
    hot[2:] = settings.planning_limit_c + settings.scenario.backoff_c + 0.3
    raised = controller.reachable_limit(window, hot, warm)
    x, reached = hot, []
    for j in range(lp.problem.horizon):
        x = np.array(lp.problem.functions.step(x, warm.us[j], window[j])).ravel()
        reached.append(x[model.node_indices("winding")[0]])
    cols = lp.problem.parameters.slice("limit_c")
    now = hot[model.node_indices("winding")[0]]   # never planned hotter than the estimate
    expected = np.maximum(window[1:, cols].ravel(), np.minimum(reached, now) - settings.scenario.backoff_c + 1e-4)
    np.testing.assert_allclose(raised[1:, cols].ravel(), expected, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(raised[0], window[0])
    other = np.ones(window.shape[1], bool)
    other[cols] = False
    np.testing.assert_array_equal(raised[:, other], window[:, other])
    assert raised[1, cols] > window[1, cols]
