"""Robust receding-horizon planning (mpc.robust): the controller's hold kept to what every motor of the set
survives, the set narrowed by the observer's resistance scale.

Oracles: brute force over the set's vertices and random motors (the planner's own replay, checked against an
independent solve_ivp replay in test_robust_lift), the nominal controller from the same state, the true plant
of a closed loop (the sweep's hot draw on which the nominal hold needs the fallback)."""
import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.mpc import (MPCSettings, RecedingHorizonController, build_models, mpc_solver, planning_problem,
                            run_closed_loop)
from thermo_ddp.studies.sweep import OBSERVER, _controller, draw, run_seeds
from thermo_ddp.tasks.robust import TOLERANCE_K

LIMIT_C = 84.0
HOT_RUN = 10  # run 10 of the sweep with seed 0: a plant hotter than the model; the nominal hold falls back 19 times


@pytest.fixture(scope="module")
def controllers():
    """The robust (+-25 %) and the nominal controller's cold plans from a warm motor (every node at 45 °C)."""
    settings = MPCSettings.from_options(limit_c=LIMIT_C, hold_s=15.0, robust_uncertainty=0.25)
    model, _ = build_models(settings)
    lp = planning_problem(settings, model)
    solver = mpc_solver(lp, settings)
    x0 = model.state(q=[lp.settings.start_rad], temperatures_c=np.full(model.nx - 2 * model.nu, 45.0))
    robust = RecedingHorizonController(lp, settings, solver)
    nominal = RecedingHorizonController(lp, settings.replace(robust_uncertainty=0.0), solver)
    return robust, robust.start(x0), nominal, nominal.start(x0), x0


def peaks(ctl, plan_of, x0, motors) -> np.ndarray:
    rh, n = ctl.robust or plan_of.robust, ctl.lp.model.nu
    plan = ctl.plan
    return np.array([rh.worst.peak(th, plan.xs[:, :2 * n], plan.us, ctl.window(), ctl.lp.model.ambient_c,
                                   x0[2 * n:])[0] for th in motors])


def test_settings_are_validated():
    for bad in ({"robust_uncertainty": 1.0}, {"robust_uncertainty": -0.1}, {"robust_replan_s": 0.0}):
        with pytest.raises(InputError):
            MPCSettings.from_options(**bad)


def test_cold_plan_is_safe_for_every_motor_of_the_set(controllers):
    robust, step, nominal, nominal_step, x0 = controllers
    assert "robust_cut" in step.events and 0 < robust.hold_s < nominal.hold_s
    uset = robust.robust.uset
    rng = np.random.default_rng(0)
    motors = [uset.theta(z) for z in np.vstack([rng.choice([-1.0, 1.0], size=(48, uset.size)),
                                                rng.uniform(-1, 1, size=(16, uset.size))])]
    limit = robust.lp.settings.limit_c  # the planning limit (the task's minus the back-off)
    assert peaks(robust, robust, x0, motors).max() <= limit + TOLERANCE_K
    assert robust.robust.last.peak_c >= peaks(robust, robust, x0, motors).max() - 1e-9  # the search beat them
    assert peaks(nominal, robust, x0, motors).max() > limit + 0.5  # the nominal hold overheats some motors


def test_the_set_narrows_to_the_observers_interval(controllers):
    rh = controllers[0].robust
    keys = rh.prior.keys
    r = np.array([k.endswith("_k_per_w") for k in keys])
    uset = rh.narrow(1.1, 0.01)  # 2 sigma: 1.08 .. 1.12, inside the prior's 0.75 .. 1.25
    np.testing.assert_allclose(uset.low[r] / uset.nominal[r], 1.08)
    np.testing.assert_allclose(uset.high[r] / uset.nominal[r], 1.12)
    np.testing.assert_allclose(uset.low[~r], rh.prior.low[~r])  # capacities, losses: the prior's
    uset = rh.narrow(1.5, 0.01)  # outside the prior: the observer's interval
    np.testing.assert_allclose(uset.low[r] / uset.nominal[r], 1.48)
    rh.narrow(1.0, 1.0)  # wider than the prior: the prior
    np.testing.assert_allclose(rh.uset.high, rh.prior.high)


def test_closed_loop_on_a_hot_plant_needs_no_fallback():
    """The sweep's hot run: the robust hold needs no fallback plan and the true winding stays under the limit; the
    nominal hold (which needed the fallback before it kept the lowering's heat) stays safe and in range too, with a
    hold no shorter than the robust one."""
    d = draw(run_seeds(0, HOT_RUN + 1)[HOT_RUN])
    runs = {robust: run_closed_loop(MPCSettings.from_options(**_controller(False, not robust), **d),
                                    observer=OBSERVER, progress=False) for robust in (True, False)}
    nominal = runs[False]
    assert nominal.success and nominal.range_excess_rad.max() == 0 and nominal.hold_s[-1] >= runs[True].hold_s[-1]
    r = runs[True]
    assert r.step_status.count("fallback") == 0 and r.peak_winding_c < r.limit_c and not r.cutoff_tripped
    events = r.event_counts()
    assert "robust_cut" in events and "robust_extend" in events  # cut at the start, lengthened as it learned
