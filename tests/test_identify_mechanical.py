"""Mechanical identification against the published EMPS reference model and known synthetic parameters.

EMPS reference values: A. Janot, M. Gautier, M. Brunot, "Data Set and Reference Models of EMPS",
2019 Workshop on Nonlinear System Identification Benchmarks, Eindhoven:
M = 95.1089 kg, Fv = 203.5034 N·s/m, Fc = 20.3935 N, OF = -3.1648 N.
"""
from __future__ import annotations


import numpy as np
import pytest

from thermo_ddp.errors import InputError
from thermo_ddp.identify import (BASELINE_TERMS, REFERENCE_TERMS, MechanicalSettings, identify_mechanical,
                                 identify_torque_current, linear_fit)
from thermo_ddp.recordings import Recording, read_csv

PUBLISHED = {"inertia": 95.1089, "viscous_friction": 203.5034, "coulomb_friction": 20.3935, "effort_offset": -3.1648}


@pytest.fixture(scope="module")
def emps(emps_csv) -> Recording:
    return read_csv(emps_csv)


def _relative(fit, key):
    return abs(fit.parameters[key] - PUBLISHED[key]) / abs(PUBLISHED[key])


@pytest.mark.parametrize("settings", [MechanicalSettings(), MechanicalSettings(decimate=10)], ids=["1kHz", "decimated"])
def test_emps_reference_parameters_within_3_percent(emps, settings):
    fit = identify_mechanical(emps, REFERENCE_TERMS, settings)
    assert fit.success and fit.status == "ok"
    for key in ("inertia", "viscous_friction", "coulomb_friction"):
        assert _relative(fit, key) < 0.03, (key, fit.parameters[key])
    assert _relative(fit, "effort_offset") < 0.05


def test_emps_coulomb_halves_the_residual(emps):
    base = identify_mechanical(emps, BASELINE_TERMS)
    full = identify_mechanical(emps, REFERENCE_TERMS)
    assert full.rmse < 0.65 * base.rmse  # published: about 10.7 N -> 5.9 N
    # without Coulomb, viscous friction absorbs it: about twice the published Fv
    assert base.parameters["viscous_friction"] > 1.5 * PUBLISHED["viscous_friction"]
    report = full.fit_report()
    assert "coulomb_friction" in report and "+/-" in report and "95% CI" in report


def _synthetic(params: dict, seed: int = 0, noise: float = 1.0, n: int = 20000, dt: float = 1e-3, vs: float = 0.02):
    """Multi-sine trajectory (analytic derivatives) and effort from known parameters + white noise."""
    rng = np.random.default_rng(seed)
    t = dt * np.arange(n)
    freqs, amps = np.array([0.2, 0.9, 2.3]), np.array([0.04, 0.006, 0.001])
    phases = rng.uniform(0, 2 * np.pi, 3)
    arg = 2 * np.pi * freqs[:, None] * t + phases[:, None]
    q = (amps[:, None] * np.sin(arg)).sum(0)
    v = (amps[:, None] * 2 * np.pi * freqs[:, None] * np.cos(arg)).sum(0)
    a = -(amps[:, None] * (2 * np.pi * freqs[:, None]) ** 2 * np.sin(arg)).sum(0)
    effort = (params.get("inertia", 0) * a + params.get("viscous_friction", 0) * v
              + params.get("coulomb_friction", 0) * np.sign(v) + params.get("effort_offset", 0)
              + params.get("stribeck_friction", 0) * np.exp(-(v / vs) ** 2) * np.sign(v))
    return Recording(name=f"synthetic{seed}", time_s=t, position=q, effort=effort + rng.normal(0, noise, n))


TRUE = {"inertia": 12.0, "viscous_friction": 80.0, "coulomb_friction": 6.0, "effort_offset": -1.5}


def test_synthetic_known_parameters_within_confidence():
    fit = identify_mechanical(_synthetic(TRUE), REFERENCE_TERMS)
    for key, value in TRUE.items():
        assert abs(fit.parameters[key] - value) < max(4 * fit.stderr[key], 0.02 * abs(value)), key
        assert abs(fit.parameters[key] - value) < 0.03 * abs(value), key
    assert fit.rmse == pytest.approx(1.0, rel=0.05)  # the injected white noise


def test_synthetic_two_recordings_share_parameters():
    recs = [_synthetic(TRUE, seed=1, n=8000), _synthetic(TRUE, seed=2, n=8000)]
    fit = identify_mechanical(recs, REFERENCE_TERMS)
    assert fit.n_samples > 15000
    for key, value in TRUE.items():
        assert abs(fit.parameters[key] - value) < 0.05 * abs(value), key


def test_stribeck_velocity_found_by_search():
    truth = dict(TRUE, stribeck_friction=4.0)
    fit = identify_mechanical(_synthetic(truth, noise=0.5, vs=0.02), REFERENCE_TERMS + ("stribeck_friction",))
    assert fit.parameters["stribeck_velocity"] == pytest.approx(0.02, rel=0.2)
    assert fit.parameters["stribeck_friction"] == pytest.approx(4.0, rel=0.15)
    assert "stribeck_velocity" not in fit.stderr


def test_subset_of_terms_and_rank_deficiency():
    rec = _synthetic(TRUE)
    only = identify_mechanical(rec, ("inertia", "effort_offset"))
    assert set(only.parameters) == {"inertia", "effort_offset"}
    still = Recording(name="still", time_s=np.arange(500) * 1e-3, position=np.zeros(500), effort=np.ones(500))
    bad = identify_mechanical(still, ("inertia", "viscous_friction"))
    assert not bad.success and bad.status == "rank_deficient"
    assert np.all(np.isfinite(list(bad.parameters.values())))
    with pytest.raises(InputError, match="unknown"):
        identify_mechanical(rec, ("inertia", "magic_friction"))


def test_stderr_matches_closed_form():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(200, 3))
    y = X @ [1.0, -2.0, 0.5] + rng.normal(0, 0.3, 200)
    fit = linear_fit(X, y, ("a", "b", "c"))
    p = np.linalg.solve(X.T @ X, X.T @ y)
    s2 = np.sum((y - X @ p) ** 2) / (200 - 3)
    expected = np.sqrt(np.diag(s2 * np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose([fit.stderr[k] for k in "abc"], expected, rtol=1e-9)
    np.testing.assert_allclose([fit.parameters[k] for k in "abc"], p, rtol=1e-9)


def test_torque_current_line_seed_report_eq9():
    """Seed report eq. 9: joint torque ≈ 11.06 N·m/A · i + 1.17 N·m."""
    rng = np.random.default_rng(4)
    current = rng.uniform(-5, 5, 3000)
    rec = Recording(name="tc", time_s=np.arange(3000) * 0.01, current_a=current,
                    effort=11.06 * current + 1.17 + rng.normal(0, 0.2, 3000))
    fit = identify_torque_current(rec)
    assert fit.parameters["effort_per_current"] == pytest.approx(11.06, abs=4 * fit.stderr["effort_per_current"])
    assert fit.parameters["effort_offset"] == pytest.approx(1.17, abs=4 * fit.stderr["effort_offset"])
    lo, hi = fit.confidence["effort_per_current"]
    assert lo < fit.parameters["effort_per_current"] < hi
    with pytest.raises(InputError, match="current_a"):
        identify_torque_current(Recording(name="x", time_s=[0.0, 1.0], effort=[0.0, 1.0]))
