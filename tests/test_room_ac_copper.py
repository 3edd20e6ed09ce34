"""Two terms the Paderborn profiles asked for (issue 24): a link to a second boundary, the room
(``room_link``: ``[[thermal.link]] between = [node, "room"]``, the room's temperature from a recording's
``room_c`` or the file's ``[thermal] room_c``), and the AC copper loss ``ac_copper`` k R(T_w) i^2 (|w| / w_ref)^2.
Oracles: the hand-written equations, finite differences, the resistor-network answer, and a truth integrated
exactly (matrix exponential, numpy) whose known values identification recovers and whose terms the growth adds."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from thermo_ddp.model import motor
from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file, parameters_from_dict
from thermo_ddp.model.thermal import joint_heat_rhs, network_from_parameters

PMSM = load_parameters(packaged_parameter_file("paderborn_pmsm"))
TRUTH = {"winding": 2000.0, "yoke": 6000.0, "winding-yoke": 0.02, "yoke-ambient": 0.03, "yoke-room": 0.1,
         "factor": 0.5, "ref_speed": 500.0}


def _thermal(room_c: float | None = 22.0, **truth) -> dict:
    t = TRUTH | truth
    out = {"model": "network", "ambient_c": 25.0, "sensor": "winding",
           "node": [{"name": "winding", "capacity_j_per_k": t["winding"]}, {"name": "yoke", "capacity_j_per_k": t["yoke"]}],
           "link": [{"between": ["winding", "yoke"], "resistance_k_per_w": t["winding-yoke"]},
                    {"between": ["yoke", "ambient"], "resistance_k_per_w": t["yoke-ambient"]},
                    {"between": ["yoke", "room"], "resistance_k_per_w": t["yoke-room"]}],
           "source": [{"kind": "copper", "split": {"winding": 1.0}},
                      {"kind": "ac_copper", "split": {"winding": 1.0}, "factor": t["factor"],
                       "ref_speed_rad_s": t["ref_speed"]}]}
    return out | ({"room_c": room_c} if room_c is not None else {})


def _params(thermal: dict):
    return parameters_from_dict(PMSM.to_dict() | {"thermal": thermal}, "test.toml")


def test_room_link_and_ac_copper_are_the_hand_written_equations():
    params = _params(_thermal())
    net = network_from_parameters(params.thermal)
    tw, ty, i, v, amb = 95.0, 60.0, 180.0, 420.0, 40.0
    r = float(motor.resistance_ohm(params.motor, tw))
    heat_w = r * i ** 2 * (1 + 0.5 * (v / 500.0) ** 2)
    for room, room_used in ((None, 22.0), (30.0, 30.0)):  # the file's room_c, or the one given
        out = np.array(joint_heat_rhs(net, params.motor, [tw, ty], i, v, amb, room_c=room), float).ravel()
        expected = [(heat_w - (tw - ty) / 0.02) / 2000.0,
                    ((tw - ty) / 0.02 - (ty - amb) / 0.03 - (ty - room_used) / 0.1) / 6000.0]
        np.testing.assert_allclose(out, expected, rtol=1e-12)
    # without [thermal] room_c the room is at the ambient's temperature
    bare = network_from_parameters(_params(_thermal(room_c=None)).thermal)
    out = np.array(joint_heat_rhs(bare, params.motor, [tw, ty], 0.0, 0.0, amb), float).ravel()
    assert out[1] == pytest.approx(((tw - ty) / 0.02 - (ty - amb) / 0.03 - (ty - amb) / 0.1) / 6000.0, rel=1e-12)


def test_ac_copper_derivatives_match_finite_differences():
    params = _params(_thermal())
    net = network_from_parameters(params.thermal)
    x = ca.SX.sym("x", 5)  # winding, yoke, current, velocity, room
    f = ca.Function("f", [x], [joint_heat_rhs(net, params.motor, x[:2], x[2], x[3], 35.0, room_c=x[4])])
    jac = ca.Function("j", [x], [ca.jacobian(f(x), x)])
    point = np.array([90.0, 55.0, 150.0, -310.0, 24.0])
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-3])
    fd = np.column_stack([(np.array(f(point + h * e)) - np.array(f(point - h * e))).ravel() / (2 * h)
                          for h, e in zip(steps, np.eye(5))])
    np.testing.assert_allclose(np.array(jac(point)), fd, rtol=1e-6, atol=1e-10)


def test_two_boundaries_steady_state_is_the_resistor_answer():
    """Only constant heat: the yoke sees the coolant and the room in parallel; the winding sits P R above it."""
    thermal = _thermal() | {"source": [{"kind": "constant", "split": {"winding": 1.0}, "power_w": 500.0}]}
    data = PMSM.to_dict() | {"thermal": thermal, "hardware": {"heat_sources": ["constant"]}}
    net = network_from_parameters(parameters_from_dict(data, "test.toml").thermal)
    amb, room, g_a, g_r = 40.0, 22.0, 1 / 0.03, 1 / 0.1
    ty = (500.0 + g_a * amb + g_r * room) / (g_a + g_r)
    np.testing.assert_allclose(net.steady_state({}, amb), [ty + 500.0 * 0.02, ty], rtol=1e-12)


@pytest.mark.parametrize("change, field, words", [
    (lambda t: t["link"][2].update(between=["room", "yoke"]), "thermal.link[2].between", "two different nodes"),
    (lambda t: t["node"][1].update(name="room"), "thermal.node[1].name", "other than"),
    (lambda t: t["source"][1].update(factor=-0.2), "thermal.source.ac_copper.factor", ">= 0"),
    (lambda t: t["source"][1].update(factor=12.0), "thermal.source.ac_copper.factor", "expected 0 to 10"),
    (lambda t: t.update(room_c=95.0), "thermal.room_c", "-50 to 80"),
])
def test_bad_room_and_ac_copper_get_one_line_naming_the_field(change, field, words):
    thermal = _thermal()
    change(thermal)
    with pytest.raises(Exception) as err:
        _params(thermal)
    msg = str(err.value)
    assert type(err.value).__name__ == "InputError" and "\n" not in msg
    assert f"{field} = " in msg and words in msg, msg


def _truth_recording(seed: int = 5):
    """Three hours at 10 s: current, speed and room steps every 2 min, the coolant stepping 25 -> 60 °C halfway;
    winding and yoke measured with 0.05 K noise.  Integrated exactly (the network is affine in T over each held
    block: R(T) is linear) by the matrix exponential, numpy only."""
    from thermo_ddp.recordings import Recording

    rng = np.random.default_rng(seed)
    dt, n, block = 10.0, 1080, 12
    steps = lambda x: np.repeat(x, block)  # noqa: E731
    current = steps(rng.choice([40.0, 120.0, 200.0, 260.0], n // block))
    speed = steps(rng.choice([0.0, 150.0, 300.0, 450.0, 600.0], n // block))
    coolant = steps(np.where(np.arange(n // block) < n // block // 2, 25.0, 60.0))
    room = steps(22.0 + rng.uniform(-1.5, 1.5, n // block))
    m, t = PMSM.motor, TRUTH
    c = np.array([t["winding"], t["yoke"]])
    r1 = m.resistance_ohm * m.copper_alpha_per_k  # R(T) = r0 + r1 T
    r0 = m.resistance_ohm * (1 - m.copper_alpha_per_k * m.resistance_ref_c)
    g_wy, g_ya, g_yr = 1 / t["winding-yoke"], 1 / t["yoke-ambient"], 1 / t["yoke-room"]
    temps = np.empty((n, 2))
    x = np.array([30.0, 28.0])
    for k0 in range(0, n, block):
        heat = current[k0] ** 2 * (1 + t["factor"] * (speed[k0] / t["ref_speed"]) ** 2)  # x R(T)
        aug = np.zeros((3, 3))
        aug[:2, :2] = np.array([[-g_wy + r1 * heat, g_wy], [g_wy, -g_wy - g_ya - g_yr]]) / c[:, None]
        aug[:2, 2] = np.array([r0 * heat, g_ya * coolant[k0] + g_yr * room[k0]]) / c
        step = expm(aug * dt)
        for k in range(k0, k0 + block):
            temps[k] = x
            x = (step @ np.r_[x, 1.0])[:2]
    noisy = temps + rng.normal(0.0, 0.05, temps.shape)
    return Recording("truth", np.arange(n) * dt, current_a=current, temperature_c=noisy[:, 0], velocity=speed,
                     ambient_c=coolant, room_c=room, sensors={"yoke": noisy[:, 1]})


@pytest.fixture(scope="module")
def truth_grid():
    from thermo_ddp.identify.thermal_data import ThermalSettings, thermal_grid
    return thermal_grid(_truth_recording(), PMSM, ThermalSettings(min_step_s=10.0, max_step_s=10.0))


def test_identification_recovers_a_known_room_link_and_ac_copper(truth_grid):
    from thermo_ddp.diagnose.growth import Ranges
    from thermo_ddp.identify.network import free_paths
    from thermo_ddp.identify.network_fit import fit_network

    start = _params(_thermal(**{"winding": 2800.0, "yoke": 4500.0, "winding-yoke": 0.026, "yoke-ambient": 0.022,
                                "yoke-room": 0.16, "factor": 0.2})).thermal.general
    ranges = Ranges((1.0, 1e6), 1e4, PMSM.motor.current_nominal_a)
    fit = fit_network(PMSM, start, "winding", tuple(ranges.free(p) for p in free_paths(start)), [truth_grid])
    assert fit.success, fit.message
    expected = {"thermal.node.winding.capacity_j_per_k": 2000.0, "thermal.node.yoke.capacity_j_per_k": 6000.0,
                "thermal.link.winding-yoke.resistance_k_per_w": 0.02,
                "thermal.link.yoke-ambient.resistance_k_per_w": 0.03,
                "thermal.link.yoke-room.resistance_k_per_w": 0.1, "thermal.source.ac_copper.factor": 0.5}
    for path, value in expected.items():
        assert fit.values[path] == pytest.approx(value, rel=0.03), path
        lo, hi = fit.interval(path)
        assert lo < fit.values[path] < hi
    assert all(r < 1.3 * 0.05 for r in fit.per_sensor().values()), fit.per_sensor()


def test_growth_offers_a_room_link_only_with_a_room_and_ac_copper_where_the_copper_is():
    from thermo_ddp.diagnose.growth import additions

    spec = _params(_thermal()).thermal.general
    bare = spec.with_values({}).__class__(spec.nodes, spec.links[:2], spec.sources[:1])  # no room link, copper only
    offered = {(a.term, a.where) for a in additions(bare, ("copper", "ac_copper"), 100.0, 500.0, room=True)}
    assert {("room_link", "winding"), ("room_link", "yoke"), ("ac_copper", "winding")} <= offered
    assert not {t for t, w in offered if t == "ac_copper" and w != "winding"}  # never where there is no copper
    without_room = {a.term for a in additions(bare, ("copper", "ac_copper"), 100.0, 500.0, room=False)}
    assert "room_link" not in without_room
    assert "ac_copper" not in {a.term for a in additions(bare, ("copper",), 100.0, 500.0, room=True)}


def test_growth_adds_the_room_link_and_ac_copper_the_truth_has(truth_grid):
    """From the truth's two nodes without its room link and AC copper loss, the growth adds both (each by the
    nested test) and ends within the sensors' noise."""
    from thermo_ddp.diagnose.network_diagnosis import diagnose_network

    thermal = _thermal()
    thermal["link"], thermal["source"] = thermal["link"][:2], thermal["source"][:1]
    data = PMSM.to_dict() | {"thermal": thermal, "hardware": {"heat_sources": ["copper", "iron_losses", "ac_copper"]}}
    d = diagnose_network(parameters_from_dict(data, "test.toml"), [truth_grid], progress=False)
    assert {s.addition.term for s in d.steps} == {"room_link", "ac_copper"}, [s.addition.label for s in d.steps]
    assert d.status == "ok" and all(r < 1.3 * 0.05 for r in d.final.per_sensor().values())
    ac = next(s for s in d.final.spec.sources if s.kind == "ac_copper")  # w_ref: the 95th percentile speed
    assert ac["factor"] * (TRUTH["ref_speed"] / ac["ref_speed_rad_s"]) ** 2 == pytest.approx(0.5, rel=0.05)
    assert d.network_section()["room_c"] == pytest.approx(22.0, abs=1.0)  # the recording's mean room
