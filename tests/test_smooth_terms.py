"""Every heat term is smooth at v = 0 (issue 23): derivatives of the thermal right-hand side in the joint speed
against central finite differences at and around rest, finite second derivatives for every speed exponent,
and the implicit Euler step's Newton residual checked."""
import casadi as ca
import numpy as np
import pytest

from thermo_ddp.model import motor
from thermo_ddp.model.actuated import load_model
from thermo_ddp.model.integrators import IMPLICIT_RESIDUAL_TOL, check_implicit_steps
from thermo_ddp.model.parameters import load_parameters, parameters_from_dict
from thermo_ddp.model.thermal import joint_heat_rhs, network_from_parameters


def _speed_heated(elbow_file, exponent: float):
    """The elbow's parameters with friction heat (c1 |v| + c2 v^2) and iron losses (|v|^exponent) switched on."""
    data = load_parameters(elbow_file).to_dict()
    data["thermal"].update(friction_heating_fraction=0.5, friction_heat_linear_w_s_per_rad=3.0,
                           friction_heat_quadratic_w_s2_per_rad2=1.0, iron_loss_w=4.0,
                           iron_loss_ref_speed_rad_s=2.0, iron_loss_speed_exponent=exponent)
    return parameters_from_dict(data)


@pytest.mark.parametrize("exponent", [1.0, 1.5, 2.0, 2.4])
def test_heat_rhs_derivatives_in_speed_match_finite_differences_at_rest(elbow_file, exponent):
    params = _speed_heated(elbow_file, exponent)
    net = network_from_parameters(params.thermal)
    v = ca.SX.sym("v")
    temps = np.array([60.0, 45.0, 50.0][:len(net.nodes)])
    rhs = joint_heat_rhs(net, params.motor, temps, 3.0, v, 26.0)
    f = ca.Function("f", [v], [rhs])
    df = ca.Function("df", [v], [ca.jacobian(rhs, v)])
    d2f = ca.Function("d2f", [v], [ca.jacobian(ca.jacobian(rhs, v), v)])
    h = 1e-6
    for v0 in (0.0, 1e-4, -0.03, 0.5):
        fd = (np.array(f(v0 + h)) - np.array(f(v0 - h))) / (2 * h)
        assert np.array(df(v0)) == pytest.approx(fd, rel=1e-5, abs=1e-7), v0
        second = np.array(d2f(v0))
        assert np.all(np.isfinite(second)), (exponent, v0)
        fd2 = (np.array(df(v0 + h)) - np.array(df(v0 - h))) / (2 * h)
        assert second == pytest.approx(fd2, rel=1e-3, abs=1e-4), (exponent, v0)
    # at rest the speed-driven heat is zero, far from rest it is the file's |v| law
    eps = params.motor.coulomb_smoothing_rad_s
    assert float(motor.smooth_abs(params.motor, 0.0)) == 0.0
    assert float(motor.smooth_abs(params.motor, -20 * eps)) == pytest.approx(20 * eps, rel=1e-12)


def test_friction_power_is_the_friction_torque_times_speed(elbow_file):
    m = load_parameters(elbow_file).motor
    for v in (-1.0, -0.05, 0.0, 0.02, 2.0):
        assert float(motor.friction_w(m, v)) == pytest.approx(float(motor.friction_torque_nm(m, v)) * v, abs=1e-12)


def test_implicit_euler_steps_are_checked():
    model = load_model(("arm_left_4_joint",), payload_kg=10.0)
    u = np.full((20, 1), -5.0)
    good = model.simulate(model.state(q=[-1.0]), u, 0.05, "implicit_euler")
    amb = np.full((20, 1), model.ambient_c)
    assert check_implicit_steps(model.ode, 0.05, good.xs, u, amb) <= IMPLICIT_RESIDUAL_TOL
    with pytest.raises(ArithmeticError, match="Newton residual"):  # 4 Newton steps cannot close a 0.5 s step
        model.simulate(model.state(q=[-1.0]), u[:5], 0.5, "implicit_euler")
