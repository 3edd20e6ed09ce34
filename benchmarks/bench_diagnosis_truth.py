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

    python benchmarks/bench_diagnosis_truth.py [--cases 200] [--workers 2]
"""
from __future__ import annotations

import argparse
import multiprocessing
import time

import numpy as np

from _common import RESULTS, write
from thermo_ddp.diagnose.thermal import CANDIDATE_TERMS

CASE_SEED = 50_000


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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    start = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        cases = pool.map(run_case, range(args.cases), chunksize=1)
    matrix = confusion(cases)
    concealed = sum(m["true_positive"] + m["false_negative"] for m in matrix.values())
    absent = sum(m["false_positive"] + m["true_negative"] for m in matrix.values())
    payload = {
        "cases": cases, "n_cases": len(cases),
        "detection_rate": sum(m["true_positive"] for m in matrix.values()) / max(concealed, 1),
        "false_alarm_rate": sum(m["false_positive"] for m in matrix.values()) / max(absent, 1),
        "exact_rate": float(np.mean([set(c["found"]) == set(c["concealed"]) for c in cases])),
        "confusion": matrix,
        "status_counts": {s: sum(c["status"] == s for c in cases) for s in sorted({c["status"] for c in cases})},
        "median_diagnose_s": float(np.median([c["diagnose_s"] for c in cases])),
        "wall_s": time.perf_counter() - start, "workers": args.workers,
    }
    write("diagnosis_truth", payload)
    plot(matrix, RESULTS / "diagnosis_truth.png")
    print({k: v for k, v in payload.items() if k != "cases"})


if __name__ == "__main__":
    main()
