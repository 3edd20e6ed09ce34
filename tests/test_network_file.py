"""The general network in the parameter file (model = "network"): the legacy models are special cases of it
(equal right-hand sides, against the hand-written equations), a numeric network is written back as a file
(round trips), a hand-built network's steady state against its closed form, the scope sections read and
written back unchanged, symbols at dotted paths."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
import tomllib

from thermo_ddp.model import motor
from thermo_ddp.model.parameters import dumps_parameters, load_parameters, packaged_parameter_file, parameters_from_dict
from thermo_ddp.model.thermal import network_from_parameters, thermal_parameters_from_network

ELBOW = load_parameters(packaged_parameter_file("arm_left_4_joint"))
TWO_NODE = {"model": "two_node", "ambient_c": 26.0, "winding_capacity_j_per_k": 40.0, "casing_capacity_j_per_k": 1200.0,
            "winding_casing_k_per_w": 0.9, "casing_ambient_k_per_w": 1.3}
# Every kind of source, shared among nodes, on a four-node stator network with a link to the room.
NETWORK = {
    "model": "network", "ambient_c": 30.0, "room_c": 21.0, "sensor": "tooth",
    "node": [{"name": "winding", "capacity_j_per_k": 1500.0}, {"name": "tooth", "capacity_j_per_k": 900.0},
             {"name": "yoke", "capacity_j_per_k": 2500.0}, {"name": "housing", "capacity_j_per_k": 4000.0}],
    "link": [{"between": ["winding", "tooth"], "resistance_k_per_w": 0.02},
             {"between": ["tooth", "yoke"], "resistance_k_per_w": 0.01},
             {"between": ["yoke", "housing"], "resistance_k_per_w": 0.015},
             {"between": ["housing", "ambient"], "resistance_k_per_w": 0.03},
             {"between": ["winding", "ambient"], "resistance_k_per_w": 0.4},
             {"between": ["housing", "room"], "resistance_k_per_w": 0.2}],
    "source": [{"kind": "copper", "split": {"winding": 1.0}},
               {"kind": "iron_losses", "split": {"tooth": 0.6, "yoke": 0.4}, "power_w": 300.0,
                "ref_speed_rad_s": 576.0, "speed_exponent": 1.6},
               {"kind": "friction_heating", "split": {"housing": 1.0}, "linear_w_s_per_rad": 0.05,
                "quadratic_w_s2_per_rad2": 1e-4, "motor_fraction": 0.5},
               {"kind": "drive_heating", "split": {"housing": 0.25, "yoke": 0.75}, "idle_w": 12.0, "loss_w_per_a2": 0.01},
               {"kind": "constant", "name": "pump", "split": {"housing": 1.0}, "power_w": 7.0},
               {"kind": "ac_copper", "split": {"winding": 1.0}, "factor": 0.4, "ref_speed_rad_s": 500.0}],
}
LEGACY = {
    "one_node": {"model": "one_node", "ambient_c": 26.0, "sensor": "winding", "capacity_j_per_k": 300.0,
                 "resistance_k_per_w": 2.0, "iron_loss_w": 3.0, "iron_loss_ref_speed_rad_s": 2.0,
                 "iron_loss_speed_exponent": 1.5, "friction_heating_fraction": 0.7, "drive_idle_w": 4.0},
    "two_node": TWO_NODE | {"friction_heat_linear_w_s_per_rad": 0.8, "friction_heat_quadratic_w_s2_per_rad2": 0.5,
                            "friction_heat_node": "casing", "friction_heating_fraction": 0.3, "drive_loss_w_per_a2": 0.2},
    "two_node_drive": ELBOW.thermal.to_dict() | {"friction_heat_linear_w_s_per_rad": 0.4, "friction_heating_fraction": 1.0},
}


def _params(thermal: dict, **sections):
    data = ELBOW.to_dict() | sections
    data["thermal"] = thermal
    return parameters_from_dict(data, "test.toml")


def _rhs(params, temps, current_a=3.0, velocity=1.7, ambient_c=26.0):
    """dT/dt of every node at a state and input, from the file's one network (motor losses included)."""
    from thermo_ddp.model.thermal import joint_heat_rhs
    net = network_from_parameters(params.thermal)
    return np.array(joint_heat_rhs(net, params.motor, temps, current_a, velocity, ambient_c), dtype=float).ravel()


