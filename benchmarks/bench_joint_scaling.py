"""DDP solve time from 1 to 7 joints on the same hold problem (thermal limits present), N = 100.

Problem (thermo_ddp.tasks.whole_arm.build_hold_problem): from the hanging posture to the naive posture (forearm
horizontal by the elbow, every other joint at 0) with 40 kg at the gripper in 0.8 s, then hold it 0.8 s;
per joint: winding_limit (84 °C), bus_voltage, joint_range, joint_velocity, current box; the task-space
hold_band. RK4 at dt = 0.016 s (stable for 7 joints: |lambda|max ~ 110 /s), N = 100. Joint sets by name:
1: elbow; 2: shoulder (arm_left_2) + elbow; 4: arm_left_1..4; 7: the whole left arm.

For each set and DDP mode (Gauss-Newton iLQR and full second-order DDP), the codegen backend: build
(symbolic knot functions, C generation, gcc: one file per knot function, compiled in parallel; run the
benchmark with an empty cache, THERMO_DDP_CACHE=$(mktemp -d), for build times from scratch), then
``--repeats`` cold solves from the same initial guess; per-iteration time = solve time / iterations,
medians over the repeats. ``--baseline FILE``: an earlier run's JSON (e.g. the whole-horizon mapaccum
code of commit 41709c8) whose build and per-iteration figures are copied beside each case, with ratios.

Usage: python benchmarks/bench_joint_scaling.py [--repeats 5] [--joints 1 2 4 7] [--baseline old.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

from _common import write

from thermo_ddp.model.arm import ELBOW, LEFT_ARM
from thermo_ddp.solvers import DDPSettings, DDPSolver
from thermo_ddp.tasks.whole_arm import WholeArmSettings, build_hold_problem, initial_guess, prepare

JOINT_SETS = {1: (ELBOW,), 2: ("arm_left_2_joint", ELBOW), 4: LEFT_ARM[:4], 7: LEFT_ARM}
DT_S, MOVE_S, HOLD_S = 0.016, 0.8, 0.8


def bench_case(joints, full: bool, repeats: int) -> dict:
    s = WholeArmSettings(joints=joints, hold_s=HOLD_S, move_s=MOVE_S, posture_choice="naive", dt_s=DT_S)
    model, _, chosen, target, dt = prepare(s)
    hp = build_hold_problem(model, s, chosen.q_rad, target, dt)
    start = time.perf_counter()
    solver = DDPSolver(hp.problem, DDPSettings(full_second_order=full, backend="codegen", max_iterations=300))
    build_s = time.perf_counter() - start
    guess = initial_guess(hp)
    runs = [solver.solve(hp.x0, hp.params, guess) for _ in range(repeats)]
    last = runs[-1]
    per_iter = [r.solve_s / max(r.iterations, 1) for r in runs]
    per_pass = [r.solve_s / max(r.info.get("backward_passes", 1), 1) for r in runs]
    return {"joints": list(joints), "nx": hp.problem.nx, "nu": hp.problem.nu, "N": hp.problem.horizon,
            "mode": "full_ddp" if full else "gauss_newton", "status": last.status, "success": bool(last.success),
            "iterations": int(last.iterations), "backward_passes": int(last.info.get("backward_passes", 0)),
            "max_constraint_violation": float(last.max_constraint_violation),
            "peak_winding_c": float(last.xs[:, [model.index(j, "winding_c") for j in model.joints]].max()),
            "build_s": build_s, "solve_median_s": statistics.median(r.solve_s for r in runs),
            "per_iteration_median_s": statistics.median(per_iter),
            "per_backward_pass_median_s": statistics.median(per_pass), "repeats": repeats}


def _baseline(path) -> dict:
    """(joint count, mode) -> the earlier run's case."""
    if path is None:
        return {}
    return {(len(c["joints"]), c["mode"]): c for c in json.loads(open(path).read())["cases"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--joints", type=int, nargs="*", default=list(JOINT_SETS), choices=list(JOINT_SETS))
    ap.add_argument("--baseline", help="an earlier run's JSON: its figures are copied beside each case")
    ap.add_argument("--baseline-label", default="whole-horizon mapaccum C (commit 41709c8)")
    args = ap.parse_args()
    baseline = _baseline(args.baseline)
    rows = []
    for n in args.joints:
        for full in (False, True):
            row = bench_case(JOINT_SETS[n], full, args.repeats)
            old = baseline.get((n, row["mode"]))
            if old is not None:
                row["baseline"] = {k: old[k] for k in ("build_s", "per_iteration_median_s", "iterations", "status")}
                row["per_iteration_ratio_to_baseline"] = row["per_iteration_median_s"] / old["per_iteration_median_s"]
            rows.append(row)
            print(f"{n} joints {row['mode']:>12}: {row['status']:>22} {row['iterations']:4d} it, "
                  f"{1e3 * row['per_iteration_median_s']:8.2f} ms/it, {row['solve_median_s']:7.3f} s, "
                  f"build {row['build_s']:.1f} s", flush=True)
    base = {r["mode"]: r["per_iteration_median_s"] for r in rows if len(r["joints"]) == 1}
    for r in rows:
        ratio = r["per_iteration_median_s"] / base[r["mode"]] if r["mode"] in base else None
        r["per_iteration_ratio_to_1_joint"] = ratio
    write("joint_scaling", {"problem": __doc__.split("\n\n")[1], "dt_s": DT_S, "move_s": MOVE_S, "hold_s": HOLD_S,
                            "baseline": args.baseline_label if baseline else None, "cases": rows})


if __name__ == "__main__":
    main()
