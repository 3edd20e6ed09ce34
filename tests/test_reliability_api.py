"""Issue 14, the API: arguments checked before work (numpy scalars accepted, shapes checked, limits on
work named with their reason), no option silently read as another."""
import json

import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.model.actuated import load_model
from thermo_ddp.studies.demo import hold_demo
from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, plan_lift


@pytest.fixture(scope="module")
def model():
    return load_model(payload_kg=10.0)


@pytest.mark.parametrize("dt_s", [-0.01, 0.0, float("nan"), float("inf"), "0.01"])
def test_simulate_and_step_refuse_a_bad_step(model, dt_s):
    with pytest.raises(InputError, match="dt_s"):
        model.simulate(model.state(), np.zeros((3, 1)), dt_s)
    with pytest.raises(InputError, match="dt_s"):
        model.step(dt_s)


@pytest.mark.parametrize("currents, x0", [
    (np.zeros((3, 2)), None),              # two joints' currents for a one-joint model
    (np.zeros((0, 1)), None),              # no step
    (np.zeros((2, 2, 1)), None),
    ([[1.0], [np.nan]], None),
    (np.zeros((3, 1)), np.zeros(2)),       # state of the wrong size
    (np.zeros((3, 1)), [0.0, 0.0, np.inf, 30.0, 30.0]),
])
def test_simulate_refuses_bad_shapes_and_values(model, currents, x0):
    with pytest.raises(InputError):
        model.simulate(model.state() if x0 is None else x0, currents, 0.01)


def test_simulate_accepts_numpy_scalars_and_one_joint_vectors(model):
    a = model.simulate(model.state(), np.full(4, 2.0), np.float32(0.01), ambient_c=np.float64(26.0))
    b = model.simulate(model.state(), np.full((4, 1), 2.0), 0.01, ambient_c=26.0)
    assert np.allclose(a.xs, b.xs, rtol=1e-6) and a.xs.shape == (5, model.nx)


def test_plan_lift_with_numpy_scalars_gives_a_json_plan():
    plan = plan_lift(np.float32(20.0), np.float64(84.0), np.float32(2.0), find_longest_hold=False)
    d = json.loads(json.dumps(plan.to_dict()))
    assert d["payload_kg"] == 20.0 and d["hold_s"] == 2.0 and type(plan.settings.payload_kg) is float


def test_zero_velocity_limit_is_refused_not_read_as_the_default():
    with pytest.raises(InputError, match="velocity_limit_rad_s"):
        LiftSettings(velocity_limit_rad_s=0.0)
    # a given limit is the one used (not the URDF's)
    lp = build_lift_problem(LiftSettings(velocity_limit_rad_s=0.5, hold_s=1.0))
    g = lp.problem.constraints[[c.name for c in lp.problem.constraints].index("joint_velocity")].function
    x = lp.x0.copy()
    x[1] = 0.7
    assert float(np.max(np.array(g(x, [0.0], lp.params[0])))) == pytest.approx(0.2)


@pytest.mark.parametrize("name, value", [("goal_rad", 1.0), ("goal_rad", -3.0), ("start_rad", 0.5)])
def test_angles_outside_the_joint_range_are_refused(name, value):
    with pytest.raises(InputError, match=f"{name}.*range"):
        build_lift_problem(LiftSettings(hold_s=1.0, **{name: value}))


@pytest.mark.parametrize("options, words", [
    ({"hold_s": 1e6}, "3600 s"), ({"hold_s": float("inf")}, "finite"), ({"payload_kg": -1.0}, ">= 0 kg"),
    ({"dt_s": 0.001, "hold_s": 3600.0}, "50000 knots"), ({"payload_kg": "40"}, "number"),
    ({"tracking_weight": 0.0}, "> 0"), ({"integrator": "euler"}, "integrator"),
])
def test_lift_settings_bound_the_work(options, words):
    with pytest.raises(InputError, match=words):
        LiftSettings(**options)


@pytest.mark.parametrize("kwargs", [{"hold_s": 1e9}, {"hold_s": float("nan")}, {"dt_s": 1e-9}, {"payload_kg": 1e6}])
def test_hold_demo_bounds_the_work(kwargs):
    with pytest.raises(InputError):
        hold_demo(**kwargs)


@pytest.mark.parametrize("options, words", [
    ({"hold_s": float("inf")}, "finite"), ({"payload_kg": "x"}, "number"), ({"hold_s": 0.0}, "hold_s"),
    ({"dt_s": 0.001, "hold_s": 3600.0}, "50000 knots"), ({"move_s": -1.0}, "move_s"),
])
def test_whole_arm_settings_bound_the_work(options, words):
    from thermo_ddp.tasks.whole_arm import WholeArmSettings
    with pytest.raises(InputError, match=words):
        WholeArmSettings(**options)


@pytest.mark.parametrize("kwargs", [{"q": [0.0, 0.0]}, {"v": [np.nan]}, {"temperatures_c": [30.0]}])
def test_state_checks_each_part(model, kwargs):
    with pytest.raises(InputError):
        model.state(**kwargs)


def test_static_current_checks_the_posture(model):
    with pytest.raises(InputError, match="q"):
        model.static_current_a([0.0, 1.0])
