"""Thermal diagnosis against known truths: the seed report's experiments on the testbed elbow, and
three-node truths the diagnosing model does not share (testbed.truths: own network and integrator),
one per failure class: strong friction heat, a small but long mismatch, two masking terms, an
unidentifiable split, no fit at all, too little data.  Oracles: the concealed terms and true values."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from thermo_ddp.diagnose.selection import (HeldOutCheck, SubsetFit, SubsetSettings, nested_test, select_held_out,
                                          subset_select)
from thermo_ddp.diagnose.thermal import diagnose_thermal, diagnose_thermal_files, iron_max, term_specs
from thermo_ddp.errors import InputError
from thermo_ddp.identify.thermal import load_joint_parameters
from thermo_ddp.model.parameters import parameters_from_dict
from thermo_ddp.recordings import Recording
from thermo_ddp.testing.testbed import PlantParameters, biceps, static_3a, static_4a
from thermo_ddp.testing.testbed.truths import ThreeNodeTruth, record

CONTRACT_KEYS = {"success", "status", "message", "physics", "recordings", "rows", "baseline", "mismatches",
                 "missing_physics", "not_determinable", "final", "validation", "unexplained"}
TERM_KEYS = {"term", "evidence", "parameters", "rmse", "p_value", "effect_k", "ci95", "collinear_with", "held"}
INTERVAL_KEYS = {"recording", "start_s", "end_s", "regime", "mean_residual"}
SPECIFIC = ("friction_heating", "drive_heating", "casing_node")
ELBOW = load_joint_parameters(None)


def report_experiments(params: PlantParameters, heating_s: float = 1800.0, cooling_s: float = 1800.0):
    """Seed report 4.3: ~3 A and ~4 A static holds and the biceps curl (shortened)."""
    return [static_3a(params=params, heating_s=heating_s, cooling_s=cooling_s, loading_s=300.0).to_recording(),
            static_4a(params=params, heating_s=heating_s, cooling_s=cooling_s).to_recording(),
            biceps(params=params, heating_s=heating_s / 2, cooling_s=cooling_s).to_recording()]


def truth_recording(seed: int, concealed, **values) -> Recording:
    truth = ThreeNodeTruth(concealed=frozenset(concealed), **values)
    return record(truth, np.random.default_rng(seed), name=f"truth_{seed}", duration_s=10800.0, noise_c=0.05,
                  sample_s=2.0, jitter=0.2, gaps=1, ambient_drift_c=1.0)


@pytest.fixture(scope="module")
def both_effects():
    return diagnose_thermal(report_experiments(PlantParameters().with_effects("both")))


def test_report_experiments_name_friction_drive_and_the_casing_node(both_effects):
    d = both_effects
    assert d.success and d.status == "ok"
    assert set(d.missing_physics) == {"friction_heating", "drive_heating", "casing_node"}
    assert d.final_fit.rmse < 0.15 < d.baseline_fit.rmse
    out = d.to_dict()
    json.dumps(out)  # plain JSON types, no NaN objects
    assert CONTRACT_KEYS <= set(out)
    assert all(set(m) == INTERVAL_KEYS for m in out["mismatches"] + out["unexplained"])
    for term in out["missing_physics"]:
        assert set(term) == TERM_KEYS
        assert term["p_value"] * d.selection.n_tests < 1e-3 and term["effect_k"] > 0.01
        assert set(term["ci95"]) <= set(term["parameters"]) and not set(term["ci95"]) & set(term["held"])
    assert out["validation"]["rmse_after"] < 0.3 * out["validation"]["rmse_before"]
    params = parameters_from_dict(out["parameter_file"])
    truth = PlantParameters()
    assert params.thermal.model == "two_node_drive" and params.thermal.friction_node == "casing"
    assert params.thermal["drive_idle_w"] == pytest.approx(truth.drive_idle_w, rel=0.2)
    assert params.thermal["casing_capacity_j_per_k"] == pytest.approx(truth.casing_capacity_j_per_k, rel=0.15)
    assert out["speed_source"]["biceps"] == "velocity"
    # every named term lowers the error of recordings predicted by fits of the others; friction heat only on
    # the static holds (the statics' few touches cannot predict the biceps curl's speeds)
    held = out["validation"]["leave_one_segment_out"]
    assert held["segments"] == ["static_3a", "static_4a"] and held["rmse_after"] < held["rmse_before"]
    assert all(held["terms"][t]["rmse_with"] < held["terms"][t]["rmse_without"] for t in d.missing_physics)


def test_one_recording_moving_is_diagnosed_without_a_held_out_segment():
    """One recording without gaps and strong friction heat: nothing to leave out; the speed-driven term is
    named on the in-sample tests alone."""
    truth = ThreeNodeTruth(concealed=frozenset({"friction_heating"}), friction_linear_w_s_per_rad=4.0,
                           friction_quadratic_w_s2_per_rad2=1.5)
    rec = record(truth, np.random.default_rng(1), name="one", duration_s=10800.0, noise_c=0.05, sample_s=2.0,
                 jitter=0.2, gaps=0, ambient_drift_c=1.0)
    out = diagnose_thermal(rec, candidates=SPECIFIC).to_dict()
    assert out["success"] and [m["term"] for m in out["missing_physics"]] == ["friction_heating"]
    assert "leave_one_segment_out" not in out["validation"] and out["rows"]["segments"] == 1


def test_nothing_missing_gives_empty_missing_physics(tmp_path):
    one_node = PlantParameters(winding_casing_k_per_w=1e-3).with_effects("none")
    paths = []
    for rec in report_experiments(one_node):
        paths.append(tmp_path / f"{rec.name}.csv")
        rec.to_csv(paths[-1])
    out = diagnose_thermal_files(paths, plot=tmp_path / "none.png")
    assert out["success"] and out["status"] == "ok" and out["missing_physics"] == []
    assert out["final"] == out["baseline"] and out["final"]["model"] == "one_node"
    assert parameters_from_dict(out["parameter_file"]).thermal.model == "one_node"
    assert (tmp_path / "none.png").exists()


def test_strong_friction_heat_is_named_although_it_exceeds_the_files_friction():
    """Gearbox heat 4 W s/rad |v| + 1.5 W s^2/rad^2 v^2: over three times the file's friction power."""
    d = diagnose_thermal(truth_recording(1, {"friction_heating"}, friction_linear_w_s_per_rad=4.0,
                                         friction_quadratic_w_s2_per_rad2=1.5))
    assert d.status == "ok" and d.missing_physics == ["friction_heating"]
    term = d.to_dict()["missing_physics"][0]
    c1, c2 = term["parameters"].values()
    heat = lambda v: c1 * v + c2 * v ** 2  # noqa: E731
    file_power = lambda v: ELBOW.motor.coulomb_friction_nm * v + ELBOW.motor.viscous_friction_nm_s_per_rad * v ** 2  # noqa: E731
    assert heat(1.4) > 2.5 * file_power(1.4)
    assert "information, not a bound" in term["evidence"]