def _write_back(params):
    """file -> network -> file (the network's own file), read again from its TOML text."""
    net = network_from_parameters(params.thermal)
    thermal = thermal_parameters_from_network(net, params.thermal.ambient_c)
    data = params.to_dict() | {"thermal": thermal.to_dict()}
    return parameters_from_dict(tomllib.loads(dumps_parameters(parameters_from_dict(data))), "written.toml")


@pytest.mark.parametrize("model", ["one_node", "two_node", "two_node_drive", "network"])
def test_file_network_file_network_gives_the_same_rhs(model):
    params = _params(NETWORK if model == "network" else LEGACY[model])
    again = _write_back(params)
    assert again.thermal.model == "network"
    assert network_from_parameters(again.thermal).nodes == network_from_parameters(params.thermal).nodes
    rng = np.random.default_rng(3)
    for _ in range(5):
        temps = rng.uniform(20, 120, len(network_from_parameters(params.thermal).nodes))
        i, v, amb = rng.uniform(-20, 20), rng.uniform(-600, 600), rng.uniform(10, 40)
        np.testing.assert_allclose(_rhs(again, temps, i, v, amb), _rhs(params, temps, i, v, amb), rtol=1e-12, atol=1e-15)
    twice = _write_back(again)
    assert twice.to_dict()["thermal"] == again.to_dict()["thermal"]


def test_one_node_network_is_the_hand_written_equation():
    """C dT/dt = R(T) i^2 + P_Fe (|v|/v_ref)^k + f tau_f(v) v + P_idle - (T - T_a) / R_th (seed eq. 7 + the keys)."""
    th = LEGACY["one_node"]
    params = _params(th)
    temp, i, v, amb = 61.0, 4.0, -3.0, 22.0
    heat = (motor.joule_w(params.motor, i, temp) + 3.0 * (float(motor.smooth_abs(params.motor, v)) / 2.0) ** 1.5
            + 0.7 * float(motor.friction_w(params.motor, v)) + 4.0)
    expected = (heat - (temp - amb) / 2.0) / 300.0
    assert _rhs(params, [temp], i, v, amb)[0] == pytest.approx(expected, rel=1e-12)


def test_two_node_drive_network_is_the_hand_written_equations():
    params = _params(LEGACY["two_node_drive"])
    w, c, d, i, v, amb = 70.0, 45.0, 50.0, 2.5, 0.8, 26.0
    joule = float(motor.joule_w(params.motor, i, w))
    friction = float(motor.smooth_abs(params.motor, v)) * 0.4  # the model's |v| (smooth at rest)
    casing_heat = float(motor.friction_w(params.motor, v))  # fraction 1.0 into the casing
    drive = 23.0 + 0.1 * i ** 2
    expected = [(joule + friction - (w - c) / 0.9) / 40.0,
                ((w - c) / 0.9 + casing_heat - (c - amb) / 1.3 + (d - c) / 0.6) / 1200.0,
                (drive - (d - c) / 0.6 - (d - amb) / 2.5) / 300.0]
    np.testing.assert_allclose(_rhs(params, [w, c, d], i, v, amb), expected, rtol=1e-12)


def test_steady_state_of_a_hand_built_network_is_the_resistor_network_answer():
    """Constant heat P into the tooth, Q into the winding: winding -> tooth -> yoke -> ambient and a direct
    winding -> ambient path.  Nodal analysis by hand: two equations in (T_w, T_t), T_y from the chain."""
    thermal = {"model": "network", "ambient_c": 20.0, "sensor": "winding",
               "node": [{"name": n, "capacity_j_per_k": 100.0} for n in ("winding", "tooth", "yoke")],
               "link": [{"between": ["winding", "tooth"], "resistance_k_per_w": 0.5},
                        {"between": ["tooth", "yoke"], "resistance_k_per_w": 0.25},
                        {"between": ["yoke", "ambient"], "resistance_k_per_w": 0.25},
                        {"between": ["winding", "ambient"], "resistance_k_per_w": 2.0}],
               "source": [{"kind": "constant", "split": {"tooth": 0.75, "winding": 0.25}, "power_w": 40.0}]}
    params = _params(thermal, hardware={"heat_sources": ["constant"]})
    p_tooth, p_winding = 30.0, 10.0
    # winding: (Tw - Tt)/0.5 + (Tw - 20)/2 = 10; tooth + yoke chain: (Tt - 20)/0.5 = 10 + 30 - (Tw - 20)/2
    a = np.array([[1 / 0.5 + 1 / 2.0, -1 / 0.5], [1 / 2.0, 1 / 0.5]])
    b = np.array([p_winding + 20.0 / 2.0, p_tooth + p_winding + 20.0 / 2.0 + 20.0 / 0.5])
    tw, tt = np.linalg.solve(a, b)
    ty = 20.0 + 0.25 * (tt - 20.0) / 0.5
    net = network_from_parameters(params.thermal)
    np.testing.assert_allclose(net.steady_state({}, 20.0), [tw, tt, ty], rtol=1e-12)


