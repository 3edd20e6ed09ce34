"""The loop of designed experiments (thermo_ddp.studies.experiment_loop.close_the_loop) on short requests: two
rounds sharing one duration, and the winding guard every later round keeps.

Oracles: the request's duration; the recordings the second round's diagnosis read and what it leaves open; the winding guard of the passive diagnosis (``winding_rise_k_per_w``) times the copper loss at
the limit (``motor.joule_w``), over the design's predicted sensor; the truth's winding against the limit.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from thermo_ddp.diagnose.thermal import diagnose_thermal
from thermo_ddp.model import motor
from thermo_ddp.studies import experiment_loop
from thermo_ddp.studies.experiment_loop import close_the_loop, undetermined
from thermo_ddp.tasks.experiment import ExperimentSettings, design_experiment, winding_rise_k_per_w
from thermo_ddp.testing.testbed.truths import family_case

LIMIT_C, DURATION_S = 84.0, 600.0   # ten minutes: 10 knots of 30 s per 5-minute round (seconds to design)
MEASUREMENT = {"noise_c": 0.05, "sample_s": 2.0}


@pytest.fixture(scope="module")
def passive():
    """Friction heat never excited (the joint never moves): the passive session and its diagnosis."""
    truth, rec = family_case("friction_never_excited", np.random.default_rng(1), **MEASUREMENT)
    return truth, rec, diagnose_thermal(rec)


def spy_designs(monkeypatch) -> list[dict]:
    """Every design the loop asks for: its recordings, settings, diagnosis and result."""
    calls = []

    def spy(recordings, settings=None, diagnosis=None):
        design = design_experiment(recordings, settings=settings, diagnosis=diagnosis)
        calls.append({"recordings": list(recordings), "settings": settings, "diagnosis": diagnosis, "design": design})
        return design

    monkeypatch.setattr(experiment_loop, "design_experiment", spy)
    return calls


def test_two_rounds_share_the_duration_and_the_second_targets_what_is_still_open(passive, monkeypatch):
    truth, rec, before = passive
    calls = spy_designs(monkeypatch)
    settings = ExperimentSettings(duration_s=DURATION_S, limit_c=LIMIT_C, progress=False)
    loop = close_the_loop([rec], truth, rounds=2, settings=settings, diagnosis=before, shared=True, **MEASUREMENT)
    ran = [r for r in loop.rounds if r.true_peak_winding_c is not None]
    assert loop.success and len(ran) == 2, loop.report()
    # the rounds share the request: together no longer than it, the first in its half
    assert sum(r.design.duration_s for r in ran) <= DURATION_S
    assert ran[0].design.duration_s <= DURATION_S / 2
    assert calls[1]["settings"].duration_s <= DURATION_S - ran[0].design.duration_s
    # the second round is designed from the diagnosis of the passive and the first round's recordings, for what
    # that diagnosis leaves open
    second = calls[1]["recordings"]
    assert len(second) == 2 and second[0] is rec
    assert calls[1]["diagnosis"].recordings == (rec.name, second[1].name)
    still_open = undetermined(calls[1]["diagnosis"])
    assert loop.rounds[1].undetermined == still_open and still_open != undetermined(before)
    assert set(ran[1].design.targets) <= set(still_open)
    # safety: the robot's winding under the limit in every round
    assert max(r.true_peak_winding_c for r in ran) <= LIMIT_C


def test_a_later_round_guards_the_winding_at_least_as_the_first(passive, monkeypatch):
    """A later diagnosis that trusts half the winding-casing resistance (case 90019: a narrower but biased
    interval) must not loosen the guard: every round's predicted winding stays at least the sensor plus the first
    diagnosis's winding rise times the copper loss at the limit."""
    truth, rec, before = passive
    rise = winding_rise_k_per_w(before)
    key = "winding_casing_k_per_w"
    trusting = dataclasses.replace(before, params=before.params.replace(
        "thermal", **{key: 0.5 * before.params.thermal.values[key]}))
    assert winding_rise_k_per_w(trusting) < rise
    monkeypatch.setattr(experiment_loop, "diagnose_thermal", lambda recordings: trusting)
    calls = spy_designs(monkeypatch)
    settings = ExperimentSettings(duration_s=DURATION_S / 2, limit_c=LIMIT_C, progress=False)
    loop = close_the_loop([rec], truth, rounds=2, settings=settings, diagnosis=before, **MEASUREMENT)
    assert len(calls) == 2 and calls[1]["diagnosis"] is trusting and all(c["design"].designed for c in calls), \
        loop.report()
    params = before.params.motor
    for call in calls:
        d = call["design"]
        current = np.r_[d.current_a, d.current_a[-1]]
        guard = d.sensor_c + rise * motor.joule_w(params, current, LIMIT_C)[:, None]
        assert np.all(d.winding_c >= guard - 1e-9)
        assert d.peak_winding_c <= LIMIT_C + 0.05
