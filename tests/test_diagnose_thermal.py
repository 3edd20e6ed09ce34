"""Thermal diagnosis on the simulated elbow (testbed) whose hidden physics is known: the seed report's
three experiments with friction heating and drive heat, a plant with nothing missing, randomised
recordings, and a sensor glitch no candidate can explain."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from thermo_ddp.diagnose.thermal import diagnose_thermal, diagnose_thermal_files, iron_max, term_specs
from thermo_ddp.errors import InputError
from thermo_ddp.identify.thermal import load_joint_parameters
from thermo_ddp.model.parameters import parameters_from_dict
from thermo_ddp.recordings import Recording
from thermo_ddp.studies.testbed import EFFECTS, PlantParameters, biceps, random_recording, static_3a, static_4a
from thermo_ddp.studies.testbed.experiments import random_ambient, random_sensors

CONTRACT_KEYS = {"physics", "recordings", "baseline", "mismatches", "missing_physics", "final", "validation",
                 "unexplained"}
INTERVAL_KEYS = {"recording", "start_s", "end_s", "regime", "mean_residual"}
WRONG_ALWAYS = {"copper_resistance", "iron_losses"}  # the testbed has neither


def report_experiments(params: PlantParameters, heating_s: float = 1800.0, cooling_s: float = 1800.0):
    """Seed report 4.3: ~3 A and ~4 A static holds and the biceps curl (shortened)."""
    return [static_3a(params=params, heating_s=heating_s, cooling_s=cooling_s, loading_s=300.0).to_recording(),
            static_4a(params=params, heating_s=heating_s, cooling_s=cooling_s).to_recording(),
            biceps(params=params, heating_s=heating_s / 2, cooling_s=cooling_s).to_recording()]


@pytest.fixture(scope="module")
def both_effects():
    return diagnose_thermal(report_experiments(PlantParameters().with_effects("both")))


def _gain(diagnosis, term: str, regime: str) -> float:
    return next((g.gain for g in diagnosis.explained[term] if g.regime == regime), 0.0)


def test_report_experiments_reveal_friction_and_drive_heating(both_effects):
    d = both_effects
    assert set(d.missing_physics) >= {"friction_heating", "drive_heating"}
    assert not set(d.missing_physics) & WRONG_ALWAYS
    baseline_regimes = {m.regime for m in d.selection.baseline_localisation.mismatches}
    assert {"moving", "idle", "cooling"} <= baseline_regimes
    # friction explains the mismatch while the arm moves, the drive the idle and cooling mismatch
    assert _gain(d, "friction_heating", "moving") > 0.5
    assert _gain(d, "drive_heating", "idle") > 0.5 and _gain(d, "drive_heating", "cooling") > 0.5
    assert d.selection.final.fit.rmse < 0.15 < d.selection.baseline.fit.rmse
    assert not d.selection.final_localisation.mismatches


def test_diagnosis_json_follows_the_contract_and_gives_a_loadable_parameter_file(both_effects, tmp_path):
    out = both_effects.to_dict()
    assert set(out) == CONTRACT_KEYS | {"parameter_file"}
    json.dumps(out)  # plain JSON types only
    assert out["physics"] == "thermal" and out["recordings"] == ["static_3a", "static_4a", "biceps"]
    assert all(set(m) == INTERVAL_KEYS for m in out["mismatches"] + out["unexplained"])
    assert [m["term"] for m in out["missing_physics"]] == both_effects.missing_physics
    friction = next(m for m in out["missing_physics"] if m["term"] == "friction_heating")
    assert 0.7 < friction["parameters"]["friction_heating_fraction"] <= 1.0  # the plant turns all friction into heat
    assert "moving" in friction["evidence"]
    assert out["validation"]["rmse_after"] < 0.3 * out["validation"]["rmse_before"]
    params = parameters_from_dict(out["parameter_file"])
    assert params.thermal.model == "two_node_drive"
    truth = PlantParameters()
    assert params.thermal["drive_idle_w"] == pytest.approx(truth.drive_idle_w, rel=0.2)
    assert params.thermal["casing_capacity_j_per_k"] == pytest.approx(truth.casing_capacity_j_per_k, rel=0.15)
    path = both_effects.plot(tmp_path / "diagnosis.png")
    assert path.stat().st_size > 10_000


def test_iron_losses_rejected_as_unphysical_when_friction_heats(both_effects):
    """Iron losses fit the moving mismatch as well as friction does; only their physical bound
    (no-load losses of the motor class) tells them apart."""
    iron = [a for a in both_effects.selection.assessments if a.term == "iron_losses"]
    assert iron and not any(a.accepted for a in iron)
    assert any(not a.physical and a.candidate.fit.parameters["iron_loss_w_s2_per_rad2"] > iron_max(
        load_joint_parameters(None)) for a in iron)


def test_nothing_missing_gives_empty_missing_physics(tmp_path):
    one_node = PlantParameters(winding_casing_k_per_w=1e-3).with_effects("none")
    recs = report_experiments(one_node, heating_s=1800.0, cooling_s=1800.0)
    paths = []
    for rec in recs:
        paths.append(tmp_path / f"{rec.name}.csv")
        rec.to_csv(paths[-1])
    out = diagnose_thermal_files(paths, plot=tmp_path / "none.png")
    assert out["missing_physics"] == [] and out["unexplained"] == [] and out["mismatches"] == []
    assert out["final"] == out["baseline"] and out["final"]["model"] == "one_node"
    assert parameters_from_dict(out["parameter_file"]).thermal.model == "one_node"
    assert (tmp_path / "none.png").exists()


def test_unexplained_systematic_residual_is_reported_with_its_interval():
    """A sensor glitch (+2 K for 20 minutes during cooling) is systematic but no physics explains it."""
    rec = static_4a(params=PlantParameters(winding_casing_k_per_w=1e-3).with_effects("none"), heating_s=2400.0,
                    cooling_s=4800.0).to_recording()
    start = rec.time_s[-1] - 3000.0
    glitch = (rec.time_s > start) & (rec.time_s < start + 1200.0)
    d = diagnose_thermal(dataclasses.replace(rec, temperature_c=rec.temperature_c + 2.0 * glitch))
    assert not set(d.missing_physics) & ({"friction_heating", "drive_heating"} | WRONG_ALWAYS)
    unexplained = d.to_dict()["unexplained"]
    assert unexplained, "the glitch must be reported"
    covered = max(min(m["end_s"], start + 1200.0) - max(m["start_s"], start) for m in unexplained)
    assert covered > 600.0
    assert all(m["mean_residual"] > 0 for m in unexplained if m["start_s"] >= start and m["end_s"] <= start + 1200)


def _pair(seed: int, effects: str):
    rng = np.random.default_rng(10_000 + seed)
    params = PlantParameters().randomised(rng).with_effects(effects)
    common = dict(params=params, sensors=random_sensors(rng), ambient=random_ambient(rng), idle_s=300.0)
    return [static_4a(heating_s=2400.0, cooling_s=1800.0, current_a=rng.uniform(2.5, 4.0), seed=seed, **common)
            .to_recording(),
            biceps(heating_s=900.0, cooling_s=1800.0, current_rms_a=rng.uniform(2.3, 2.8), seed=seed + 1, **common)
            .to_recording()]


def test_randomised_recordings_detection_and_false_alarm_bounds():
    """Small version of benchmarks/bench_thermal_diagnosis.py: noisy, quantised, irregular recordings
    of randomised plants.  Bounds: no false alarm, drive heat found in most static holds, friction
    found in moving + static pairs."""
    found, truth = [], []
    for seed in range(4):
        rec = random_recording(seed, experiment=("static_4a", "static_3a")[seed % 2], heating_s=2400.0,
                               cooling_s=1800.0)
        found.append(set(diagnose_thermal(rec.to_recording()).missing_physics))
        truth.append({t for t, on in rec.truth.parameters.effects.items() if on})
    for seed, effects in ((0, "friction"), (1, "none"), (2, "both")):
        found.append(set(diagnose_thermal(_pair(seed, effects)).missing_physics))
        truth.append({"none": set(), "friction": {"friction_heating"},
                      "both": {"friction_heating", "drive_heating"}}[effects])
    false_alarms = sum(bool(f - t - {"casing_node"}) for f, t in zip(found, truth))
    drive = [("drive_heating" in f) for f, t in zip(found, truth) if "drive_heating" in t]
    friction = [("friction_heating" in f) for f, t in zip(found[4:], truth[4:]) if "friction_heating" in t]
    assert false_alarms == 0, list(zip(found, truth))
    assert drive and np.mean(drive) >= 0.75, list(zip(found, truth))
    assert friction and all(friction), list(zip(found, truth))


def test_physical_bounds_and_bad_input():
    specs = term_specs(load_joint_parameters(None))
    assert specs["friction_heating"].bounds["friction_heating_fraction"] == (0.0, 1.0)
    assert 0 < iron_max(load_joint_parameters(None)) < 1.0
    t = np.arange(200.0)
    with pytest.raises(InputError, match="temperature_c"):
        diagnose_thermal(Recording(name="no_temp", time_s=t, current_a=np.ones_like(t)))
    with pytest.raises(InputError, match="term"):
        diagnose_thermal(Recording(name="x", time_s=t, current_a=np.ones_like(t), temperature_c=30 + 0 * t),
                         candidates=("not_a_term",))
    assert EFFECTS == ("none", "friction", "drive", "both")