def test_small_long_mismatch_is_significant_without_an_absolute_gate():
    """A drive idling at 0.4 W lifts the casing by ~0.2 K for three hours: below the former 0.5 K gate."""
    rec = truth_recording(2, {"drive_heating"}, drive_idle_w=0.4, drive_loss_w_per_a2=0.0)
    d = diagnose_thermal(rec, candidates=SPECIFIC)
    assert d.baseline_fit.rmse < 0.4
    assert d.status == "ok" and d.missing_physics == ["drive_heating"]


def test_two_masking_terms_are_found_together():
    d = diagnose_thermal(truth_recording(3, {"friction_heating", "drive_heating"}), candidates=SPECIFIC)
    assert d.status == "ok" and d.missing_physics == ["friction_heating", "drive_heating"]


def test_casing_node_is_named_when_its_split_from_the_drive_node_is_not_identifiable():
    d = diagnose_thermal(truth_recording(4, {"casing_node", "drive_heating"}), candidates=SPECIFIC)
    assert d.status == "ok" and set(d.missing_physics) == {"casing_node", "drive_heating"}
    out = d.to_dict()
    loose = [n for n in out["not_determinable"] if n["term"] in ("casing_node", "drive_heating")]
    collinear = [t["collinear_with"] for t in out["missing_physics"] if t["collinear_with"]]
    assert loose or collinear
    assert all(n["experiment"] for n in out["not_determinable"])


