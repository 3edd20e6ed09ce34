"""Energy conservation, the report's facts, and the plant simulator against an independent ODE solver."""
import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import solve_ivp

from thermo_ddp.model.actuated import load_model
from thermo_ddp.model.parameters import load_parameters
from thermo_ddp.model.thermal import network_from_parameters

ENERGY_TOL = 1e-8  # relative drift of mechanical energy, RK4 at 1 ms over 2 s


def test_rk4_conserves_mechanical_energy_without_current_or_friction():
    joints = ("arm_left_3_joint", "arm_left_4_joint")
    model = load_model(joints, payload_kg=10.0)
    frictionless = {j: p.replace("motor", viscous_friction_nm_s_per_rad=0.0, coulomb_friction_nm=0.0)
                    for j, p in model.params.items()}
    model = type(model).from_parameters(model.arm.settings, frictionless)
    x0 = model.state(q=[0.4, -1.2], v=[1.5, -2.0])
    traj = model.simulate(x0, np.zeros((2000, 2)), 1e-3)
    pm, data = model.arm.model, model.arm.model.createData()
    energy = [pin.computeKineticEnergy(pm, data, x[:2], x[2:4]) + pin.computePotentialEnergy(pm, data, x[:2])
              for x in traj.xs]
    kinetic0 = pin.computeKineticEnergy(pm, data, x0[:2], x0[2:4])
    assert np.ptp(energy) <= ENERGY_TOL * kinetic0
    assert np.ptp(traj["q_rad"][:, 1]) > 0.5  # the arm really moved


def test_simulator_matches_an_independent_solver_with_fourth_order_convergence():
    model = load_model(payload_kg=20.0)
    x0 = model.state(q=[-1.0], v=[0.5])
    ref = solve_ivp(lambda t, x: np.array(model.ode(x, [-4.0], 26.0)).ravel(), (0, 2.0), x0,
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    errors = []
    for dt in (0.01, 0.005):
        traj = model.simulate(x0, np.full((round(2.0 / dt), 1), -4.0), dt)
        errors.append(np.abs(ref.sol(traj.time_s).T - traj.xs).max())
    assert errors[1] < 1e-5
    assert 10 < errors[0] / errors[1] < 22  # RK4: halving dt divides the error by about 16


def test_implicit_euler_is_stable_at_large_steps_and_agrees_at_small_ones():
    model = load_model(payload_kg=40.0)
    q = np.array([-np.pi / 2])
    x0 = model.state(q=q)
    i = np.tile(model.static_current_a(q), (60, 1))
    coarse = model.simulate(x0, i, 1.0, "implicit_euler")
    fine = model.simulate(x0, np.repeat(i, 100, axis=0), 0.01, "rk4")
    assert np.isfinite(coarse.xs).all()
    assert abs(coarse["winding_c"][-1, 0] - fine["winding_c"][-1, 0]) < 3.0  # first-order at 1 s


# --- the report's facts, checked on the elbow's parameter file --------------------------------

@pytest.fixture(scope="module")
def elbow():
    from thermo_ddp.model.parameters import packaged_parameter_file
    return load_parameters(packaged_parameter_file("arm_left_4_joint"))


def test_idle_motor_sits_at_43c_in_a_26c_room(elbow):
    model = load_model()
    assert elbow.thermal.ambient_c == 26.0
    assert model.idle_temperatures()[model.networks["arm_left_4_joint"].index("casing")] == pytest.approx(43.0, abs=1.0)


def test_5a_continuous_settles_the_winding_near_the_84c_cutoff_from_idle(elbow):
    model = load_model()
    net = model.networks["arm_left_4_joint"]
    # A 5 A hold: the payload whose static current at horizontal is 5 A, held for 4 h (implicit Euler).
    q = np.array([-np.pi / 2])
    i0 = model.static_current_a(q)[0]
    payload = (-5.0 - i0) / (load_model(payload_kg=1.0).static_current_a(q)[0] - i0)  # affine in mass
    held = load_model(payload_kg=payload)
    i = held.static_current_a(q)
    assert i[0] == pytest.approx(-5.0, abs=1e-3)
    traj = held.simulate(held.state(q=q), np.tile(i, (1440, 1)), 10.0, "implicit_euler")
    assert traj["casing_c"][0, 0] == pytest.approx(43.0, abs=1.0)
    assert traj["winding_c"][-1, 0] == pytest.approx(elbow.limits.safety_cutoff_c, abs=4.0)
    assert np.abs(np.diff(traj["winding_c"][-30:, 0])).max() < 0.01  # settled
    assert net.sensor_node == "casing" and net.limit_node == "winding"


def test_time_constants_winding_tens_of_seconds_casing_tens_of_minutes(elbow):
    import casadi as ca
    net = network_from_parameters(elbow.thermal)
    t = ca.SX.sym("t", len(net.nodes))
    rhs = net.rhs(t, {"joule_w": 0.0, "friction_w": 0.0, "current_sq_a2": 0.0}, 26.0)
    tau = np.sort(-1 / np.linalg.eigvals(np.array(ca.Function("j", [t], [ca.jacobian(rhs, t)])(0))).real)
    assert 10 <= tau[0] <= 100          # winding: tens of seconds
    assert 10 * 60 <= tau[-1] <= 60 * 60  # casing: tens of minutes
