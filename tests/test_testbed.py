"""The simulated elbow (testbed) against oracles: closed forms, matrix exponentials, energy, the report."""
from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm

from thermo_ddp.errors import InputError
from thermo_ddp.testing.testbed import (COLUMNS, Ambient, PlantParameters, SensorSettings, biceps, random_campaign,
                                random_recording, simulate, static_4a, static_hold)
from thermo_ddp.testing.testbed.physics import Phase, Profile, curl, hold
from thermo_ddp.testing.testbed.sensors import sample_times

NOISELESS = SensorSettings().noiseless()


def _rise(recording, phase: str = "heating") -> float:
    """True casing rise over a phase."""
    start, end = recording.truth.phase(phase)
    casing = recording.truth.solution.temperatures([start, end])[1]
    return float(casing[1] - casing[0])


# ----------------------------------------------------------------------------- thermal oracles
def test_one_node_limit_follows_report_eq8_first_order_response():
    """Winding glued to the casing, no drive, no friction: eq. (8) with gain and time constant
    R_TA R_th / (1 - R_TA R_th alpha I^2) and C R_th / (1 - ...), copper feedback included."""
    params = PlantParameters(winding_casing_k_per_w=1e-4, drive_heating=False, friction_heating=False)
    current = 5.0
    rec = static_hold(current, payload_kg=20.0, heating_s=6000.0, start="cold", sensors=NOISELESS, params=params,
                      ambient=Ambient(room_c=params.resistance_ref_c))
    t = np.linspace(0.0, 6000.0, 61)
    np.testing.assert_allclose(rec.truth.solution.profile.mechanics(params, t).current_a, current, rtol=1e-12)
    r_th = params.casing_ambient_k_per_w + params.winding_casing_k_per_w
    cap = params.casing_capacity_j_per_k + params.winding_capacity_j_per_k
    loop = 1 - params.resistance_ohm * r_th * params.copper_alpha_per_k * current**2
    gain, tau = params.resistance_ohm * r_th / loop, cap * r_th / loop
    expected = params.resistance_ref_c + gain * current**2 * (1 - np.exp(-t / tau))
    casing = rec.truth.solution.temperatures(t)[1]
    np.testing.assert_allclose(casing, expected, atol=3e-3)
    without_copper_feedback = params.resistance_ohm * r_th * current**2
    assert gain * current**2 - without_copper_feedback > 0.5  # the oracle does see the R(T) term


def _network_matrix(p: PlantParameters) -> tuple[np.ndarray, np.ndarray]:
    """Winding/casing/drive network written out by hand: C dT/dt = -L T + q (alpha = 0)."""
    g_wc, g_ca = 1 / p.winding_casing_k_per_w, 1 / p.casing_ambient_k_per_w
    g_dc, g_da = 1 / p.drive_casing_k_per_w, 1 / p.drive_ambient_k_per_w
    lap = np.array([[g_wc, -g_wc, 0.0],
                    [-g_wc, g_wc + g_ca + g_dc, -g_dc],
                    [0.0, -g_dc, g_dc + g_da]])
    caps = np.array([p.winding_capacity_j_per_k, p.casing_capacity_j_per_k, p.drive_capacity_j_per_k])
    return lap, caps


def test_three_node_linear_case_matches_matrix_exponential():
    params = PlantParameters(copper_alpha_per_k=0.0, friction_heating=False)
    current, room = 4.0, 26.0
    rec = static_hold(current, payload_kg=20.0, heating_s=4000.0, start="cold", sensors=NOISELESS, params=params,
                      ambient=Ambient(room_c=room))
    lap, caps = _network_matrix(params)
    heat = np.array([params.resistance_ohm * current**2, 0.0,
                     params.drive_idle_w + params.drive_loss_w_per_a2 * current**2])
    heat += room * np.array([0.0, 1 / params.casing_ambient_k_per_w, 1 / params.drive_ambient_k_per_w])
    a, b = -lap / caps[:, None], heat / caps
    t0 = np.full(3, room)
    final = np.linalg.solve(a, -b)
    for t in (10.0, 100.0, 1000.0, 4000.0):
        expected = final + expm(a * t) @ (t0 - final)
        np.testing.assert_allclose(rec.truth.solution.temperatures([t])[:, 0], expected, atol=1e-5)