def test_a_symbolic_iron_exponent_has_a_finite_derivative_at_rest():
    params = _params(NETWORK)
    n = ca.SX.sym("n")
    sym = params.with_values({"thermal.source.iron_losses.speed_exponent": n})
    from thermo_ddp.model.thermal import joint_heat_rhs
    rhs = joint_heat_rhs(network_from_parameters(sym.thermal), sym.motor, np.full(4, 50.0), 10.0, 0.0, 30.0)
    grad = np.array(ca.Function("g", [n], [ca.jacobian(rhs, n)])(1.6), float)
    assert np.all(np.isfinite(grad))


def test_symbols_at_dotted_paths_differentiate_the_same_rhs():
    params = _params(NETWORK)
    paths = ("thermal.node.tooth.capacity_j_per_k", "thermal.link.tooth-winding.resistance_k_per_w",
             "thermal.source.iron_losses.speed_exponent", "thermal.source.iron_losses.split.tooth", "motor.resistance_ohm")
    p = ca.SX.sym("p", len(paths))
    sym = params.with_values(dict(zip(paths, ca.vertsplit(p))))
    from thermo_ddp.model.thermal import joint_heat_rhs
    temps = np.array([80.0, 70.0, 60.0, 50.0])
    rhs = joint_heat_rhs(network_from_parameters(sym.thermal), sym.motor, temps, 100.0, 400.0, 30.0)
    jac = ca.Function("j", [p], [ca.jacobian(rhs, p)])
    p0 = np.array([params.value(k) for k in paths])
    assert params.value("thermal.link.tooth-winding.resistance_k_per_w") == 0.02  # either order names the link
    for k, path in enumerate(paths):
        h = 1e-6 * abs(p0[k])
        hi, lo = (params.with_values({path: p0[k] + s * h}) for s in (1, -1))
        fd = (_rhs(hi, temps, 100.0, 400.0, 30.0) - _rhs(lo, temps, 100.0, 400.0, 30.0)) / (2 * h)
        np.testing.assert_allclose(np.array(jac(p0))[:, k], fd, rtol=1e-6, atol=1e-12)


SCOPE = {
    "hardware": {"heat_sources": ["copper", "iron_losses", "friction_heating", "drive_heating", "constant",
                                  "ac_copper"]},
    "uncertainty": {"thermal.node.winding.capacity_j_per_k": [1400.0, 1600.0],
                    "thermal.source.iron_losses.speed_exponent": [1.4, 1.9], "motor.resistance_ohm": [0.6, 0.8]},
    "envelope": {"current_a": [0.0, 214.0], "speed_rad_s": [0.0, 576.0], "ambient_c": [16.5, 20.6],
                 "temperature_c": [19.8, 123.0]},
    "alternatives": [{"terms": ["drive_heating"], "thermal.source.iron_losses.power_w": 0.0,
                      "thermal.source.drive_heating.idle_w": 300.0}],
}


def test_scope_sections_are_read_checked_and_written_back_unchanged():
    params = _params(NETWORK, **SCOPE)
    text = dumps_parameters(params)
    again = parameters_from_dict(tomllib.loads(text), "again.toml")
    for section, value in SCOPE.items():
        assert tomllib.loads(text)[section] == value
    assert again.to_dict() == params.to_dict()
    alt = params.alternative(0)
    assert alt.value("thermal.source.drive_heating.idle_w") == 300.0 and not alt.scope.alternatives
    assert alt.value("thermal.source.iron_losses.power_w") == 0.0
    from thermo_ddp.model.scope import Alternative
    rebuilt = _params(NETWORK).with_scope(heat_sources=tuple(SCOPE["hardware"]["heat_sources"]),
                                          uncertainty={k: tuple(v) for k, v in SCOPE["uncertainty"].items()},
                                          envelope={k: tuple(v) for k, v in SCOPE["envelope"].items()},
                                          alternatives=(Alternative(("drive_heating",), {
                                              "thermal.source.iron_losses.power_w": 0.0,
                                              "thermal.source.drive_heating.idle_w": 300.0}),))
    assert dumps_parameters(rebuilt) == text
    with pytest.raises(Exception, match="outside the interval"):
        params.with_scope(uncertainty={"motor.resistance_ohm": (0.1, 0.2)})


