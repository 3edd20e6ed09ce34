"""Thermal networks: eq. (8) closed form, thermal runaway, networks as data, model wiring."""
import casadi as ca
import numpy as np
import pytest

from thermo_ddp.model import motor
from thermo_ddp.model.actuated import ActuatedArm
from thermo_ddp.model.arm import ArmSettings
from thermo_ddp.model.parameters import load_parameters, parameters_from_dict
from thermo_ddp.model.thermal import AMBIENT, HeatSource, Link, ThermalNetwork, network_from_parameters, one_node_response

ONE_NODE = {"model": "one_node", "ambient_c": 26.0, "capacity_j_per_k": 300.0, "resistance_k_per_w": 1.8}


@pytest.fixture
def one_node(elbow_file):
    data = load_parameters(elbow_file).to_dict()
    data["thermal"] = dict(ONE_NODE)
    return parameters_from_dict(data)


def _simulate_winding(params, current_a, times_s, t0_c):
    """One-node network + eq. (5) Joule losses, integrated by CVODES (tight tolerances)."""
    net = network_from_parameters(params.thermal)
    t = ca.SX.sym("t", 1)
    rhs = net.rhs(t, motor.losses_w(params.motor, current_a, 0.0, t[0]), params.thermal.ambient_c)
    sim = ca.integrator("sim", "cvodes", {"x": t, "ode": rhs}, 0.0, list(times_s),
                        {"abstol": 1e-10, "reltol": 1e-10})
    return np.array(sim(x0=t0_c)["xf"]).ravel()


def _closed(params, i):
    m, th = params.motor, params.thermal
    return one_node_response(m.resistance_ohm, m.resistance_ref_c, m.copper_alpha_per_k,
                             th["capacity_j_per_k"], th["resistance_k_per_w"], th.ambient_c, i)


@pytest.mark.parametrize("current_a", [2.0, 5.0, 10.0])
def test_constant_current_is_first_order_with_eq8_gain_and_time_constant(one_node, current_a):
    resp = _closed(one_node, current_a)
    amb = one_node.thermal.ambient_c
    times = np.linspace(10, 5 * resp.time_constant_s, 20)
    sim = _simulate_winding(one_node, current_a, times, amb)
    expected = amb + resp.gain_k * (1 - np.exp(-times / resp.time_constant_s))
    assert np.abs(sim - expected).max() <= 1e-6 * resp.gain_k
    # and the closed form is eq. (8) of the report: gain and tau grow as 1/(1 - R R_th alpha i^2)
    m, th = one_node.motor, one_node.thermal
    plain = 1 - m.resistance_ohm * th["resistance_k_per_w"] * m.copper_alpha_per_k * current_a ** 2
    assert resp.time_constant_s == pytest.approx(th["capacity_j_per_k"] * th["resistance_k_per_w"] / plain)


def test_runaway_current_reported_and_real(one_node):
    m, th = one_node.motor, one_node.thermal
    resp = _closed(one_node, 1.0)
    expected = (1 / (m.resistance_ohm * m.copper_alpha_per_k * th["resistance_k_per_w"])) ** 0.5
    assert resp.runaway_current_a == pytest.approx(expected)
    below = _simulate_winding(one_node, 0.95 * expected, [20000.0], th.ambient_c)[0]
    above = _simulate_winding(one_node, 1.05 * expected, [20000.0], th.ambient_c)[0]
    assert not _closed(one_node, 0.95 * expected).runaway and _closed(one_node, 1.05 * expected).runaway
    assert below < th.ambient_c + 1.2 * _closed(one_node, 0.95 * expected).gain_k
    assert above > 1000.0  # no equilibrium: the winding heats without bound


def test_a_new_node_is_data_not_code():
    """A three-node chain with a constant source: steady state equals the resistor-chain answer."""
    net = ThermalNetwork(nodes=("a", "b", "c"), capacities_j_per_k=(1.0, 2.0, 3.0),
                         links=(Link("a", "b", 0.5), Link("b", "c", 0.25), Link("c", AMBIENT, 1.0)),
                         sources=(HeatSource("a", None, constant_w=10.0),), sensor_node="c", limit_node="a")
    t = net.steady_state({}, 20.0)
    assert np.allclose(t, [20 + 10 * 1.75, 20 + 10 * 1.25, 20 + 10 * 1.0])


def test_bad_network_is_rejected():
    with pytest.raises(ValueError, match="unknown node"):
        ThermalNetwork(("a",), (1.0,), (Link("a", "z", 1.0),), (), sensor_node="a", limit_node="a")


def test_model_composition_wires_joule_heat_to_the_winding(one_node):
    """Held at rest with its static current, the composed model's winding follows eq. (8)."""
    model = ActuatedArm.from_parameters(ArmSettings(payload_kg=10.0), {"arm_left_4_joint": one_node})
    q = np.array([-np.pi / 2])
    i = model.static_current_a(q)
    traj = model.simulate(model.state(q=q, temperatures_c=[26.0]), np.tile(i, (600, 1)), 0.1)
    resp = _closed(one_node, abs(i[0]))
    expected = 26.0 + resp.gain_k * (1 - np.exp(-traj.time_s / resp.time_constant_s))
    assert np.abs(traj["q_rad"][:, 0] - q[0]).max() < 1e-6
    assert np.abs(traj["winding_c"][:, 0] - expected).max() < 1e-3


