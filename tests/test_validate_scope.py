"""validate with several sensors and a file's scope: per-sensor errors on a synthetic three-node motor whose
truth is simulated exactly (matrix exponential), the uncertainty band against the vertices of the box, the
alternatives' predictions, the envelope; Paderborn profile 60 validated with a file identified on profile 24."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.linalg import expm

from conftest import DATA, ROOT, shared_data
from thermo_ddp.cli import main
from thermo_ddp.envelope import check_envelope, envelope_of
from thermo_ddp.model.parameters import dumps_parameters, load_parameters, packaged_parameter_file, parameters_from_dict
from thermo_ddp.recordings import Recording, read_recordings
from thermo_ddp.validate import validate_thermal

C = {"winding": 200.0, "tooth": 400.0, "yoke": 800.0}
R_WT, R_TY, R_YA, AMBIENT = 0.5, 0.3, 0.4, 25.0
R_OHM, PUMP_W = 0.2, 20.0  # copper alpha 0: the network is linear, its exact step is a matrix exponential
THERMAL = {"model": "network", "ambient_c": AMBIENT, "sensor": "winding",
           "node": [{"name": n, "capacity_j_per_k": c} for n, c in C.items()],
           "link": [{"between": ["winding", "tooth"], "resistance_k_per_w": R_WT},
                    {"between": ["tooth", "yoke"], "resistance_k_per_w": R_TY},
                    {"between": ["yoke", "ambient"], "resistance_k_per_w": R_YA}],
           "source": [{"kind": "copper", "split": {"winding": 1.0}},
                      {"kind": "constant", "split": {"tooth": 0.5, "yoke": 0.5}, "power_w": PUMP_W}]}


def _params(**scope):
    data = load_parameters(packaged_parameter_file("arm_left_4_joint")).to_dict()
    data["motor"] |= {"resistance_ohm": R_OHM, "copper_alpha_per_k": 0.0}
    data["thermal"] = THERMAL
    data["limits"] = {"winding_max_c": 180.0, "safety_cutoff_c": 150.0}
    return parameters_from_dict(data | scope, "truth.toml")


def _truth(current_a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Node temperatures (winding, tooth, yoke) by the exact zero-order-hold step of the hand-written
    network: C dT/dt = conduction + heat (written here, not with the library)."""
    g_wt, g_ty, g_ya = 1 / R_WT, 1 / R_TY, 1 / R_YA
    cap = np.array(list(C.values()))
    a = np.array([[-g_wt, g_wt, 0.0], [g_wt, -g_wt - g_ty, g_ty], [0.0, g_ty, -g_ty - g_ya]]) / cap[:, None]
    x = [np.full(3, AMBIENT)]
    for k in range(t.size - 1):
        heat = np.array([R_OHM * current_a[k] ** 2, PUMP_W / 2, PUMP_W / 2 + g_ya * AMBIENT]) / cap
        step = expm(a * (t[k + 1] - t[k]))
        x.append(step @ x[-1] + np.linalg.solve(a, (step - np.eye(3)) @ heat))
    return np.array(x)


@pytest.fixture(scope="module")
def synthetic():
    t = np.arange(0.0, 3601.0)
    current = 12.0 + 6.0 * np.sign(np.sin(2 * np.pi * t / 900.0))
    return t, current, _truth(current, t)


def _recording(synthetic, tooth_bias=0.0, **extra):
    t, current, x = synthetic
    return Recording("synthetic", t, current_a=current, temperature_c=x[:, 0], ambient_c=np.full_like(t, AMBIENT),
                     sensors={"tooth": x[:, 1] + tooth_bias, "yoke": x[:, 2], **extra})


