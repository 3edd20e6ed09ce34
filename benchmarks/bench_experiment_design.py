"""Designed experiments against the report's protocol and a plain current-step test, at equal duration.

Cases: randomised three-node truths (``thermo_ddp.testing.testbed.truths.random_case``: values +-30 %, a random
concealed subset of friction heating, drive heating and a casing node, sensor noise, quantisation, drifting
room, jittered sampling, gaps; their sessions move at ONE speed) whose passive recording leaves a heat term
undetermined (the design has a target).  Each case adds one experiment of ``--duration-s`` to the passive
recording, run on the same truth, and diagnoses both together:

- ``designed``: ``design_experiment`` (the default settings, the elbow's 84 °C cut-off);
- ``sequential``: two rounds sharing the duration (``studies.experiment_loop.close_the_loop``, ``shared``): the
  first (half; all of it when nothing can be designed in half) designed for what the passive recording leaves
  open, run, diagnosed; the second designed for what is still open in what is left (none when nothing is), run,
  diagnosed with all;
- ``protocol``: the seed report's: move back and forth at the passive session's speed at 3 A for half the
  time, then hold still at the same current (the same RMS current);
- ``steps``: a plain current-step test at rest: 4 A and 0 A alternating every quarter.

Per method: the share of cases whose design targets alone are settled (``targets_settled_share``: each target
named exactly and its values within +-50 %), and the share with the exact term set named (the truth's concealed
set) AND every named parameter identifiable (95 % half-width <= 50 % of its value; a value the fit holds at the
parameter file's, the diagnosis's ``held``: the drive's i^2 loss, a drive node's ambient path, is not estimated,
not judged); the mean relative error of the friction-heat and drive-idle values named where the truth has them;
the peak true winding; the wall time of the design; the designs over the limit or the duration (must be 0).
"Identifiable" cases: those whose one-round design lists nothing ``not_determinable`` (the package's own rule,
stated before any run: a value of a named term that no start's design pins within +-50 % by its predicted
covariance); the shares are also given over them, with the cases left out and why.
Writes benchmarks/results/experiment_design.json.

Also issue 25's families (``truths.FAMILIES``: drive + friction heat seen only while moving, friction heat at one
speed, friction heat never excited, and a truth with nothing missing), summarised per family.

    python benchmarks/bench_experiment_design.py [--cases 12] [--first-case 0] [--family-seeds 1] [--workers 2]
                                                 [--duration-s 3600] [--from-log LOG --wall-s S]
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time

import numpy as np

from _common import machine, write

CASE_SEED, FAMILY_SEED = 90_000, 95_000
METHODS = ("designed", "sequential", "protocol", "steps")
UNSEEN_SPEED_RAD_S = 1.5   # the protocol's speed when the passive session never moved
LIMIT_C = 84.0             # the elbow file's cut-off: the designs' default limit


def protocol_inputs(duration_s: float, speed: float):
    t = np.arange(0.0, duration_s, 1.0)
    moving = t < duration_s / 2
    return t, np.full(t.size, 3.0), np.where(moving, speed * np.sign(np.sin(2 * np.pi * t / 20.0) + 1e-9), 0.0)


def step_inputs(duration_s: float):
    t = np.arange(0.0, duration_s, 1.0)
    return t, np.where((t // (duration_s / 4)) % 2 == 0, 4.0, 0.0), np.zeros(t.size)


def judge(truth, diagnosis) -> dict:
    from thermo_ddp.identify.thermal import FRICTION_KEYS
    out = diagnosis.to_dict()
    named = set(diagnosis.missing_physics)
    # values the fit holds at the parameter file's (the term's "held": the drive's i^2 loss, and a drive node's
    # ambient path) are not estimated, not claimed: not judged; every other named value is
    held = sorted({k for m in out["missing_physics"] for k in m.get("held", ())})
    loose = [k for m in out["missing_physics"] for k, v in m["parameters"].items() if k not in held
             and (k not in m["ci95"] or (m["ci95"][k][1] - m["ci95"][k][0]) / 2 > 0.5 * abs(v))]
    errors = []
    fit = diagnosis.final_fit.parameters if diagnosis.final_fit is not None else {}
    if "friction_heating" in named & truth.concealed:
        true = (truth.friction_linear_w_s_per_rad, truth.friction_quadratic_w_s2_per_rad2)
        errors += [abs(fit[k] - v) / v for k, v in zip(FRICTION_KEYS, true)]
    if "drive_heating" in named & truth.concealed and "drive_idle_w" in fit:
        errors.append(abs(fit["drive_idle_w"] - truth.drive_idle_w) / truth.drive_idle_w)
    exact = named == set(truth.concealed)
    return {"named": sorted(named), "exact": exact, "loose": loose, "held": held, "settled": exact and not loose,
            "errors": errors, "status": diagnosis.status}


def passive_case(family: str | None, seed: int):
    """(recording, truth): a random case, or the family's session (k = 0: the class truth, else randomised)."""
    from thermo_ddp.testing.testbed.truths import ThreeNodeTruth, family_case, random_case
    if family is None:
        return random_case(CASE_SEED + seed)
    rng = np.random.default_rng(FAMILY_SEED + seed)
    truth = ThreeNodeTruth().randomised(rng) if seed else None
    truth, rec = family_case(family, rng, truth)
    return rec, truth


