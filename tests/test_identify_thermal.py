"""Thermal identification against oracles: known parameters of the simulated elbow (testbed, its own
scipy integration), the closed-form first-order response of eq. (8), finite differences."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import curve_fit

from thermo_ddp.errors import InputError
from thermo_ddp.identify.thermal_files import identify_thermal_files
from thermo_ddp.identify.thermal import (ThermalModel, ThermalSettings, identify_thermal,
                                         load_joint_parameters, thermal_grid)
from thermo_ddp.model.parameters import parameters_from_dict
from thermo_ddp.recordings import Recording
from thermo_ddp.testing.testbed import Ambient, PlantParameters, SensorSettings, static_3a, static_4a, static_hold
from thermo_ddp.model.thermal import one_node_response

# winding glued to the casing: the plant is a one-node network (testbed's own oracle test uses 1e-4)
ONE_NODE_PLANT = PlantParameters(winding_casing_k_per_w=1e-3, friction_heating=False, drive_heating=False)
ELBOW = load_joint_parameters(None)


def _randomised(seed: int, **changes) -> PlantParameters:
    return dataclasses.replace(PlantParameters().randomised(np.random.default_rng(seed)), **changes)


def test_one_node_recovers_known_capacity_and_resistance():
    plant = dataclasses.replace(_randomised(1), winding_casing_k_per_w=1e-3, friction_heating=False,
                                drive_heating=False)
    rec = static_4a(params=plant, heating_s=3600.0, cooling_s=3600.0, seed=3).to_recording()
    fit = identify_thermal(rec, "one_node")
    assert fit.success, fit.message
    cap = plant.casing_capacity_j_per_k + plant.winding_capacity_j_per_k
    res = plant.casing_ambient_k_per_w + plant.winding_casing_k_per_w
    assert fit.parameters["capacity_j_per_k"] == pytest.approx(cap, rel=0.02)
    assert fit.parameters["resistance_k_per_w"] == pytest.approx(res, rel=0.01)
    assert fit.rmse < 0.13  # sensor noise 0.1 degC and 0.1 degC quantisation
    lo, hi = fit.confidence["capacity_j_per_k"]
    assert lo < fit.parameters["capacity_j_per_k"] < hi and hi - lo < 0.1 * cap
    assert "inflated" in fit.fit_report()


def test_constant_current_step_matches_eq8_first_order_response():
    """A 5 A step from room temperature: an exponential K (1 - exp(-t / tau)) fitted to the data
    (independent of the package's model) equals eq. (8) evaluated at the identified C and R_th."""
    current = 5.0
    room = Ambient(room_c=ONE_NODE_PLANT.resistance_ref_c)
    rec = static_hold(current, payload_kg=20.0, heating_s=6000.0, start="cold", params=ONE_NODE_PLANT, ambient=room,
                      sensors=SensorSettings(temperature_quantum_c=0.0), seed=2).to_recording()
    fit = identify_thermal(rec, "one_node")
    m = ELBOW.motor
    eq8 = one_node_response(m.resistance_ohm, m.resistance_ref_c, m.copper_alpha_per_k, fit.parameters["capacity_j_per_k"],
                            fit.parameters["resistance_k_per_w"], room.room_c, current)
    rise = rec.temperature_c - room.room_c
    (gain, tau), _ = curve_fit(lambda t, k, tc: k * (1 - np.exp(-t / tc)), rec.time_s, rise, p0=(30.0, 3000.0))
    assert eq8.gain_k == pytest.approx(gain, rel=0.01)
    assert eq8.time_constant_s == pytest.approx(tau, rel=0.02)
    truth = one_node_response(m.resistance_ohm, m.resistance_ref_c, m.copper_alpha_per_k,
                              ONE_NODE_PLANT.casing_capacity_j_per_k + ONE_NODE_PLANT.winding_capacity_j_per_k,
                              ONE_NODE_PLANT.casing_ambient_k_per_w + ONE_NODE_PLANT.winding_casing_k_per_w,
                              room.room_c, current)
    assert eq8.time_constant_s == pytest.approx(truth.time_constant_s, rel=0.02)


def test_two_node_recovers_known_parameters_from_a_randomised_plant():
    plant = _randomised(4, friction_heating=False, drive_heating=False)
    rec = static_4a(params=plant, heating_s=5400.0, cooling_s=3600.0, seed=5).to_recording()
    fit = identify_thermal(rec, "two_node")
    assert fit.success, fit.message
    assert fit.parameters["casing_capacity_j_per_k"] == pytest.approx(plant.casing_capacity_j_per_k, rel=0.03)
    assert fit.parameters["casing_ambient_k_per_w"] == pytest.approx(plant.casing_ambient_k_per_w, rel=0.02)
    assert fit.parameters["winding_casing_k_per_w"] == pytest.approx(plant.winding_casing_k_per_w, rel=0.15)
    assert fit.parameters["winding_capacity_j_per_k"] == pytest.approx(plant.winding_capacity_j_per_k, rel=0.35)


def test_two_node_drive_recovers_idle_heat_and_casing_from_two_recordings():
    """The drive's ambient path and i^2 loss are held at the file's values (not identifiable from
    the casing sensor alone); the plant uses those, the rest is randomised."""
    plant = _randomised(6, friction_heating=False, drive_ambient_k_per_w=ELBOW.thermal["drive_ambient_k_per_w"],
                        drive_loss_w_per_a2=ELBOW.thermal["drive_loss_w_per_a2"])
    recs = [static_4a(params=plant, heating_s=3600.0, cooling_s=3600.0, seed=7).to_recording(),
            static_3a(params=plant, heating_s=3600.0, cooling_s=3600.0, seed=8).to_recording()]
    fit = identify_thermal(recs, "two_node_drive", settings=ThermalSettings(min_step_s=5.0, max_step_s=5.0))
    assert fit.success, fit.message
    assert fit.rmse < 0.13
    assert fit.parameters["drive_idle_w"] == pytest.approx(plant.drive_idle_w, rel=0.15)
    assert fit.parameters["casing_capacity_j_per_k"] == pytest.approx(plant.casing_capacity_j_per_k, rel=0.10)
    assert fit.parameters["casing_ambient_k_per_w"] == pytest.approx(plant.casing_ambient_k_per_w, rel=0.10)
    assert fit.parameters["drive_ambient_k_per_w"] == ELBOW.thermal["drive_ambient_k_per_w"]
    assert "drive_ambient_k_per_w" not in fit.stderr


def test_multi_recording_fit_shares_parameters_and_keeps_initial_states_apart():
    plant = dataclasses.replace(ONE_NODE_PLANT, casing_capacity_j_per_k=1000.0)
    warm = static_4a(params=plant, heating_s=2400.0, cooling_s=2400.0, seed=9).to_recording()
    cold = dataclasses.replace(static_3a(params=plant, heating_s=2400.0, cooling_s=2400.0, seed=10, start="cold",
                                         ambient=Ambient(room_c=22.0)).to_recording(), name="cold")
    both = identify_thermal([warm, cold], "one_node")
    alone = identify_thermal(warm, "one_node")
    assert both.recordings == ("static_4a", "cold") and both.n_samples == len(warm) + len(cold)
    assert both.parameters["capacity_j_per_k"] == pytest.approx(1000.0 + plant.winding_capacity_j_per_k, rel=0.02)
    assert both.stderr["capacity_j_per_k"] < alone.stderr["capacity_j_per_k"]
    assert both.fitted[both.rows("cold")][0] == pytest.approx(22.0, abs=0.3)
    assert both.fitted[both.rows("static_4a")][0] == pytest.approx(warm.temperature_c[0], abs=0.3)


def test_simulation_on_an_irregular_grid_with_gaps_matches_the_testbed_truth():
    """True parameters through the CasADi model (zero-order hold, trapezoidal sub-steps) against
    the testbed's scipy integration, on jittered 0.3 Hz samples with gaps."""
    plant = PlantParameters(friction_heating=False, drive_heating=False)
    sensors = SensorSettings(sample_rate_hz=0.3, jitter_fraction=0.3, gap_count=3).noiseless()
    rec = static_4a(params=plant, heating_s=3600.0, cooling_s=3600.0, sensors=sensors, seed=11)
    grid = thermal_grid(rec.to_recording(), ELBOW)
    model = ThermalModel(ELBOW, ("casing_node",))
    values = [getattr(plant, k) for k in model.keys]
    temps, sensor, *_ = model.simulate(grid, values, 0.0)
    assert np.max(np.abs(np.diff(grid.time_s))) > 25.0  # there is a gap
    np.testing.assert_allclose(sensor, rec.truth.casing_c, atol=0.03)
    # the fast winding node lags by up to one 3.3 s hold while the current ramps (zero-order hold)
    np.testing.assert_allclose(temps[0], rec.truth.winding_c, atol=0.7)
    assert np.median(np.abs(temps[0] - rec.truth.winding_c)) < 0.02


def test_sensitivities_match_finite_differences():
    plant = PlantParameters()
    rec = static_4a(params=plant, heating_s=1200.0, cooling_s=600.0, sample_rate_hz=0.5, seed=12).to_recording()
    grid = thermal_grid(rec, ELBOW)
    model = ThermalModel(ELBOW, ("casing_node", "drive_heating", "friction_heating", "copper_resistance"))
    values = np.array([{"friction_heat_linear_w_s_per_rad": 1.5, "friction_heat_quadratic_w_s2_per_rad2": 0.4,
                        "copper_alpha_per_k": 0.004}.get(k, 0.0) or ELBOW.thermal[k] for k in model.keys])
    _, _, jac, jac_winding = model.simulate(grid, values, 0.3)
    for j in range(len(values) + 1):
        # the heat is linear in the friction coefficients: a large step is exact and keeps roundoff out of
        # their tiny sensitivities in a static hold
        linear = j < len(values) and model.keys[j].startswith("friction_heat")
        step = (0.1 if linear else 1e-4 * abs(values[j])) if j < len(values) else 1e-3
        up, down = values.copy(), values.copy()
        if j < len(values):
            up[j] += step
            down[j] -= step
        sim_up = model.simulate(grid, up, 0.3 + (step if j == len(values) else 0.0))
        sim_down = model.simulate(grid, down, 0.3 - (step if j == len(values) else 0.0))
        for analytic, fd in ((jac, (sim_up[1] - sim_down[1]) / (2 * step)),   # sensor (casing)
                             (jac_winding, (sim_up[0][model.winding] - sim_down[0][model.winding]) / (2 * step))):
            np.testing.assert_allclose(analytic[:, j], fd, rtol=1e-4, atol=1e-7 * np.abs(analytic[:, j]).max())


@pytest.mark.parametrize("missing", ["current_a", "temperature_c"])
def test_recording_without_current_or_temperature_is_an_input_error(missing):
    t = np.arange(100.0)
    columns = {"current_a": np.ones_like(t), "temperature_c": np.full_like(t, 30.0)}
    del columns[missing]
    with pytest.raises(InputError, match=missing):
        identify_thermal(Recording(name="bad", time_s=t, **columns))


def test_csv_entry_point_returns_a_loadable_parameter_file(tmp_path):
    rec = static_4a(params=ONE_NODE_PLANT, heating_s=1800.0, cooling_s=1800.0, seed=13)
    path = rec.to_csv(tmp_path / "hold.csv")
    out = identify_thermal_files([path], "one_node")
    assert out["success"] and out["physics"] == "thermal" and out["recordings"] == ["hold.csv"]
    loaded = parameters_from_dict(out["parameter_file"])
    assert loaded.thermal.model == "one_node"
    assert loaded.thermal["capacity_j_per_k"] == out["parameters"]["capacity_j_per_k"]
    # the file says how well each value is known and where it was identified
    lo, hi = loaded.scope.uncertainty["thermal.capacity_j_per_k"]
    assert lo < loaded.thermal["capacity_j_per_k"] < hi
    assert set(loaded.scope.uncertainty) == {"thermal.capacity_j_per_k", "thermal.resistance_k_per_w"}
    cov = loaded.scope.covariance  # log values: each interval is the value x exp(+-1.96 sigma), as the fit's errors
    for k, var in zip(cov.paths, np.diag(cov.array)):
        lo, hi = loaded.scope.uncertainty[k]
        assert np.log(hi / lo) == pytest.approx(2 * 1.959964 * np.sqrt(var), rel=1e-6)
    rho = cov.array[0, 1] / np.sqrt(cov.array[0, 0] * cov.array[1, 1])
    assert -1 < rho < 1
    fixed = loaded.replace("thermal", capacity_j_per_k=1.1 * loaded.thermal["capacity_j_per_k"])  # now as written:
    r = cov.paths.index("thermal.resistance_k_per_w")  # the resistance's variance given it
    assert fixed.scope.covariance.paths == ("thermal.resistance_k_per_w",)
    assert fixed.scope.covariance.array[0, 0] == pytest.approx(cov.array[r, r] * (1 - rho ** 2))
    assert loaded.scope.envelope["current_a"][1] == pytest.approx(np.abs(rec.to_recording().current_a).max())
    bad = tmp_path / "no_temp.csv"
    rec.to_csv(bad, columns=("time_s", "current_a"))
    with pytest.raises(InputError, match="temperature_c"):
        identify_thermal_files([bad])


def test_voltage_thermometry_pins_the_winding_node_down():
    """Known parameters (two-node plant, nothing concealed): with the motor voltage as a winding
    thermometer the winding capacity and resistance come out closer to the truth and with smaller
    standard errors than from the casing sensor alone; a one-node model ignores the voltage."""
    from thermo_ddp.testing.testbed import LOGGED_COLUMNS, winding_pulses
    plant = PlantParameters(friction_heating=False, drive_heating=False)
    recs = [static_4a(params=plant, heating_s=1800.0, cooling_s=1800.0, seed=21), winding_pulses(params=plant, seed=22)]
    casing = identify_thermal([r.to_recording() for r in recs], "two_node")
    both = identify_thermal([r.to_recording(LOGGED_COLUMNS) for r in recs], "two_node")
    assert casing.success and both.success
    for key, rel in (("winding_capacity_j_per_k", 0.06), ("winding_casing_k_per_w", 0.03)):
        true = getattr(plant, key)
        assert both.parameters[key] == pytest.approx(true, rel=rel)
        assert abs(both.parameters[key] - true) <= 3 * both.stderr[key]
        assert both.stderr[key] < 0.7 * casing.stderr[key]
    assert "winding resistance thermometry from voltage_v" in both.fit_report()
    one = identify_thermal([r.to_recording(LOGGED_COLUMNS) for r in recs], "one_node")
    assert not any("thermometry" in n for n in one.notes)


def test_thermometry_uses_only_loaded_and_still_samples():
    from thermo_ddp.testing.testbed import LOGGED_COLUMNS, biceps
    rec = biceps(heating_s=600.0, cooling_s=600.0, seed=3).to_recording(LOGGED_COLUMNS)
    grid = thermal_grid(rec, ELBOW)
    used = grid.winding_weight > 0
    assert 0 < used.sum() < 0.2 * len(grid)          # the curl moves: only the grasp and holds qualify
    assert np.all(np.abs(grid.current_a[used]) >= 1.0) and np.all(np.abs(grid.velocity[used]) <= 0.05)
    assert np.all(np.isnan(grid.winding_c[~used]))
    off = thermal_grid(rec, ELBOW, ThermalSettings(voltage_thermometry=False))
    assert off.winding_c is None and off.thermometry_samples == 0


def test_iron_losses_are_written_as_the_contract_iron_loss_the_planner_uses():
    """The fitted k v^2 becomes iron_loss_w = k at 1 rad/s, exponent 2: the planner's network then injects
    exactly k v^2 in the winding (and the identification's structure is that network)."""
    from types import SimpleNamespace

    from thermo_ddp.identify.thermal import IRON_KEY, parameter_file
    from thermo_ddp.model.thermal import network_from_parameters
    model = ThermalModel(ELBOW, ("casing_node", "iron_losses"))
    values = {k: ELBOW.thermal[k] for k in model.keys if k != IRON_KEY} | {IRON_KEY: 0.03}
    fit = SimpleNamespace(parameters=values, terms=model.terms, model=model.name, confidence={IRON_KEY: (0.02, 0.04)},
                          stderr={IRON_KEY: 0.006}, correlation={IRON_KEY: {IRON_KEY: 1.0}})
    written = parameters_from_dict(parameter_file(ELBOW, fit, ("rec",)))
    assert written.thermal["iron_loss_w"] == 0.03 and written.thermal["iron_loss_speed_exponent"] == 2.0
    assert written.scope.uncertainty == {"thermal.iron_loss_w": (0.02, 0.04)}  # by the written key's path
    cov = written.scope.covariance  # fitted on a linear scale: the error itself
    assert cov.paths == ("thermal.iron_loss_w",) and cov.scale == ("linear",) and cov.array[0, 0] == pytest.approx(0.006 ** 2)
    iron = [s for s in network_from_parameters(written.thermal).sources if s.name == "speed_abs_rad_s"]
    assert len(iron) == 1 and iron[0].node == "winding"
    assert iron[0].power_w({"speed_abs_rad_s": 2.5}) == pytest.approx(0.03 * 2.5 ** 2, rel=1e-15)
    assert "identified" in written.sources["iron_loss_w"]


def test_speed_regressor_says_where_it_comes_from_and_gaps_split_the_recording():
    from thermo_ddp.identify.thermal_data import split_at_gaps
    t = np.concatenate([np.arange(0.0, 600.0), np.arange(900.0, 1500.0), np.arange(5000.0, 5005.0)])
    q = np.sin(0.5 * t)
    base = dict(time_s=t, current_a=np.ones_like(t), temperature_c=np.full_like(t, 30.0))
    assert thermal_grid(Recording(name="v", velocity=0.5 * np.cos(0.5 * t), **base), ELBOW).speed_source == "velocity"
    assert thermal_grid(Recording(name="q", position=q, **base), ELBOW).speed_source == "position differences"
    assert thermal_grid(Recording(name="none", **base), ELBOW).speed_source == "none"
    parts, skipped = split_at_gaps(Recording(name="g", position=q, **base))
    assert [p.name for p in parts] == ["g[0]", "g[1]"] and skipped == 5   # a 300 s gap; a 5-sample tail left out
    assert parts[1].time_s[0] == 900.0 and np.array_equal(parts[1].position, q[600:1200])


# ----------------------------------------------------------------------------- general networks, several sensors
def _network_truth_fit(seed: int = 1):
    from thermo_ddp.identify.network import free_paths
    from thermo_ddp.identify.network_fit import fit_network
    from thermo_ddp.diagnose.growth import Ranges
    from thermo_ddp.model.network_spec import LinkSpec, NetworkSpec, NodeSpec, SourceSpec
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file
    from thermo_ddp.testing.testbed.truths import network_case

    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    train, _, truth = network_case(seed, "chain3_iron")
    grid = thermal_grid(train, params, ThermalSettings(min_step_s=10.0, max_step_s=10.0))
    c = truth.capacity_j_per_k
    # the truth's structure, every value started 20-40 % off and the iron loss's share and exponent free
    spec = NetworkSpec(
        (NodeSpec("winding", 1.4 * c[0]), NodeSpec("tooth", 0.7 * c[1]), NodeSpec("yoke", 1.3 * c[2])),
        (LinkSpec(("winding", "tooth"), 1.3 * truth.link_k_per_w["winding-tooth"]),
         LinkSpec(("tooth", "yoke"), 0.8 * truth.link_k_per_w["tooth-yoke"]),
         LinkSpec(("yoke", "ambient"), 1.2 * truth.link_k_per_w["yoke-ambient"])),
        (SourceSpec("copper", {"winding": 1.0}, {}),
         SourceSpec("iron_losses", {"tooth": 0.5, "yoke": 0.5},
                    {"power_w": 300.0, "speed_exponent": 2.0, "ref_speed_rad_s": truth.ref_speed_rad_s})))
    ranges = Ranges((1.0, 1e6), 1e4, params.motor.current_nominal_a)
    fit = fit_network(params, spec, "winding", tuple(ranges.free(p) for p in free_paths(spec)), [grid])
    return fit, truth, grid, train


def test_network_fit_recovers_a_three_node_truth_on_every_sensor():
    """Oracle: a numpy three-node truth integrated exactly on a 1 s step (testing.testbed.truths), three sensors
    with 0.05 K noise; the fit's 10 s trapezoidal grid recovers it within its discretisation (2 %)."""
    fit, truth, grid, _ = _network_truth_fit()
    assert fit.success, fit.message
    c = truth.capacity_j_per_k
    expected = {"thermal.node.winding.capacity_j_per_k": c[0], "thermal.node.tooth.capacity_j_per_k": c[1],
                "thermal.node.yoke.capacity_j_per_k": c[2],
                "thermal.link.winding-tooth.resistance_k_per_w": truth.link_k_per_w["winding-tooth"],
                "thermal.link.tooth-yoke.resistance_k_per_w": truth.link_k_per_w["tooth-yoke"],
                "thermal.link.yoke-ambient.resistance_k_per_w": truth.link_k_per_w["yoke-ambient"],
                "thermal.source.iron_losses.power_w": truth.iron_w,
                "thermal.source.iron_losses.split.yoke": truth.iron_split[1]}
    for path, value in expected.items():
        assert fit.values[path] == pytest.approx(value, rel=0.04), path
    assert fit.values["thermal.source.iron_losses.speed_exponent"] == pytest.approx(truth.iron_exponent, abs=0.03)
    # each sensor weighted by its own noise, estimated from second differences of its readings
    assert set(fit.noise_c) == {"winding", "tooth", "yoke"}
    assert all(0.04 < s < 0.065 for s in fit.noise_c.values()), fit.noise_c
    assert all(r < 1.3 * 0.05 for r in fit.per_sensor().values()), fit.per_sensor()


def test_network_fit_uncertainty_by_dotted_path_is_written_and_read_back():
    """[uncertainty] (95 % interval of every fitted value) and [envelope] written into a network file that
    the parameter reader accepts: every interval holds its value."""
    from thermo_ddp.diagnose.network_diagnosis import network_section
    from thermo_ddp.envelope import envelope_of
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file

    fit, truth, grid, train = _network_truth_fit()
    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    data = params.to_dict() | {"thermal": network_section(fit.spec, 25.0, "winding"), "uncertainty": fit.uncertainty(),
                               "envelope": {k: list(v) for k, v in envelope_of([train]).items()}}
    back = parameters_from_dict(data, "written")
    assert set(back.scope.uncertainty) == set(fit.values)
    for path, (lo, hi) in back.scope.uncertainty.items():
        assert lo <= back.value(path) <= hi and hi > lo, path
    speeds = np.abs(train.velocity)
    assert back.scope.envelope["speed_rad_s"] == (speeds.min(), speeds.max())
    assert speeds.max() <= 400.0 and back.scope.envelope["ambient_c"][0] == pytest.approx(25.0, abs=0.2)


def test_identify_entry_fits_a_network_file_on_every_sensor(tmp_path):
    """``thermo-ddp identify`` with a network file and a CSV with node_<name>_c columns: every sensor fitted at
    once, a loadable network file with [uncertainty] and [envelope] written."""
    import pandas as pd

    from thermo_ddp.diagnose.network_diagnosis import network_section
    from thermo_ddp.model.parameters import dumps_parameters, load_parameters, packaged_parameter_file

    fit, truth, _, train = _network_truth_fit()
    columns = {"time_s": train.time_s, "current_a": train.current_a, "temperature_c": train.temperature_c,
               "velocity": train.velocity, "ambient_c": train.ambient_c}
    columns |= {f"node_{n}_c": v for n, v in train.sensors.items()}
    csv_path = tmp_path / "truth.csv"
    pd.DataFrame(columns).to_csv(csv_path, index=False)
    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    start = fit.spec.with_values({"node.winding.capacity_j_per_k": 2000.0, "source.iron_losses.power_w": 400.0})
    network = parameters_from_dict(params.to_dict() | {"thermal": network_section(start, 25.0, "winding")}, "net")
    model = tmp_path / "net.toml"
    model.write_text(dumps_parameters(network))
    out = identify_thermal_files([csv_path], parameters=model)
    assert out["success"] and set(out["per_sensor"]) == {"winding", "tooth", "yoke"}
    assert all(r < 1.3 * 0.05 for r in out["per_sensor"].values()), out["per_sensor"]
    written = parameters_from_dict(out["parameter_file"], "written")
    c = written.value("thermal.node.winding.capacity_j_per_k")
    assert c == pytest.approx(truth.capacity_j_per_k[0], rel=0.04)
    lo, hi = written.scope.uncertainty["thermal.node.winding.capacity_j_per_k"]
    assert lo < c < hi and written.scope.envelope["current_a"][1] == pytest.approx(np.abs(train.current_a).max())