def test_per_sensor_errors_against_a_known_truth(synthetic):
    t = synthetic[0]
    assert synthetic[2][:, 0].max() > AMBIENT + 40  # the motor really heats
    exact = validate_thermal([_recording(synthetic, magnet=np.full_like(t, 30.0))], _params())
    assert set(exact.per_sensor) == {"winding", "tooth", "yoke"}  # the magnet is no node of this network
    assert max(v["rmse"] for v in exact.per_sensor.values()) < 5e-4  # trapezoid on 1 s steps, tau >= 100 s
    bias = 0.3 * np.sin(2 * np.pi * t / 600.0)  # a sensor error known exactly: rmse 0.3 sqrt(mean sin^2)
    biased = validate_thermal([_recording(synthetic, tooth_bias=bias)], _params())
    assert biased.per_sensor["tooth"]["rmse"] == pytest.approx(np.sqrt(np.mean(bias ** 2)), abs=2e-3)
    assert biased.per_sensor["winding"]["rmse"] < 2e-3 and biased.per_sensor["yoke"]["rmse"] < 2e-3
    assert biased.to_dict()["per_sensor"]["tooth"]["rmse"] == biased.per_sensor["tooth"]["rmse"]


def test_the_band_combines_each_values_exact_spread_in_quadrature(synthetic):
    """Narrow intervals (+-2 %): the first-order band equals, to second order, the quadrature sum of each
    value's own spread (each moved alone to its bounds, simulated exactly), and lies between the largest
    single spread and the spread over the box's vertices (every value at a bound at once)."""
    paths = {"thermal.node.tooth.capacity_j_per_k": C["tooth"], "thermal.link.yoke-ambient.resistance_k_per_w": R_YA,
             "motor.resistance_ohm": R_OHM}
    box = {k: [0.98 * v, 1.02 * v] for k, v in paths.items()}
    rec = _recording(synthetic)
    result = validate_thermal([rec], _params(uncertainty=box))
    base = _params()

    def run(values):
        return validate_thermal([rec], base.with_values(values).checked()).predictions[0].predicted_c
    nominal = run({})
    shifts = np.array([[run({k: box[k][j]}) - nominal for j in (0, 1)] for k in box])  # values x bound x samples
    up = np.sqrt(np.sum(np.maximum(shifts.max(axis=1), 0) ** 2, axis=0))
    down = np.sqrt(np.sum(np.minimum(shifts.min(axis=1), 0) ** 2, axis=0))
    quadrature = float(np.max(up + down))
    corners = [dict(zip(box, (box[k][(n >> j) & 1] for j, k in enumerate(box)))) for n in range(2 ** len(box))]
    runs = np.array([run(c) for c in corners])
    vertices = float(np.max(runs.max(axis=0) - runs.min(axis=0)))
    single = float(np.max(np.abs(shifts[:, 1] - shifts[:, 0])))
    assert single > 0.5 and vertices > quadrature * 1.2  # three values that matter: the corner is wider
    assert result.band_k == pytest.approx(quadrature, rel=2e-3)
    assert single < result.band_k < vertices


def test_alternatives_are_predicted_and_widen_the_band(synthetic):
    alt = {"terms": ["drive_heating"], "thermal.source.constant.power_w": 0.0,
           "thermal.source.drive_heating.idle_w": 20.0, "thermal.source.drive_heating.split.yoke": 1.0}
    params = _params(alternatives=[alt])
    rec = _recording(synthetic)
    result = validate_thermal([rec], params)
    own = validate_thermal([rec], params.alternative(0))
    assert result.to_dict()["alternatives"] == [{"terms": ["drive_heating"], "rmse": own.rmse}]
    assert own.rmse > 0.05  # the truth is the file's own explanation: the alternative predicts worse
    gap = np.max(np.abs(own.predictions[0].predicted_c - result.predictions[0].predicted_c))
    assert result.band_k == pytest.approx(gap, rel=1e-9)