def run_case(job: tuple[str | None, int, float]) -> dict:
    from thermo_ddp.diagnose.thermal import diagnose_thermal
    from thermo_ddp.tasks.experiment import ExperimentSettings, design_experiment
    from thermo_ddp.testing.testbed.truths import run_inputs, run_programme

    family, seed, duration_s = job
    rec, truth = passive_case(family, seed)
    before = diagnose_thermal(rec)
    out = {"family": family or "random", "seed": seed if family else CASE_SEED + seed,
           "concealed": sorted(truth.concealed), "named_before": before.missing_physics}
    tic = time.perf_counter()
    settings = ExperimentSettings(duration_s=duration_s, limit_c=LIMIT_C, progress=False)
    design = design_experiment([rec], settings=settings, diagnosis=before)
    out |= {"design_status": design.status, "targets": list(design.targets), "design_s": time.perf_counter() - tic,
            "duration_s": duration_s, "not_determinable": design.to_dict()["not_determinable"]}
    if not design.designed:
        return out
    moving = np.abs(rec.velocity[np.abs(rec.velocity) > 0.05])
    speed = float(np.median(moving)) if moving.size else UNSEEN_SPEED_RAD_S
    measurement = {"noise_c": 0.05, "sample_s": 2.0}
    rng = np.random.default_rng(seed)
    runs = {"designed": run_programme(truth, design.programme(), rng, "designed", **measurement),
            "protocol": run_inputs(truth, rng, *protocol_inputs(duration_s, speed), "protocol", **measurement),
            "steps": run_inputs(truth, rng, *step_inputs(duration_s), "steps", **measurement)}
    for method, (run, temps) in runs.items():
        out[method] = judge(truth, diagnose_thermal([rec, run])) | {"peak_winding_c": float(temps[:, 0].max()),
                                                                  "duration_s": float(run.time_s[-1])}
    out["design_peak_winding_c"] = design.peak_winding_c
    return out | {"sequential": sequential(rec, truth, before, settings, seed, measurement)}


def sequential(rec, truth, before, settings, seed: int, measurement: dict) -> dict:
    """Two rounds of half the duration (``close_the_loop``), judged on its final diagnosis."""
    from thermo_ddp.studies.experiment_loop import close_the_loop
    loop = close_the_loop([rec], truth, rounds=2, settings=settings, seed=seed, diagnosis=before, shared=True,
                          **measurement)
    ran = [r for r in loop.rounds if r.true_peak_winding_c is not None]
    return judge(truth, loop.final) | {"peak_winding_c": max((r.true_peak_winding_c for r in ran), default=None),
                                       "duration_s": sum(r.design.duration_s for r in ran), "rounds": len(ran),
                                       "round_designs": [{"status": r.design.status, "targets": list(r.design.targets)}
                                                         for r in loop.rounds]}


def targets_settled(case: dict, method: str) -> bool:
    """The design's target terms alone: each named exactly when the truth has it, and then its values within +-50 %
    (what the design aims at; the full ``settled`` also judges the other named terms' values)."""
    from thermo_ddp.diagnose._thermal_terms import term_keys
    judged = case[method]
    named = judged["named"]
    return all((t in named) == (t in case["concealed"]) and not (t in named and set(term_keys(t, named))
                                                                   & set(judged["loose"])) for t in case["targets"])


