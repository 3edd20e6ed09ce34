"""Diagnosis against truths it does not share: detection and false-alarm rates, per-term confusion.

Each case is a randomised three-node truth (``thermo_ddp.testing.testbed.truths``: its own numpy
network and matrix-exponential integrator, friction heat split between winding and casing, a drive
node losing heat to casing and ambient; values +-30 %), a random concealed subset of
friction_heating / drive_heating / casing_node (none included), sensor noise 0.02-0.1 K,
quantisation 0 / 0.0625 / 0.1 K, drifting room (up to 2 K), 1-5 s jittered sampling, gaps.
``diagnose_thermal`` runs with the full candidate library; copper_resistance and iron_losses are
never concealed, so naming them is always a false alarm.

detection_rate = named concealed terms / concealed terms; false_alarm_rate = named absent terms /
absent (case, term) pairs over all five candidates.  A case whose status is not ``ok`` counts with
the terms it named.  Writes benchmarks/results/diagnosis_truth.json and diagnosis_truth.png.

Network truths (``--network-per-family N``): randomised multi-sensor truths of three families
(``thermo_ddp.testing.testbed.truths.NetworkTruth``, its own numpy network and matrix-exponential
integrator on a 1 s step; values +-30 %, iron-loss exponent 1.2-2.2): ``chain3`` (winding - tooth - yoke -
coolant, copper heat only), ``chain3_iron`` (+ iron losses shared by tooth and yoke), ``rotor4_iron`` (+ an
unmeasured rotor coupled to the tooth and the coolant, hosting part of the iron losses).  Three sensors
(0.05 K noise, 2 s sampling), 1.5 h at speeds up to 400 rad/s, 25 °C coolant; ``diagnose_thermal`` starts from
the packaged Paderborn file (one node, copper; the motor can have copper, iron losses, friction heating).
Detection: iron_losses named / truths with iron losses; false alarms: heat kinds named that the truth lacks
(iron_losses in chain3, friction_heating and ac_copper anywhere) / such (case, kind) pairs.  Unseen regime: a second
recording of the same truth at 500-600 rad/s and a 45 °C coolant predicted (no refit, from its first
readings) by the improved file and by the plain refit (the file's one node refitted on the training data):
winding RMSE of each.  ``--cases 0`` keeps the three-node results already in the JSON.

    python benchmarks/bench_diagnosis_truth.py [--cases 200] [--network-per-family 4] [--workers 2]
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import time

import numpy as np

from _common import RESULTS, write
from thermo_ddp.diagnose.thermal import CANDIDATE_TERMS

CASE_SEED = 50_000
HEAT_TERMS = ("iron_losses", "friction_heating", "ac_copper")  # heat kinds of the Paderborn file the growth may name
NETWORK_SEED = 70_000


def run_case(seed: int) -> dict:
    from thermo_ddp.diagnose.thermal import diagnose_thermal
    from thermo_ddp.testing.testbed.truths import random_case

    rec, truth = random_case(CASE_SEED + seed)
    start = time.perf_counter()
    d = diagnose_thermal(rec)
    return {"seed": CASE_SEED + seed, "concealed": sorted(truth.concealed), "found": d.missing_physics,
            "status": d.status, "samples": len(rec), "duration_s": float(rec.time_s[-1] - rec.time_s[0]),
            "rmse_c": d.final_fit.rmse if d.final_fit is not None else None,
            "noise_ratio": d.noise.rmse_ratio if d.noise is not None else None,
            "not_determinable": [n["term"] for n in d.not_determinable], "diagnose_s": time.perf_counter() - start}


def confusion(cases: list[dict]) -> dict:
    out = {}
    for term in CANDIDATE_TERMS:
        truth = np.array([term in c["concealed"] for c in cases])
        found = np.array([term in c["found"] for c in cases])
        out[term] = {"true_positive": int(np.sum(truth & found)), "false_negative": int(np.sum(truth & ~found)),
                     "false_positive": int(np.sum(~truth & found)), "true_negative": int(np.sum(~truth & ~found))}
    return out


def plot(matrix: dict, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    terms = list(matrix)
    fig, axes = plt.subplots(1, len(terms), figsize=(3.2 * len(terms), 3.2))
    for ax, term in zip(axes, terms):
        m = matrix[term]
        grid = np.array([[m["true_positive"], m["false_negative"]], [m["false_positive"], m["true_negative"]]])
        ax.imshow(grid, cmap="Blues")
        for (r, c), v in np.ndenumerate(grid):
            ax.text(c, r, str(v), ha="center", va="center", fontsize=12)
        ax.set_xticks([0, 1], ["named", "not named"])
        ax.set_yticks([0, 1], ["concealed", "absent"])
        ax.set_title(term, fontsize=10)
    fig.suptitle("diagnosis on randomised three-node truths: per-term confusion")
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def run_network_case(job: tuple[str, int]) -> dict:
    from thermo_ddp.diagnose.thermal import ThermalDiagnosisSettings, diagnose_thermal
    from thermo_ddp.identify.network_fit import fit_network
    from thermo_ddp.identify.thermal_data import thermal_grid
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file
    from thermo_ddp.testing.testbed.truths import network_case

    family, seed = job
    params = load_parameters(packaged_parameter_file("paderborn_pmsm"))
    train, unseen, truth = network_case(seed, family)
    start = time.perf_counter()
    d = diagnose_thermal([train], parameters=params)
    grid = thermal_grid(unseen, params, ThermalDiagnosisSettings().fit)

    def unseen_rmse(fit) -> float:
        return fit_network(params, fit.spec, fit.sensor, (), [grid]).rmse("winding")

    named = sorted({s.addition.term for s in d.steps if s.addition.term in HEAT_TERMS})
    return {"family": family, "seed": seed, "truth_iron": truth.iron, "named": named, "status": d.status,
            "nodes": list(d.final.spec.node_names), "added": [s.addition.label for s in d.steps],
            "alternatives": [a["terms"][0] for a in d.alternatives],
            "rmse_c": d.final.per_sensor(), "unseen_rmse_improved_c": unseen_rmse(d.final),
            "unseen_rmse_plain_refit_c": unseen_rmse(d.baseline), "diagnose_s": time.perf_counter() - start}


def network_summary(cases: list[dict]) -> dict:
    with_iron = [c for c in cases if c["truth_iron"]]
    absent = [(c, term) for c in cases for term in ("friction_heating", "ac_copper")]
    absent += [(c, "iron_losses") for c in cases if not c["truth_iron"]]
    families = {}
    for family in sorted({c["family"] for c in cases}):
        mine = [c for c in cases if c["family"] == family]
        families[family] = {
            "cases": len(mine), "ok": sum(c["status"] == "ok" for c in mine),
            "iron_named": sum("iron_losses" in c["named"] for c in mine),
            "median_nodes": float(np.median([len(c["nodes"]) for c in mine])),
            "median_unseen_rmse_improved_c": float(np.median([c["unseen_rmse_improved_c"] for c in mine])),
            "median_unseen_rmse_plain_refit_c": float(np.median([c["unseen_rmse_plain_refit_c"] for c in mine])),
            "improved_no_worse": sum(c["unseen_rmse_improved_c"] <= c["unseen_rmse_plain_refit_c"] for c in mine)}
    return {"n_cases": len(cases),
            "detection_rate": sum("iron_losses" in c["named"] for c in with_iron) / max(len(with_iron), 1),
            "false_alarm_rate": sum(term in c["named"] for c, term in absent) / max(len(absent), 1),
            "families": families, "median_diagnose_s": float(np.median([c["diagnose_s"] for c in cases]))}


def three_node(cases: list[dict], workers: int, wall_s: float) -> dict:
    matrix = confusion(cases)
    concealed = sum(m["true_positive"] + m["false_negative"] for m in matrix.values())
    absent = sum(m["false_positive"] + m["true_negative"] for m in matrix.values())
    plot(matrix, RESULTS / "diagnosis_truth.png")
    return {
        "cases": cases, "n_cases": len(cases),
        "detection_rate": sum(m["true_positive"] for m in matrix.values()) / max(concealed, 1),
        "false_alarm_rate": sum(m["false_positive"] for m in matrix.values()) / max(absent, 1),
        "exact_rate": float(np.mean([set(c["found"]) == set(c["concealed"]) for c in cases])),
        "confusion": matrix,
        "status_counts": {s: sum(c["status"] == s for c in cases) for s in sorted({c["status"] for c in cases})},
        "median_diagnose_s": float(np.median([c["diagnose_s"] for c in cases])),
        "wall_s": wall_s, "workers": workers,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", type=int, default=200)
    parser.add_argument("--network-per-family", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    from thermo_ddp.testing.testbed.truths import NETWORK_FAMILIES
    path = RESULTS / "diagnosis_truth.json"
    payload = json.loads(path.read_text()) if path.exists() else {}
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        if args.cases:
            start = time.perf_counter()
            cases = pool.map(run_case, range(args.cases), chunksize=1)
            payload |= three_node(cases, args.workers, time.perf_counter() - start)
        if args.network_per_family:
            start = time.perf_counter()
            jobs = [(f, NETWORK_SEED + k) for k in range(args.network_per_family) for f in NETWORK_FAMILIES]
            cases = []
            for case in pool.imap_unordered(run_network_case, jobs, chunksize=1):  # written as they come (long runs)
                cases.append(case)
                payload["network"] = {**network_summary(cases), "cases": cases, "planned": len(jobs),
                                      "wall_s": time.perf_counter() - start, "workers": args.workers}
                write("diagnosis_truth", payload)
    write("diagnosis_truth", payload)
    print({k: v for k, v in payload.items() if k not in ("cases", "network", "confusion")})
    print({k: v for k, v in payload.get("network", {}).items() if k != "cases"})


if __name__ == "__main__":
    main()