def test_the_packaged_paderborn_file_says_what_a_test_bench_pmsm_has():
    p = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    assert set(p.scope.heat_sources) == {"copper", "iron_losses", "friction_heating", "ac_copper"}
    assert "drive_heating" not in p.scope.allowed_sources and "heat_sources" in p.sources


@pytest.mark.parametrize("change, field, words", [
    (lambda t: t["node"][1].update(name="2tooth"), "thermal.node[1].name", "identifier"),
    (lambda t: t["node"].append({"name": "magnet", "capacity_j_per_k": 400.0}), "thermal.link", "floating"),
    (lambda t: t["link"][4].update(between=["tooth", "winding"]), "thermal.link[4].between", "linked twice"),
    (lambda t: t["source"][1]["split"].update(tooth=-0.1, yoke=1.1), "thermal.source.iron_losses.split.tooth", ">= 0"),
    (lambda t: t["source"][1]["split"].update(tooth=0.5), "thermal.source.iron_losses.split", "sum to 0.9"),
    (lambda t: t["node"].pop(0), "thermal.node", "'winding' node"),
    (lambda t: t["source"][1].update(speed_exponent=3.5), "thermal.source.iron_losses.speed_exponent", "2.5"),
    (lambda t: t.update(sensor="magnet"), "thermal.sensor", "name the node"),
    (lambda t: t["source"][4].update(kind="laser"), "thermal.source[4].kind", "expected one of"),
])
def test_bad_networks_get_one_line_naming_the_field(change, field, words):
    import copy
    thermal = copy.deepcopy(NETWORK)
    change(thermal)
    with pytest.raises(Exception) as err:
        _params(thermal)
    msg = str(err.value)
    assert type(err.value).__name__ == "InputError" and "\n" not in msg
    assert f"{field} = " in msg and words in msg and "test.toml" in msg


@pytest.mark.parametrize("scope, field, words", [
    ({"hardware": {"heat_sources": ["copper", "plasma"]}}, "hardware.heat_sources", "unknown heat source"),
    ({"hardware": {"heat_sources": ["copper", "iron_losses"]}}, "hardware.heat_sources", "friction_heating heat"),
    ({"uncertainty": {"thermal.node.rotor.capacity_j_per_k": [1.0, 2.0]}}, "uncertainty", "names no value"),
    ({"uncertainty": {"motor.resistance_ohm": [0.8, 0.9]}}, "uncertainty.motor.resistance_ohm", "outside the interval"),
    ({"envelope": {"torque_nm": [0.0, 1.0]}}, "envelope.torque_nm", "unknown quantity"),
    ({"alternatives": [{"terms": ["x"], "thermal.source.drive_heating.idle_w": -3.0}]},
     "thermal.source.drive_heating.idle_w", ">= 0"),
    ({"alternatives": [{"terms": ["x"], "thermal.node.rotor.capacity_j_per_k": 3.0}]}, "alternatives[1]", "no value"),
])
def test_bad_scope_gets_one_line_naming_the_field(scope, field, words):
    with pytest.raises(Exception) as err:
        _params(NETWORK, **scope)
    msg = str(err.value)
    assert type(err.value).__name__ == "InputError" and "\n" not in msg
    assert f"{field} = " in msg and words in msg


def test_a_legacy_file_with_heat_its_hardware_cannot_have_is_refused():
    with pytest.raises(Exception, match="drive_heating heat"):
        _params(LEGACY["one_node"] | {"friction_heating_fraction": 0.0, "iron_loss_w": 0.0},
                hardware={"heat_sources": ["copper"]})