def shares(done: list[dict], m: str) -> dict:
    """The method's shares over the cases ``done`` (None: no case)."""
    def share(values):
        return float(np.mean(values)) if done else None
    return {"settled_share": share([c[m]["settled"] for c in done]),
            "targets_settled_share": share([targets_settled(c, m) for c in done]),
            "exact_share": share([c[m]["exact"] for c in done])}


def summary(cases: list[dict]) -> dict:
    done = [c for c in cases if "designed" in c]
    identifiable = [c for c in done if not c["not_determinable"]]
    out = {"cases_drawn": len(cases), "cases_with_targets": len(done),
           "nothing_missing_named_nothing": [c["design_status"] == "nothing_undetermined" and not c["named_before"]
                                             for c in cases if c["family"] == "nothing_missing"],
           "design_statuses": {s: sum(c["design_status"] == s for c in cases)
                               for s in sorted({c["design_status"] for c in cases})}}
    for m in METHODS:
        errors = [e for c in done for e in c[m]["errors"]]
        out[m] = shares(done, m) | {"identifiable": shares(identifiable, m),
                                    "mean_parameter_error": float(np.mean(errors)) if errors else None,
                                    "max_peak_winding_c": max((c[m]["peak_winding_c"] for c in done
                                                               if c[m]["peak_winding_c"] is not None), default=None)}
    out["identifiable_cases"] = len(identifiable)
    out["not_identifiable"] = {c["seed"]: [u["key"] for u in c["not_determinable"]] for c in done
                               if c["not_determinable"]}
    out["median_design_s"] = float(np.median([c["design_s"] for c in done])) if done else None
    # safety: the truth's winding over the limit, or a designed run longer than requested (both must be 0)
    for m in ("designed", "sequential"):
        out[f"{m}_over_limit"] = sum((c[m]["peak_winding_c"] or -np.inf) > LIMIT_C for c in done)
        out[f"{m}_over_duration"] = sum(c[m]["duration_s"] > c["duration_s"] for c in done)
    return out


def run_cases(args) -> list[dict]:
    """Every case of the request, each printed to stderr as it ends (a long run's progress)."""
    from thermo_ddp.testing.testbed.truths import FAMILIES
    jobs = [(f, k, args.duration_s) for f in FAMILIES for k in range(args.family_seeds)]
    jobs += [(None, k, args.duration_s) for k in range(args.first_case, args.first_case + args.cases)]
    cases = []
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        for case in pool.imap(run_case, jobs, chunksize=1):
            cases.append(case)
            print(json.dumps(case), file=sys.stderr, flush=True)
    return cases


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", type=int, default=12)
    parser.add_argument("--first-case", type=int, default=0, help="the first random seed (after 90000); other than 0, "
                        "the JSON is experiment_design_from_<first>.json (more cases beside the main run)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--family-seeds", type=int, default=1, help="cases per family of issue 25 (the first: the "
                        "class truth of tests/test_experiment_design.py, the others randomised)")
    parser.add_argument("--duration-s", type=float, default=3600.0)
    parser.add_argument("--from-log", help="summarise the cases a run printed (its stderr, one JSON line per case: a "
                        "run stopped early) instead of running; with --wall-s, the wall time measured outside")
    parser.add_argument("--wall-s", type=float)
    args = parser.parse_args()
    from thermo_ddp.testing.testbed.truths import FAMILIES
    start = time.perf_counter()
    if args.from_log:
        with open(args.from_log) as log:
            cases = [json.loads(line) for line in log if line.startswith("{")]
    else:
        cases = run_cases(args)
    payload = {"summary": summary([c for c in cases if c["family"] == "random"]),
               "families": {f: summary([c for c in cases if c["family"] == f]) for f in FAMILIES
                            if any(c["family"] == f for c in cases)},
               "cases": cases, "duration_s": args.duration_s, "workers": args.workers,
               "wall_s": args.wall_s if args.from_log else time.perf_counter() - start, "machine": machine(),
               "from_log": args.from_log}
    write("experiment_design" + (f"_from_{args.first_case}" if args.first_case else ""), payload)
    print(json.dumps({"random": payload["summary"], "families": payload["families"]}, indent=2))


if __name__ == "__main__":
    main()