def test_envelope_of_and_its_check(synthetic):
    rec = _recording(synthetic)
    env = envelope_of([rec])
    assert env["current_a"] == (6.0, 18.0) and env["ambient_c"] == (AMBIENT, AMBIENT) and "speed_rad_s" not in env
    assert env["temperature_c"] == (AMBIENT, float(synthetic[2][:, 0].max()))
    assert not check_envelope(env, [rec]).outside
    hot = dataclasses.replace(rec, current_a=2 * rec.current_a)
    check = check_envelope(env, [hot])
    assert check.outside and "current_a" in check.message and "18 A above" in check.message
    assert [q.name for q in check.quantities if q.outside] == ["current_a"]


def test_cli_validate_reports_scope_keys_and_says_when_outside(tmp_path, synthetic, capsys):
    rec = _recording(synthetic)
    csv = rec.to_csv(tmp_path / "rec.csv")
    env = {k: list(v) for k, v in envelope_of([rec]).items()} | {"current_a": [0.0, 10.0]}
    model = tmp_path / "m.toml"
    model.write_text(dumps_parameters(_params(envelope=env)))
    out = tmp_path / "v.json"
    assert main(["validate", str(csv), "--model", str(model), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert {"per_sensor", "envelope", "alternatives", "band_k"} <= set(d)
    assert d["envelope"]["outside"] and d["envelope"]["quantities"]["current_a"]["here"] == [6.0, 18.0]
    assert set(d["per_sensor"]) == {"winding", "tooth", "yoke"} and d["band_k"] == 0.0
    assert d["envelope"]["known"] and not validate_thermal([rec], _params()).to_dict()["envelope"]["known"]
    assert "used where it was never identified: current_a" in capsys.readouterr().out
    unc = {"uncertainty": {"motor.resistance_ohm": [0.98 * R_OHM, 1.02 * R_OHM]}}
    own = {k: list(v) for k, v in envelope_of([rec]).items()}
    outside, inside = (validate_thermal([rec], _params(envelope=e, **unc)) for e in (env, own))
    assert outside.band_k > 0 and outside.band_k == pytest.approx(inside.band_k)
    assert "outside the envelope: the values" in outside.report() and "outside the envelope" not in inside.report()


def test_paderborn_profile_60_lies_outside_a_file_identified_on_profile_24(tmp_path):
    """Data README: profile 24 runs at 5,500 rpm with coolant 16.5-20.6 °C and |i_dq| up to 214 A; profile
    60 has its coolant step to about 70 °C and |i_dq| up to about 300 A."""
    p60 = shared_data("paderborn/profile_60_first50min.csv")
    maps = ROOT / "examples" / "columns"
    p24 = read_recordings([DATA / "paderborn" / "profile_24.csv"], maps / "paderborn_profile_24.toml").recordings
    model = tmp_path / "from_24.toml"
    env = {k: list(v) for k, v in envelope_of(p24).items()}
    data = load_parameters(packaged_parameter_file("paderborn_pmsm")).to_dict() | {"envelope": env}
    model.write_text(dumps_parameters(parameters_from_dict(data)))
    out = tmp_path / "v.json"
    assert main(["validate", str(p60), "--columns", str(maps / "paderborn_profile_60.toml"), "--model", str(model),
                 "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    q = d["envelope"]["quantities"]
    assert d["envelope"]["outside"] and q["ambient_c"]["outside"] and q["current_a"]["outside"]
    assert q["ambient_c"]["above_by"] > 45.0 and q["current_a"]["above_by"] > 60.0
    # the room (the CSV's ambient column, room_c in the maps): 18.4-26.3 °C in profile 24, down to 15.4 °C in 60
    assert q["room_c"]["outside"] and q["room_c"]["below_by"] == pytest.approx(3.0, abs=0.1)
    assert "ambient_c" in d["message"] and "never identified" in d["message"]
    assert set(d["per_sensor"]) == {"winding"}  # a one-node file: tooth and yoke are no nodes of it


def test_the_plot_draws_every_measured_node(tmp_path, synthetic):
    result = validate_thermal([_recording(synthetic)], _params())
    fig = result.plot(tmp_path / "v.png")
    assert fig.stat().st_size > 10_000
