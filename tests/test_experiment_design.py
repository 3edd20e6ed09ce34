"""Designed experiments (thermo_ddp.tasks.experiment): the experiment the DDP plans from a diagnosis, run on the
testbed's hidden truths (thermo_ddp.testing.testbed.truths) and diagnosed again with the passive recording.

Oracles: the truth's concealed terms and friction-heat values (c1 |v| + c2 v^2), its true winding temperature,
the request's duration and the joint's URDF range and speed limit.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from thermo_ddp.diagnose.thermal import diagnose_thermal
from thermo_ddp.identify.thermal import FRICTION_KEYS
from thermo_ddp.tasks.experiment import ExperimentSettings, design_experiment
from thermo_ddp.tasks.experiment_motion import joint_bounds
from thermo_ddp.identify.thermal import load_joint_parameters
from thermo_ddp.testing.testbed.truths import ThreeNodeTruth, run_inputs, run_programme

HEAT = {"friction_heating", "drive_heating", "iron_losses", "copper_resistance"}
LIMIT_C, DURATION_S = 84.0, 3600.0
MEASUREMENT = {"noise_c": 0.05, "sample_s": 2.0}
# passive sessions: (duration s, current A, speed rad/s) segments, the speed reversing every 10 s
CASES = {
    "friction_one_speed": ({"friction_heating"}, [(600, 0, 0), (2400, 3.5, 0), (2400, 3.0, 1.5), (2400, 0, 0)]),
    "both_only_moving": ({"friction_heating", "drive_heating"}, [(600, 0, 0), (3600, 3.0, 1.5), (3600, 0, 0)]),
    "friction_never_excited": ({"friction_heating"}, [(600, 0, 0), (3600, 3.5, 0), (3600, 0, 0)]),
    "nothing_missing": (set(), [(600, 0, 0), (2400, 3.5, 0), (2400, 3.0, 1.5), (2400, 3.0, 0.5), (2400, 0, 0)]),
}


def passive(name: str):
    concealed, segments = CASES[name]
    t = np.arange(0.0, sum(s[0] for s in segments), 1.0)
    k = np.minimum(np.searchsorted(np.cumsum([s[0] for s in segments]), t, side="right"), len(segments) - 1)
    current = np.array([s[1] for s in segments], float)[k] * (1 + 0.05 * np.sin(2 * np.pi * t / 60))
    speed = np.array([s[2] for s in segments], float)[k] * np.sign(np.sin(2 * np.pi * t / 20.0) + 1e-9)
    truth = ThreeNodeTruth(concealed=frozenset(concealed))
    rec, _ = run_inputs(truth, np.random.default_rng(1), t, np.round(current, 2), speed, name, **MEASUREMENT)
    return truth, rec


def designed_and_rediagnosed(name: str):
    truth, rec = passive(name)
    design = design_experiment([rec], settings=ExperimentSettings(duration_s=DURATION_S, limit_c=LIMIT_C,
                                                                  progress=False))
    assert design.success and design.status == "designed", design.message
    rows = design.programme()
    run, temps = run_programme(truth, rows, np.random.default_rng(2), name="designed", **MEASUREMENT)
    return truth, design, rows, temps, diagnose_thermal([rec, run])


def check_settled(truth, design, rows, temps, after):
    # safety and the request: the true winding under the limit, the duration, the joint's range and speed
    assert temps[:, 0].max() <= LIMIT_C
    assert rows["time_s"][-1] <= DURATION_S and design.duration_s <= DURATION_S
    lo, hi, vmax = joint_bounds(load_joint_parameters(None), 0.0)
    assert lo <= rows["position"].min() and rows["position"].max() <= hi
    assert np.abs(rows["velocity"]).max() <= vmax and rows["velocity"][-1] == 0.0
    acceleration = np.abs(np.diff(rows["velocity"]) / np.diff(rows["time_s"]))
    assert acceleration.max() <= design.settings.acceleration_rad_s2 * (1 + 1e-9)
    assert design.peak_winding_c <= LIMIT_C + 0.05
    # the exact heat terms, every named parameter within +-50 %, friction heat within 40 % of the truth
    assert after.status == "ok"
    assert set(after.missing_physics) & HEAT == set(truth.concealed) & HEAT
    for term in after.to_dict()["missing_physics"]:
        for key, value in term["parameters"].items():
            low, high = term["ci95"][key]
            assert (high - low) / 2 <= 0.5 * abs(value), (term["term"], key, value, low, high)
    if "friction_heating" in truth.concealed:
        fit = after.final_fit.parameters
        true = (truth.friction_linear_w_s_per_rad, truth.friction_quadratic_w_s2_per_rad2)
        for key, value in zip(FRICTION_KEYS, true):
            assert abs(fit[key] - value) <= 0.4 * value, (key, fit[key], value)


def test_designed_experiment_settles_friction_heat_seen_at_one_speed():
    _, rec = passive("friction_one_speed")
    before = diagnose_thermal(rec)
    assert before.missing_physics == ["friction_heating"]
    assert not before.final_fit.identifiable(FRICTION_KEYS[0])   # one speed: c1 and c2 not separable
    truth, design, rows, temps, after = designed_and_rediagnosed("friction_one_speed")
    assert design.targets == ("friction_heating",) and design.predicted_separation_k["friction_heating"] > 0
    check_settled(truth, design, rows, temps, after)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["both_only_moving", "friction_never_excited"])
def test_designed_experiment_settles_the_truths_that_need_it(name):
    check_settled(*designed_and_rediagnosed(name))


def test_a_truth_with_nothing_missing_names_nothing():
    _, rec = passive("nothing_missing")
    design = design_experiment([rec], settings=ExperimentSettings(progress=False))
    assert design.success and design.status == "nothing_undetermined" and design.targets == ()
    assert design.to_dict()["predicted_separation_k"] == {} and design.to_dict()["duration_s"] == 0.0