def test_the_planners_model_is_the_same_with_the_network_form_of_the_elbow():
    """The composed arm + motor + heat ODE (what plan and MPC integrate) from the elbow's two_node_drive file
    and from that file written as model = "network": the same right-hand side."""
    from thermo_ddp.model.actuated import ActuatedArm, ArmSettings
    legacy = _params(LEGACY["two_node_drive"])
    network = _write_back(legacy)
    models = [ActuatedArm.from_parameters(ArmSettings(), {"arm_left_4_joint": p}) for p in (legacy, network)]
    assert models[0].state_names == models[1].state_names
    rng = np.random.default_rng(7)
    for _ in range(3):
        x = np.concatenate([rng.uniform(-1.5, 0.0, 1), rng.uniform(-2, 2, 1), rng.uniform(26, 90, 3)])
        u, amb = rng.uniform(-5, 5, 1), 26.0
        a, b = (np.array(m.ode(x, u, amb), float).ravel() for m in models)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)


def test_the_network_graph_draws_every_node_link_and_source(tmp_path):
    """diagnose.figure.draw_network: each node (with its capacity), each link's resistance and each source's
    share at each node it heats appear on the axes; the measured node is filled, the others are not."""
    from thermo_ddp._figures import new_figure
    from thermo_ddp.diagnose.figure import draw_network

    spec = _params(NETWORK).thermal.general
    fig, ax = new_figure(1, 1, figsize=(6, 6))
    draw_network(spec, ax, sensors=("tooth",))
    texts = " | ".join(t.get_text() for t in ax.texts)
    for node in NETWORK["node"]:
        assert f"{node['name']}\n{node['capacity_j_per_k']:.3g} J/K" in texts
    for link in NETWORK["link"]:
        assert f"{link['resistance_k_per_w']:.3g} K/W" in texts
    assert "iron_losses 60 %" in texts and "iron_losses 40 %" in texts and "pump 100 %" in texts
    assert "drive_heating 75 %" in texts and "(measured)" in texts and texts.count("(measured)") == 1
    assert "ac_copper 100 %" in texts and "room" in texts.split(" | ")
    filled = [tuple(c.get_facecolor()[0]) for c in ax.collections]
    assert sum(f[:3] == (1.0, 1.0, 1.0) for f in filled) == len(NETWORK["node"]) - 1  # unmeasured: white
    fig.savefig(tmp_path / "graph.png")
    assert (tmp_path / "graph.png").stat().st_size > 5_000


def test_a_value_the_data_do_not_pin_down_gets_no_uncertainty_interval():
    """NetworkFit.uncertainty (the file's [uncertainty], validate's band_k) holds only values the data pin down:
    a capacity whose log has a standard error of 3 (its 95 % interval would be the whole searched range) and an
    iron loss of 300 +- 400 W have none and are listed by undetermined(); a resistance known to 1 % and a share
    of 0.4 +- 0.05 have theirs."""
    from thermo_ddp.identify.network import with_values
    from thermo_ddp.identify.network_fit import Free, NetworkFit

    spec = _params(NETWORK).thermal.general
    cap, res = "thermal.node.yoke.capacity_j_per_k", "thermal.link.tooth-yoke.resistance_k_per_w"
    power, share = "thermal.source.iron_losses.power_w", "thermal.source.iron_losses.split.yoke"
    free = (Free(cap, 2.0, 1e5), Free(res, 1e-4, 100.0), Free(power, 0.0, 5000.0, log=False),
            Free(share, 0.0, 1.0, log=False))
    fit = NetworkFit(spec, "tooth", free, {cap: 3.0, res: 0.01, power: 400.0, share: 0.05}, {}, {}, {}, 1.0, True,
                     "converged")
    assert set(fit.uncertainty()) == {res, share} and set(fit.undetermined()) == {cap, power}
    lo, hi = fit.uncertainty()[res]
    assert lo == pytest.approx(0.01 / math.exp(1.959964 * 0.01)) and hi == pytest.approx(0.01 * math.exp(1.959964 * 0.01))
    assert fit.uncertainty()[share] == pytest.approx([0.4 - 1.959964 * 0.05, 0.4 + 1.959964 * 0.05])
    assert fit.undetermined()[cap] == (pytest.approx(2500.0 / math.exp(1.959964 * 3.0)), 1e5) and fit.undetermined()[power] == (0.0, pytest.approx(1084.0, abs=1))
    at_zero = NetworkFit(with_values(spec, {share: 0.0}), "tooth", free, {share: 0.05}, {}, {}, {}, 1.0, True, "converged")
    assert at_zero.uncertainty()[share] == pytest.approx([0.0, 1.959964 * 0.05])  # a share near 0, pinned down
