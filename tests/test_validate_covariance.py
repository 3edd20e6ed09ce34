"""The parameter file's [covariance] (the fit's joint uncertainty of its [uncertainty] values): read and checked,
written by identify, and validate's band_k over its 95 % ellipsoid, against known parameters of a synthetic
three-node motor (simulated exactly, matrix exponential), Monte Carlo over the covariance, and the box rule."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.stats import chi2

from test_validate_scope import AMBIENT, R_OHM, THERMAL, _params
from thermo_ddp.errors import InputError
from thermo_ddp.identify.thermal_data import ThermalSettings
from thermo_ddp.identify.thermal_files import identify_network_files
from thermo_ddp.model.parameters import dumps_parameters, parameters_from_dict
from thermo_ddp.model.scope import Covariance
from thermo_ddp.recordings import Recording
from thermo_ddp.validate import validate_thermal

TIME_S = np.arange(0.0, 3601.0)
CURRENT_A = 12.0 + 6.0 * np.sign(np.sin(2 * np.pi * TIME_S / 900.0))
NODES = ("winding", "tooth", "yoke")
LINKS = ("winding-tooth", "tooth-yoke", "yoke-ambient")
PATHS = (*(f"thermal.node.{n}.capacity_j_per_k" for n in NODES), *(f"thermal.link.{k}.resistance_k_per_w" for k in LINKS),
         "thermal.source.constant.power_w", "thermal.source.constant.split.yoke")


def simulate(theta: np.ndarray) -> np.ndarray:
    """Every node (motors x samples x 3) of the chain winding - tooth - yoke - ambient for the values ``theta``
    (motors x PATHS: capacities, resistances, the constant heat and its yoke share; copper R i^2 in the
    winding), by the exact zero-order-hold step, written here (not with the library)."""
    cap, g, power, share = theta[:, :3], 1 / theta[:, 3:6], theta[:, 6], theta[:, 7]
    a = np.zeros((theta.shape[0], 3, 3))
    for i, j, k in ((0, 1, 0), (1, 2, 1)):
        a[:, i, j] = a[:, j, i] = g[:, k]
    a[:, 0, 0], a[:, 1, 1], a[:, 2, 2] = -g[:, 0], -g[:, 0] - g[:, 1], -g[:, 1] - g[:, 2]
    a /= cap[:, :, None]
    step = np.array([expm(m) for m in a])
    gain = np.array([np.linalg.solve(m, s - np.eye(3)) for m, s in zip(a, step)])
    x, out = np.full((theta.shape[0], 3), AMBIENT), []
    for current in CURRENT_A:
        out.append(x)
        heat = np.stack([np.full(len(x), R_OHM * current ** 2), power * (1 - share), power * share + g[:, 2] * AMBIENT], 1)
        x = np.einsum("sij,sj->si", step, x) + np.einsum("sij,sj->si", gain, heat / cap)
    return np.stack(out, 1)


def truth(tooth_capacity=400.0, pump_w=20.0) -> np.ndarray:
    return np.array([200.0, tooth_capacity, 800.0, 0.5, 0.3, 0.4, pump_w, 0.5])


def recording(nodes: np.ndarray, noise_c: float, sensors=("tooth", "yoke"), seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    read = {n: nodes[:, i] + noise_c * rng.standard_normal(TIME_S.size) for i, n in enumerate(NODES)}
    return Recording("synthetic", TIME_S, current_a=CURRENT_A, temperature_c=read["winding"],
                     ambient_c=np.full_like(TIME_S, AMBIENT), sensors={n: read[n] for n in sensors})


def identified(start, rec: Recording):
    out = identify_network_files(start, [rec], ThermalSettings(min_step_s=10.0, max_step_s=10.0))
    assert out["success"]
    return parameters_from_dict(out["parameter_file"], "identified.toml")


def without_covariance(params):
    return dataclasses.replace(params, scope=dataclasses.replace(params.scope, covariance=None))


def test_identify_writes_the_covariance_and_the_file_reads_it_back():
    params = identified(_params(), recording(simulate(truth()[None])[0], 0.3))
    cov = params.scope.covariance
    assert set(cov.paths) == set(params.scope.uncertainty) == set(PATHS)  # every value pinned down here
    assert cov.scale == tuple("linear" if "source" in p else "log" for p in cov.paths)
    for path, var in zip(cov.paths, np.diag(cov.array)):  # the interval's width is +-1.96 sigma (unclipped)
        lo, hi = params.scope.uncertainty[path]
        width = np.log(hi / lo) if "source" not in path else hi - lo
        assert width == pytest.approx(2 * 1.959964 * np.sqrt(var), rel=0.05)  # marginal >= conditional, close here
    back = parameters_from_dict(__import__("tomllib").loads(dumps_parameters(params)), "back.toml")
    assert back.scope.covariance == cov
    assert params.replace("motor", resistance_ohm=0.21).scope.covariance == cov  # no interval: nothing to drop
    pair = Covariance.of(["a", "b"], ["log", "log"], [[0.04, -0.018], [-0.018, 0.09]])  # sd 0.2, 0.3, rho -0.3
    held = pair.restricted(["a"])  # b now held as written: a's variance given b, sd_a^2 (1 - rho^2)
    assert held.paths == ("a",) and held.array[0, 0] == pytest.approx(0.04 * (1 - 0.3 ** 2))
    data = params.to_dict()
    bad = {"paths": lambda c: c | {"paths": c["paths"][:-1]}, "scale": lambda c: c | {"scale": ["cubic"] * len(c["paths"])},
           "matrix": lambda c: c | {"matrix": [[-v for v in r] for r in c["matrix"]]},
           "symmetric": lambda c: c | {"matrix": [[v + (i < j) * 1e-3 for j, v in enumerate(r)] for i, r in enumerate(c["matrix"])]},
           "covariance.extra": lambda c: c | {"extra": 1}}
    for field, change in bad.items():
        with pytest.raises(InputError, match=field):
            parameters_from_dict(data | {"covariance": change(data["covariance"])}, "bad.toml")


def test_the_band_over_the_ellipsoid_covers_the_truth_and_matches_monte_carlo():
    """Three sensors, 0.3 K noise: the file's prediction of the noise-free truth lies within its band; the
    band is within a factor 2 of the spread of the predictions of 300 motors drawn from the fit's covariance
    (inside its 95 % ellipsoid, simulated exactly) and narrower than the band of independent intervals."""
    nodes = simulate(truth()[None])[0]
    params = identified(_params(), recording(nodes, 0.3))
    clean = recording(nodes, 0.0)
    result = validate_thermal([clean], params)
    assert result.band_basis == "covariance" and result.to_dict()["band_basis"] == "covariance"
    error = np.abs(result.predictions[0].predicted_c - nodes[:, 0])
    assert 0.02 < error.max() <= result.band_k / 2
    cov = params.scope.covariance
    theta = np.array([float(params.value(p)) for p in PATHS])
    order = [cov.paths.index(p) for p in PATHS]
    c = cov.array[np.ix_(order, order)]
    z = np.random.default_rng(1).multivariate_normal(np.zeros(len(PATHS)), c, size=320)
    z = z[np.einsum("si,ij,sj->s", z, np.linalg.inv(c), z) <= chi2.ppf(0.95, len(PATHS))]
    log = np.array([np.array(cov.scale)[order] == "log"]).ravel()
    motors = np.where(log, theta * np.exp(z), theta + z)
    winding = simulate(motors)[:, :, 0]
    monte_carlo = float(np.max(winding.max(axis=0) - winding.min(axis=0)))
    assert monte_carlo < result.band_k < 2 * monte_carlo
    independent = validate_thermal([clean], without_covariance(params))
    assert independent.band_basis == "independent" and independent.band_k > 2 * result.band_k
    assert "assumes its values' errors independent" in independent.report()


def test_two_resistances_in_series_whose_sum_is_pinned():
    """Winding and yoke measured, the tooth between them light: the fit pins the sum of the winding - tooth
    and tooth - yoke resistances better than either (their errors anti-correlated); the band that knows it is
    a small fraction of the band of independent intervals, and covers the truth."""
    theta = truth(tooth_capacity=150.0, pump_w=0.0)
    nodes = simulate(theta[None])[0]
    start = parameters_from_dict(_params().to_dict() | {"thermal": THERMAL | {"source": THERMAL["source"][:1]}}, "t")
    start = start.with_values({"thermal.node.tooth.capacity_j_per_k": 150.0}).checked()
    params = identified(start, recording(nodes, 0.1, sensors=("yoke",)))
    cov = params.scope.covariance
    i, j = (cov.paths.index(f"thermal.link.{k}.resistance_k_per_w") for k in LINKS[:2])
    sd = np.sqrt(np.diag(cov.array))
    assert cov.array[i, j] / (sd[i] * sd[j]) < -0.8
    clean = recording(nodes, 0.0, sensors=("yoke",))
    result = validate_thermal([clean], params)
    independent = validate_thermal([clean], without_covariance(params))
    assert result.band_k < independent.band_k / 10
    assert np.abs(result.predictions[0].predicted_c - nodes[:, 0]).max() <= result.band_k / 2