@pytest.mark.parametrize("kind", ["random_walk", "falls_while_heating"])
def test_a_recording_no_candidate_explains_does_not_fit(kind):
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 7200.0, 2.0)
    current = np.where((t // 1200) % 2 == 1, 4.0, 0.0)
    if kind == "random_walk":
        temperature = 40.0 + np.cumsum(rng.normal(0, 0.3, t.size))
    else:  # cools while the current heats, warms while it is off: no non-negative heat does that
        temperature = 40.0 - 8.0 * np.sin(np.pi * (t % 1200) / 1200) * np.where(current > 0, 1, -1)
    rec = Recording(name=kind, time_s=t, current_a=current, temperature_c=temperature + rng.normal(0, 0.05, t.size))
    d = diagnose_thermal(rec, candidates=("drive_heating", "casing_node"))
    out = d.to_dict()
    assert not out["success"] and out["status"] == "model_does_not_fit"
    assert "no candidate explains" in out["message"]
    json.dumps(out)


def test_twelve_rows_are_insufficient_data_not_a_crash():
    t = np.arange(12.0)
    rec = Recording(name="short", time_s=t, current_a=np.ones_like(t), temperature_c=30 + 0.01 * t)
    out = diagnose_thermal(rec).to_dict()
    assert not out["success"] and out["status"] == "insufficient_data" and "short" in out["message"]
    assert out["missing_physics"] == [] and out["baseline"] is None
    json.dumps(out)


def test_nested_test_corrects_for_autocorrelation_and_bonferroni():
    """Known statistics: a 5 % RSS drop on 1000 white samples is significant (LR = 51.3 on 1 df), the
    same drop with tau = 50 (20 effective samples) is not; the 10 % RMSE rule and Bonferroni apply."""
    small = SubsetFit(frozenset(), rss=100.0, n=1000, n_parameters=3)
    large = SubsetFit(frozenset({"a"}), rss=95.0, n=1000, n_parameters=4)
    test = nested_test(small, large)
    assert test.statistic == pytest.approx(1000 * np.log(100 / 95))
    assert test.p_value < 1e-10 and not test.significant(1e-3, 1, 0.10)  # RMSE drop 2.5 % < 10 %
    assert test.significant(1e-3, 1, 0.0)
    slow = nested_test(small, dataclasses.replace(large, tau=50.0))
    assert slow.p_value > 0.1 and not slow.significant(1e-3, 1, 0.0)
    strong = SubsetFit(frozenset({"a"}), rss=60.0, n=1000, n_parameters=4)
    both = SubsetFit(frozenset({"a", "b"}), rss=59.5, n=1000, n_parameters=5, tau=1.0)
    only_b = SubsetFit(frozenset({"b"}), rss=99.0, n=1000, n_parameters=4)
    sel = subset_select([small, strong, only_b, both], SubsetSettings())
    assert sel.chosen is strong and sel.best is both  # b adds < 10 % RMSE: the smaller set wins
    assert set(sel.term_tests) == {"a"} and sel.n_tests == 3


def test_a_term_is_withdrawn_only_if_it_raises_the_held_out_error_beyond_a_tie():
    """Known held-out errors: 'a' wins in sample (RSS 100 -> 60) but predicts held-out segments worse by more
    than the tie; it is withdrawn and the selection repeated without it picks 'b' (RSS 100 -> 70), which holds
    out better; the fixed term is never judged.  A tie within the noise of one reading, or no segment able to
    judge, is no evidence: the in-sample choice stands, as it does without held-out data."""
    base = SubsetFit(frozenset({"f"}), rss=100.0, n=1000, n_parameters=3)
    a = SubsetFit(frozenset({"f", "a"}), rss=60.0, n=1000, n_parameters=4)
    b = SubsetFit(frozenset({"f", "b"}), rss=70.0, n=1000, n_parameters=4)
    ab = SubsetFit(frozenset({"f", "a", "b"}), rss=59.0, n=1000, n_parameters=5)
    rmse = {base.terms: 1.0, a.terms: 1.05, b.terms: 0.8, ab.terms: 0.85}
    asked = []

    def held_out(tie):
        def check(term, with_term, without):
            asked.append(term)
            return HeldOutCheck(term, rmse[with_term], rmse[without], tie, ("s0",))
        return check
    sel, checks = select_held_out([base, a, b, ab], held_out(0.02), frozenset({"f"}))
    assert sel.chosen is b and sel.n_tests == 1 and asked == ["a", "b"]
    assert checks["a"].withdraws and checks["b"].improves and set(checks) == {"a", "b"}
    assert str(checks["a"]) == "held-out RMSE 1 K without it, 1.05 K with it"
    sel, checks = select_held_out([base, a, b, ab], held_out(0.06), frozenset({"f"}))  # 0.05 K worse: a tie
    assert sel.chosen is a and checks["a"].verdict == "tie" and not checks["a"].withdraws
    assert "a tie: within the 0.06 K noise" in str(checks["a"])
    undecided = select_held_out([base, a, b, ab], lambda t, *sets: HeldOutCheck(t, undecided="no segment"),
                                frozenset({"f"}))
    assert undecided[0].chosen is a and undecided[1]["a"].verdict == "undecided"
    assert select_held_out([base, a, b, ab], None, frozenset({"f"}))[0].chosen is a


@pytest.mark.parametrize("seed, verdict, judged", [(50160, "tie", 1), (50169, "tie", 1), (50163, "lowers", 1),
                                                   (50044, "undecided", 0)])
def test_a_true_casing_node_is_not_withdrawn_on_evidence_that_is_not_against_it(seed, verdict, judged):
    """Truths of the benchmark whose concealed casing node the old rule withdrew (held-out RMSE with it not
    strictly lower, on every segment the others outnumbered).  50160: its one judging stretch is idle, where
    both networks predict the same (0.03305 vs 0.03304 K): a tie within the noise.  50169: the loaded stretch
    starts 13 K/h away from rest, so its fold's unmeasured winding starts at the wrong equilibrium (it was
    judged 0.82 K with, 0.39 K without); what is left is the idle stretch, a tie.  50163: the last stretch
    starts cooling (0.47 vs 0.30 K); on the settled one the casing node predicts 0.08 K against 0.28 K.
    50044: the first stretch's loaded hold was predicted by a fit of a stretch that never holds a load
    (2.3 K with, 0.35 K without): no segment can judge.  The casing node is named; a tie or an undecided
    check says in not_determinable that it stands on the in-sample test."""
    from thermo_ddp.testing.testbed.truths import random_case

    d = diagnose_thermal(random_case(seed)[0])
    check = d.held_out["casing_node"]
    assert d.success and "casing_node" in d.missing_physics and check.verdict == verdict, str(check)
    assert len(check.segments) == judged and not check.withdraws
    note = [n for n in d.not_determinable if n["term"] == "casing_node" and "in-sample test alone" in n["reason"]]
    assert bool(note) == (verdict != "lowers")
    assert "rule:" in d.report() and f"held out, casing_node: {verdict}" in d.report()


def test_friction_heat_is_confirmed_on_the_recordings_that_can_judge_it():
    """Three runs of one friction-heating truth, each from rest: a run is judged by a fit of the other two
    when they hold more samples of each of its regimes and reach its speed and current; there the model
    without friction heat predicts kelvins off, with it within the noise."""
    truth = ThreeNodeTruth(concealed=frozenset({"friction_heating"}))
    rng = np.random.default_rng(7)
    runs = [record(truth, rng, name=f"run{k}", duration_s=5400.0, noise_c=0.05, sample_s=5.0) for k in range(3)]
    d = diagnose_thermal(runs)
    check = d.held_out["friction_heating"]
    assert d.missing_physics == ["friction_heating"] and check.improves and 0 < len(check.segments) < 3
    assert check.with_term < 0.1 < 1.0 < check.without
    terms = d.to_dict()["validation"]["leave_one_segment_out"]["terms"]
    assert terms["friction_heating"]["verdict"] == "lowers" and terms["friction_heating"]["named"]


def test_physical_bounds_and_bad_input():
    specs = term_specs(ELBOW)
    assert specs["friction_heating"].bounds["friction_heat_linear_w_s_per_rad"] == (0.0, np.inf)
    assert 0 < iron_max(ELBOW) < 1.0
    t = np.arange(2000.0)
    with pytest.raises(InputError, match="temperature_c"):
        diagnose_thermal(Recording(name="no_temp", time_s=t, current_a=np.ones_like(t)))
    with pytest.raises(InputError, match="term"):
        diagnose_thermal(Recording(name="x", time_s=t, current_a=np.ones_like(t), temperature_c=30 + 0 * t),
                         candidates=("not_a_term",))


def test_physical_ranges_follow_the_motor_in_the_parameter_file():
    """The Talos class ranges stay as they are for the elbow; another motor's file widens them to its own
    scale (a water-cooled traction PMSM: 0.08 K/W, a drive/running loss of hundreds of watts)."""
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file

    elbow, pmsm = (term_specs(load_parameters(packaged_parameter_file(f))) for f in ("arm_left_4_joint",
                                                                                      "paderborn_pmsm"))
    assert elbow["one_node"].bounds == {"capacity_j_per_k": (100.0, 2e4), "resistance_k_per_w": (0.1, 20.0)}
    assert elbow["drive_heating"].bounds["drive_idle_w"] == (0.0, 100.0)
    lo, hi = pmsm["one_node"].bounds["resistance_k_per_w"]
    assert lo <= 0.0796 / 10 + 1e-12 and hi == 20.0
    motor = load_parameters(packaged_parameter_file("paderborn_pmsm")).motor
    assert pmsm["drive_heating"].bounds["drive_idle_w"][1] == pytest.approx(5 * motor.resistance_ohm * 210.0 ** 2)


def test_suggested_experiments_are_worded_from_the_motors_own_recorded_range():
    """The experiments speak of this motor's speeds and currents (95th percentiles of the recording), and of a
    gearbox only on a geared joint: a traction PMSM at 576 rad/s and 200 A is not asked for 2 rad/s."""
    from thermo_ddp.diagnose._thermal_terms import experiments
    from thermo_ddp.identify.thermal_data import thermal_grid
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file

    t = np.arange(0.0, 600.0, 2.0)
    speed, current = np.where(t < 300, 576.0, 288.0), np.where(t < 300, 200.0, 100.0)
    pmsm = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    grid = thermal_grid(Recording(name="pmsm", time_s=t, current_a=current, velocity=speed, temperature_c=30 + 0 * t),
                        pmsm)
    texts = experiments([grid], pmsm)
    assert "576 rad/s" in texts["iron_losses"] and "288 rad/s" in texts["iron_losses"]
    assert "gearbox" not in texts["iron_losses"] and "2 rad/s" not in texts["friction_heating"]
    assert "80 A" in texts["copper_resistance"] and "160 A" in texts["copper_resistance"]
    elbow = experiments([thermal_grid(Recording(name="elbow", time_s=t, current_a=np.full_like(t, 4.0),
                                                velocity=np.full_like(t, 2.0), temperature_c=30 + 0 * t), ELBOW)],
                        ELBOW)
    assert "gearbox" in elbow["iron_losses"] and "2 rad/s" in elbow["iron_losses"]
    from thermo_ddp.diagnose._thermal_terms import beyond_envelope
    from thermo_ddp.envelope import envelope_of
    rec = Recording(name="pmsm", time_s=t, current_a=current, velocity=speed, temperature_c=30 + 0 * t,
                    ambient_c=np.linspace(16.5, 20.6, t.size))
    beyond, speeds = beyond_envelope(envelope_of([rec]))  # the network diagnosis' not_determinable
    assert "576 rad/s" in beyond and "200 A" in beyond and "16.5-20.6 °C" in beyond and "230 and 576 rad/s" in speeds
    assert beyond_envelope({}) == ("recordings at other speeds, currents and ambient (coolant) temperatures than these", "")


def test_white_noise_temperature_is_not_diagnosed_as_fine():
    """A temperature of pure noise (tens of kelvin between samples) is fitted 'to within its noise' by any
    model: that is no diagnosis. The fuzzer's silent-garbage class (issue 14)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 3 * 3600.0, 1.0)
    rec = Recording(name="noise", time_s=t, current_a=rng.uniform(0, 5, t.size),
                    temperature_c=rng.uniform(20, 110, t.size))
    d = diagnose_thermal(rec)
    assert not d.success and d.status == "model_does_not_fit" and "broken sensor" in d.message


def test_without_a_room_thermometer_a_steady_heat_is_the_rooms_stand_in_not_a_claim(tmp_path):
    """The drive's steady heat on a one-node model is the same as a warmer room: with ambient_c logged the
    diagnosis names it; without, it fits it in every model (so the fit holds) but names nothing for it and
    says why, with the experiment that would tell."""
    from thermo_ddp.testing.testbed import COLUMNS, PlantParameters, static_3a

    rec = static_3a(params=PlantParameters().with_effects("drive"), heating_s=1800.0, cooling_s=1800.0)
    logged = diagnose_thermal(rec.to_csv(tmp_path / "logged.csv"))
    unlogged = diagnose_thermal(rec.to_csv(tmp_path / "unlogged.csv", tuple(c for c in COLUMNS if c != "ambient_c")))
    assert "drive_heating" in logged.missing_physics
    assert "drive_heating" not in unlogged.missing_physics and unlogged.success
    note = next(n for n in unlogged.to_dict()["not_determinable"] if n["term"] == "drive_heating")
    assert "ambient_c" in note["reason"] and "ambient_c" in note["experiment"]
    assert unlogged.final_fit.rmse <= 1.5 * logged.final_fit.rmse   # the stand-in keeps the fit


# ----------------------------------------------------------------------------- a network that grows
def _grower(family: str, seed: int = 2, kinds=("copper", "iron_losses", "friction_heating")):
    from thermo_ddp.diagnose.growth import GrowthSettings, Grower
    from thermo_ddp.diagnose.network_diagnosis import residual_noise
    from thermo_ddp.diagnose.thermal import ThermalDiagnosisSettings
    from thermo_ddp.identify.thermal import thermal_grid
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file
    from thermo_ddp.testing.testbed.truths import network_case

    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    train, _, truth = network_case(seed, family)
    grids = [thermal_grid(train, params, ThermalDiagnosisSettings().fit)]
    return Grower(params, grids, kinds, GrowthSettings(), residual_noise(grids, 120.0)), params, truth


def test_sensor_nodes_the_file_lacks_are_added_and_explain_a_copper_only_truth():
    """A one-node file and a recording with node_tooth_c and node_yoke_c: both nodes are added (not an error),
    and on a copper-only three-node truth every sensor is then within 1.5 x its noise: nothing more to name."""
    grower, params, truth = _grower("chain3")
    spec, fit, steps = grower.place_sensors(params.thermal.general)
    assert [s.addition.term for s in steps] == ["sensor_node", "sensor_node"]
    assert set(spec.node_names) == {"winding", "tooth", "yoke"}
    assert grower.explained(fit)
    assert all(r < 1.5 * fit.noise_c[n] for n, r in fit.per_sensor().items()), fit.per_sensor()


def test_growth_names_a_speed_dependent_iron_loss_by_the_nested_test():
    """A three-node truth with iron losses P (|w| / w_ref)^n in tooth and yoke: after the sensors are placed,
    the first accepted addition is an iron loss (p far below the Bonferroni level; a friction heat c1 |w| + c2 w^2
    fits these speeds as well, and iron losses come first in the file's heat_sources), its exponent within the
    physical 1-2.5 (its value is recovered once the structure is right: test_identify_thermal's network oracle)."""
    grower, params, truth = _grower("chain3_iron")
    spec, fit, _ = grower.place_sensors(params.thermal.general)
    assert not grower.explained(fit)
    step, tried = grower.step(fit)
    assert step is not None and step.addition.term == "iron_losses"
    assert step.test.p_value * len(tried) < 1e-6 and step.test.rmse_drop > 0.5
    assert 1.0 <= step.fit.values["thermal.source.iron_losses.speed_exponent"] <= 2.5
    assert {a.term for a, _ in tried} <= {"iron_losses", "friction_heating", "sink_node", "source_node"}


@pytest.mark.slow
def test_network_diagnosis_writes_a_file_that_says_what_it_learned_and_where():
    """Slow (the fast tests above cover placement and naming): the whole diagnosis of a three-node iron truth
    ends ok, names iron losses, writes a network file with [uncertainty], [envelope] that loads."""
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file
    from thermo_ddp.testing.testbed.truths import network_case

    train, _, truth = network_case(1, "chain3_iron")
    d = diagnose_thermal([train], parameters=load_parameters(packaged_parameter_file("paderborn_pmsm")))
    out = d.to_dict()
    assert out["status"] == "ok" and "iron_losses" in d.missing_physics, d.report()
    assert "drive_heating" not in d.missing_physics
    back = parameters_from_dict(out["parameter_file"], "written")
    assert back.thermal.model == "network" and len(back.thermal.general.nodes) >= 3
    assert back.scope.uncertainty and back.scope.envelope["speed_rad_s"][1] <= 400.0