# --- optional [thermal] keys: heat the contract adds to any network -------------------------------
TWO_NODE = {"model": "two_node", "ambient_c": 26.0, "winding_capacity_j_per_k": 40.0, "casing_capacity_j_per_k": 1200.0,
            "winding_casing_k_per_w": 0.9, "casing_ambient_k_per_w": 1.3}


def _with_thermal(elbow_file, thermal):
    data = load_parameters(elbow_file).to_dict()
    data["thermal"] = dict(thermal)
    return parameters_from_dict(data)


def _model_steady_state(params, velocity_rad_s, current_a=0.0):
    """Node temperatures where the planner's ODE has no thermal rate at a held velocity and current
    (its thermal rows are affine in the temperatures)."""
    model = ActuatedArm.from_parameters(ArmSettings(), {"arm_left_4_joint": params})
    nt = model.nx - 2

    def rate(temps):
        return np.array(model.ode(np.concatenate([[-1.0, velocity_rad_s], temps]), [current_a], 26.0)).ravel()[2:]
    b = rate(np.zeros(nt))
    a = np.column_stack([rate(e) - b for e in np.eye(nt)])
    return np.linalg.solve(a, -b)


@pytest.mark.parametrize("node", ["winding", "casing"])
def test_friction_heat_at_constant_speed_settles_at_the_resistor_chain_value(elbow_file, node):
    c1, c2, v = 0.8, 0.5, -1.5
    p = _with_thermal(elbow_file, TWO_NODE | {"friction_heat_linear_w_s_per_rad": c1,
                                              "friction_heat_quadratic_w_s2_per_rad2": c2, "friction_heat_node": node})
    heat = c1 * abs(v) + c2 * v ** 2
    casing = 26.0 + 1.3 * heat
    winding = casing + (0.9 * heat if node == "winding" else 0.0)
    assert np.allclose(_model_steady_state(p, v), [winding, casing], rtol=1e-12)
    model = ActuatedArm.from_parameters(ArmSettings(), {"arm_left_4_joint": p})
    assert np.allclose(model.idle_temperatures(), 26.0)  # at rest the friction heat is off


def test_iron_loss_follows_its_speed_law_in_the_winding(elbow_file):
    p = _with_thermal(elbow_file, ONE_NODE | {"iron_loss_w": 3.0, "iron_loss_ref_speed_rad_s": 2.0,
                                              "iron_loss_speed_exponent": 1.5})
    for v in (2.0, -4.0, 0.0):
        heat = 3.0 * (abs(v) / 2.0) ** 1.5
        assert _model_steady_state(p, v)[0] == pytest.approx(26.0 + 1.8 * heat, rel=1e-12)


@pytest.mark.parametrize("sensor", ["casing", "winding"])
def test_drive_losses_without_a_drive_node_heat_the_sensor_node(elbow_file, sensor):
    p = _with_thermal(elbow_file, TWO_NODE | {"drive_idle_w": 10.0, "drive_loss_w_per_a2": 0.2, "sensor": sensor})
    net = network_from_parameters(p.thermal)
    assert net.sensor_node == sensor
    heat = 10.0 + 0.2 * 3.0 ** 2
    joule = motor.joule_w(p.motor, 3.0, 26.0)  # held as a constant power here
    t = net.steady_state({"joule_w": joule, "current_sq_a2": 9.0, "friction_w": 0.0, "speed_abs_rad_s": 0.0}, 26.0)
    casing = 26.0 + 1.3 * (heat + joule)
    assert t[1] == pytest.approx(casing, rel=1e-12)
    assert t[0] == pytest.approx(casing + 0.9 * (joule + (heat if sensor == "winding" else 0.0)), rel=1e-12)


def test_defaults_add_no_heat_source(elbow_file):
    """Absent optional keys leave today's networks as they were: Joule heat and, with a drive, its losses."""
    net = network_from_parameters(load_parameters(elbow_file).thermal)
    assert [(s.node, s.name) for s in net.sources] == [("winding", "joule_w"), ("drive", "current_sq_a2")]


def test_identification_sees_the_files_optional_heat(elbow_file):
    """A structure fitted from a file keeps its optional heat sources: the network is the planner's."""
    from thermo_ddp.identify.thermal import ThermalModel
    p = _with_thermal(elbow_file, TWO_NODE | {"friction_heat_linear_w_s_per_rad": 0.7, "friction_heat_node": "casing"})
    fit_net = ThermalModel(p, ("casing_node",)).network
    assert fit_net.sources == network_from_parameters(p.thermal).sources
    assert HeatSource("casing", "speed_abs_rad_s", 0.7, kind="friction_heating") in fit_net.sources