def test_idle_motor_sits_near_43c_in_a_26c_room_because_of_the_drive():
    """Report 4.3: drives heat an idle motor to ~43 °C in a 26 °C room."""
    params = PlantParameters()
    idle = Profile((Phase("idle", "idle", 30000.0, hold(0.0)),))
    casing = simulate(params, idle, Ambient(room_c=26.0), initial="cold").temperatures([30000.0])[1, 0]
    assert casing == pytest.approx(43.0, abs=1.0)
    # series-parallel network by hand: drive -> (ambient | casing -> ambient)
    p = params
    path = p.drive_casing_k_per_w + p.casing_ambient_k_per_w
    drive_rise = p.drive_idle_w / (1 / p.drive_ambient_k_per_w + 1 / path)
    assert casing == pytest.approx(26.0 + drive_rise * p.casing_ambient_k_per_w / path, abs=1e-3)
    cold = simulate(dataclasses.replace(params, drive_heating=False), idle, Ambient(room_c=26.0), initial="idle")
    assert cold.temperatures([0.0, 30000.0])[1] == pytest.approx([26.0, 26.0], abs=1e-3)


def test_experiments_start_warm_from_the_drive():
    rec = static_4a(heating_s=600.0, cooling_s=600.0, sensors=NOISELESS)
    assert rec.truth.casing_c[0] == pytest.approx(43.0, abs=1.0)
    assert rec.truth.drive_c is not None and rec.truth.drive_c[0] > rec.truth.casing_c[0]


@pytest.mark.parametrize("make", [
    lambda: biceps(heating_s=300.0, cooling_s=300.0, idle_s=60.0, sensors=NOISELESS),
    lambda: static_4a(heating_s=600.0, cooling_s=300.0, idle_s=60.0, bump_at_s=200.0, sensors=NOISELESS),
], ids=["biceps", "static_4a"])
def test_energy_balance_heat_in_equals_stored_plus_lost(make):
    """∫(Joule + friction + drive) dt = Σ C ΔT + ∫ losses to the room, integrated independently."""
    truth = make().truth
    end = truth.solution.profile.duration_s
    t = np.linspace(0.0, end, int(end / 2e-3) + 1)
    flows = truth.solution.heat_flows(t)
    heat_in = np.trapezoid(flows.heat_in_w, t)
    lost = np.trapezoid(flows.to_ambient_w, t)
    p = truth.parameters
    caps = np.array([p.winding_capacity_j_per_k, p.casing_capacity_j_per_k, p.drive_capacity_j_per_k])
    temps = truth.solution.temperatures([0.0, end])
    stored = float(caps @ (temps[:, 1] - temps[:, 0]))
    assert heat_in > 1e4
    assert heat_in == pytest.approx(stored + lost, rel=1e-5)


