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