# ----------------------------------------------------------------------------- mechanics
def test_inverse_dynamics_velocity_acceleration_and_effort():
    """dq, ddq match central differences of q; effort/current follow the stated torque balance."""
    params = PlantParameters()
    phase = Phase("curl", "moving", 10.0, curl(1.0, 0.8, 2.5))
    profile = Profile((phase,))
    t, h = np.linspace(0.3, 9.7, 200), 1e-4
    q = lambda s: profile.mechanics(params, s).q_rad  # noqa: E731
    mech = profile.mechanics(params, t)
    np.testing.assert_allclose(mech.v_rad_s, (q(t + h) - q(t - h)) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(mech.a_rad_s2, (q(t + h) - 2 * q(t) + q(t - h)) / h**2, atol=1e-4)
    p = params
    gravity = p.gravity_m_s2 * p.forearm_mass_kg * p.forearm_com_m * np.sin(mech.q_rad)
    link_inertia = p.forearm_inertia_kg_m2 + p.forearm_mass_kg * p.forearm_com_m**2
    np.testing.assert_allclose(mech.effort_nm, gravity + link_inertia * mech.a_rad_s2, rtol=1e-12)
    friction = (p.viscous_friction_nm_s_per_rad * mech.v_rad_s
                + p.coulomb_friction_nm * np.tanh(mech.v_rad_s / p.coulomb_smoothing_rad_s))
    motor = mech.effort_nm + p.gear_ratio**2 * p.rotor_inertia_kg_m2 * mech.a_rad_s2 + friction + p.effort_offset_nm
    np.testing.assert_allclose(mech.current_a * 11.06, motor, rtol=1e-10)


def test_static_holds_reach_the_report_currents():
    rec = static_4a(heating_s=900.0, cooling_s=300.0, bump_at_s=450.0, bump_fraction=0.1, sensors=NOISELESS)
    start, end = rec.truth.phase("heating")
    t = rec.time_s
    before = (t > start + 60) & (t < start + 440)
    after = (t > start + 460) & (t < end)
    assert np.median(rec.columns["current_a"][before]) == pytest.approx(4.0, abs=0.01)
    assert np.median(rec.columns["current_a"][after]) > 4.3  # the bump (bag slipped outward)
    cooling = t > rec.truth.phase("cooling")[0]
    assert np.all(rec.columns["current_a"][cooling] == 0.0)
    assert np.all(rec.columns["position"][cooling] == 0.0)


# ----------------------------------------------------------------------------- biceps
def test_biceps_current_rms_is_the_reports_2_57_a():
    rec = biceps(heating_s=600.0, cooling_s=0.0, idle_s=0.0, seed=3)
    start, end = rec.truth.phase("heating")
    moving = (rec.time_s > start) & (rec.time_s < end)
    measured = math.sqrt(np.mean(rec.columns["current_a"][moving] ** 2))
    assert measured == pytest.approx(2.57, rel=0.10)
    t = np.linspace(start, end, 200001)
    true = rec.truth.solution.profile.mechanics(rec.truth.parameters, t).current_a
    assert math.sqrt(np.mean(true**2)) == pytest.approx(2.57, rel=0.01)


def _curl_and_hold(friction_heating: bool):
    params = PlantParameters(friction_heating=friction_heating)
    kwargs = dict(heating_s=1200.0, cooling_s=0.0, idle_s=0.0, params=params, sensors=NOISELESS)
    return biceps(**kwargs), static_hold(2.57, **kwargs)


def test_friction_heating_makes_the_curl_heat_faster_than_a_static_hold_at_the_same_rms():
    curl_rec, hold_rec = _curl_and_hold(friction_heating=True)
    assert _rise(curl_rec) > 1.2 * _rise(hold_rec) > 0
    # the recorded (sensor) temperatures show it too
    measured = [np.mean(r.columns["temperature_c"][-20:]) - np.mean(r.columns["temperature_c"][:20])
                for r in (curl_rec, hold_rec)]
    assert measured[0] > measured[1] + 0.3
    # without friction heating, equal RMS current means equal heating
    curl_off, hold_off = _curl_and_hold(friction_heating=False)
    assert _rise(curl_off) == pytest.approx(_rise(hold_off), rel=0.03)


# ----------------------------------------------------------------------------- sensors
def test_sampling_intervals_stay_within_the_jitter_bounds():
    settings = SensorSettings(sample_rate_hz=2.0, jitter_fraction=0.3)
    times = sample_times(3600.0, settings, np.random.default_rng(1)).time_s
    low, high = settings.interval_bounds_s
    steps = np.diff(times)
    assert np.all(steps > 0) and low <= steps.min() and steps.max() <= high
    assert steps.min() < 0.5 * (1 - 0.4) and steps.max() > 0.5 * (1 + 0.4)  # jitter really is there


def test_gaps_and_dropouts_only_remove_samples():
    settings = SensorSettings(sample_rate_hz=1.0, jitter_fraction=0.2, gap_count=3, dropout_probability=0.05)
    sampling = sample_times(7200.0, settings, np.random.default_rng(5))
    steps = np.diff(sampling.time_s)
    low, high = settings.interval_bounds_s
    assert len(sampling.gaps_s) >= 1 and sampling.dropped > 0
    assert np.all(steps >= low)
    for start, end in sampling.gaps_s:
        assert not np.any((sampling.time_s > start) & (sampling.time_s < end))
    long_steps = steps[steps > high]
    assert len(long_steps) <= len(sampling.gaps_s) + sampling.dropped


def test_temperature_is_quantised_and_noise_has_the_set_size():
    quantum = 0.25
    sensors = SensorSettings(temperature_quantum_c=quantum, temperature_noise_c=0.15, sample_rate_hz=2.0)
    rec = static_4a(heating_s=1800.0, cooling_s=1800.0, sensors=sensors, seed=11)
    steps = rec.columns["temperature_c"] / quantum
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    raw = static_4a(heating_s=1800.0, cooling_s=1800.0, seed=11,
                    sensors=dataclasses.replace(sensors, temperature_quantum_c=0.0))
    noise = raw.columns["temperature_c"] - raw.truth.casing_c
    assert np.std(noise) == pytest.approx(0.15, rel=0.1)
    assert np.abs(rec.columns["temperature_c"] - rec.truth.casing_c).max() < 5 * 0.15 + quantum


def test_csv_round_trip_has_exactly_the_contract_columns(tmp_path):
    rec = random_recording(4, experiment="static_3a", heating_s=600.0, cooling_s=600.0)
    path = rec.to_csv(tmp_path / "rec.csv")
    with path.open() as handle:
        rows = list(csv.reader(handle))
    assert tuple(rows[0]) == COLUMNS
    table = np.array(rows[1:], dtype=float)
    for k, column in enumerate(COLUMNS):
        np.testing.assert_array_equal(table[:, k], rec.columns[column])
    assert np.all(np.diff(table[:, 0]) > 0)
    hidden = {"winding_c", "casing_c", "drive_c"}
    assert not hidden & set(rows[0])


def test_to_recording_is_a_valid_package_recording(tmp_path):
    from thermo_ddp.recordings import read_csv
    rec = random_recording(9, experiment="static_4a", heating_s=600.0, cooling_s=600.0)
    recording, read_back = rec.to_recording(), read_csv(rec.to_csv(tmp_path / "r.csv"))
    assert len(recording) == len(rec.time_s)
    for column in COLUMNS:
        np.testing.assert_array_equal(getattr(recording, column), rec.columns[column])
        np.testing.assert_array_equal(getattr(read_back, column), rec.columns[column])


# ----------------------------------------------------------------------------- randomisation
def test_random_recording_is_reproducible_from_its_seed():
    first, again = (random_recording(21, heating_s=600.0, cooling_s=600.0) for _ in range(2))
    other = random_recording(22, heating_s=600.0, cooling_s=600.0)
    assert first.name == again.name
    assert first.truth.parameters == again.truth.parameters
    for column in COLUMNS:
        np.testing.assert_array_equal(first.columns[column], again.columns[column])
    np.testing.assert_array_equal(first.truth.winding_c, again.truth.winding_c)
    assert first.truth.parameters != other.truth.parameters


@pytest.mark.parametrize("effects, friction, drive", [("none", False, False), ("friction", True, False),
                                                      ("drive", False, True), ("both", True, True)])
def test_random_recording_switches_the_requested_effects(effects, friction, drive):
    rec = random_recording(30, effects=effects, experiment="static_4a", heating_s=300.0, cooling_s=300.0)
    assert rec.truth.effects == {"friction_heating": friction, "drive_heating": drive}
    assert (rec.truth.drive_c is not None) == drive
    if not drive:  # no drive: the idle motor starts at room temperature
        assert rec.truth.casing_c[0] == pytest.approx(rec.truth.room_c[0], abs=0.2)


def test_campaign_is_one_robot_with_independent_recordings():
    recs = random_campaign(8, effects="both", experiments=("static_3a", "static_4a"), heating_s=300.0, cooling_s=300.0)
    assert recs[0].truth.parameters == recs[1].truth.parameters != PlantParameters()
    assert recs[0].truth.effects == {"friction_heating": True, "drive_heating": True}
    assert recs[0].truth.sensors != recs[1].truth.sensors
    assert [r.truth.experiment for r in recs] == ["static_3a", "static_4a"]


def test_randomised_parameters_stay_in_their_ranges():
    nominal = PlantParameters()
    for seed in range(50):
        drawn = nominal.randomised(np.random.default_rng(seed))
        for name, spread in (("casing_capacity_j_per_k", 0.25), ("drive_idle_w", 0.25),
                             ("winding_casing_k_per_w", 0.25), ("coulomb_friction_nm", 0.30),
                             ("viscous_friction_nm_s_per_rad", 0.30)):
            assert abs(getattr(drawn, name) / getattr(nominal, name) - 1) <= spread
        assert drawn.torque_constant_nm_per_a == nominal.torque_constant_nm_per_a


def test_bad_settings_are_input_errors():
    with pytest.raises(InputError, match="jitter_fraction"):
        SensorSettings(jitter_fraction=0.6)
    with pytest.raises(InputError, match="casing_ambient_k_per_w"):
        PlantParameters(casing_ambient_k_per_w=-1.0)
    with pytest.raises(InputError, match="current_a"):
        static_hold(0.01, payload_kg=20.0, heating_s=600.0)


# ----------------------------------------------------------------------------- motor voltage
def test_logged_voltage_is_the_resistance_law_of_the_true_winding(tmp_path):
    """voltage_v = R_ref (1 + alpha (T_w - T_ref)) i + K_m N v, evaluated here from the hidden truth
    (noiseless sensors), and it is written only when asked for."""
    from thermo_ddp.testing.testbed import LOGGED_COLUMNS, winding_pulses
    p = PlantParameters()
    rec = winding_pulses(params=p, pulses=1, cooling_s=600.0, sensors=SensorSettings().noiseless(), seed=1)
    t, c = rec.truth, rec.columns
    ohm = p.resistance_ohm * (1 + p.copper_alpha_per_k * (t.winding_c - p.resistance_ref_c))
    want = ohm * t.current_a + p.torque_constant_nm_per_a * p.gear_ratio * c["velocity"]
    np.testing.assert_allclose(c["voltage_v"], want, rtol=1e-12, atol=1e-12)
    with rec.to_csv(tmp_path / "default.csv").open() as handle:
        assert tuple(next(csv.reader(handle))) == COLUMNS
    with rec.to_csv(tmp_path / "voltage.csv", LOGGED_COLUMNS).open() as handle:
        assert tuple(next(csv.reader(handle))) == LOGGED_COLUMNS


def test_winding_pulses_excite_the_winding_and_stay_under_the_cut_off():
    from thermo_ddp.testing.testbed import winding_pulses
    rec = winding_pulses(seed=2)
    t = rec.truth
    start, end = t.phase("pulse_1")
    during = (t.time_s > start + 2) & (t.time_s < end)
    assert np.median(np.abs(t.current_a[during])) == pytest.approx(8.0, rel=0.05)
    assert 60.0 < t.winding_c.max() < 84.0           # tens of kelvin above the casing, under the cut-off
    assert t.winding_c.max() - t.casing_c.max() > 20.0
    assert [name for name, *_ in t.phases].count("rest_3") == 1
