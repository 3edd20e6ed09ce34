"""The warm MPC step of DDP alone, this checkout against another one, alternated (issue 23: "no worse").

The controller's problem of bench_mpc_step (rk4, N = 200, careful motion on and off, 140 / 94 °C) over the same
30-step closed loop; each step solved ``--repeats`` times, its fastest solve kept (the least disturbed, as ``timeit``
advises on a shared machine; the median of the repeats is recorded too), the median over the loop per case.
The two checkouts run in turn in fresh processes (``--rounds`` each, alternated, so a noisy minute hits both);
reported: per case the median over the rounds and the ratio this / baseline. DDP only (bench_mpc_step times
IPOPT and fatrop too, for minutes per run), so the rounds are short and many.

    python benchmarks/bench_mpc_step_versions.py --baseline /path/to/other/checkout [--rounds 6] [--repeats 7]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _common import write

HERE = Path(__file__).resolve().parent
STEPS = 30
CASES = [(careful, limit) for careful in (True, False) for limit in (140.0, 94.0)]


def case_name(careful: bool, limit_c: float) -> str:
    return f"careful_{'on' if careful else 'off'}_{limit_c:g}c"


def loop_medians(repeats: int) -> dict:
    """In this process (the checkout on sys.path): per case, the median over the loop of each step's fastest wall
    (``<case>``) and of its median wall (``<case>_median_of_repeats``)."""
    import bench_mpc_step as b
    from thermo_ddp.mpc.controller import free_present, mpc_ddp_settings
    from thermo_ddp.tasks.attempts import SolverLadder
    from thermo_ddp.tasks.lift import initial_guess, make_solver
    out = {}
    for careful, limit in CASES:
        lp = b.controller_problem(limit, careful, "rk4")
        solver = make_solver(lp, "ddp", mpc_ddp_settings(b.CONTROLLER.controller.max_iterations))
        lp = dataclasses.replace(lp, params=free_present(lp.params, lp.problem.parameters))
        prev = SolverLadder(lp.problem, make_solver(lp, "ddp", mpc_ddp_settings(b.COLD_ITERATIONS))).solve(
            lp, initial_guess(lp), reference=False).result
        params_all = np.vstack([lp.params, np.repeat(lp.params[-1:], STEPS, axis=0)])
        rng, x, fastest, walls = np.random.default_rng(0), lp.x0, [], []
        for j in range(1, STEPS + 1):
            x = np.asarray(lp.problem.functions.step(x, prev.us[0], params_all[j - 1])).ravel()
            x[1] += b.VELOCITY_DISTURBANCE * rng.standard_normal()
            params = free_present(params_all[j: j + b.KNOTS + 1], lp.problem.parameters)
            warm = b.warm_start("ddp", prev, lp.problem)
            samples = []
            for _ in range(repeats):
                start = time.perf_counter()
                result = solver.solve(x, params, warm)
                samples.append(time.perf_counter() - start)
            fastest.append(min(samples))
            walls.append(statistics.median(samples))
            prev = result
        out[case_name(careful, limit)] = statistics.median(fastest)
        out[f"{case_name(careful, limit)}_median_of_repeats"] = statistics.median(walls)
    return out


def run_checkout(root: Path, repeats: int) -> dict:
    """:func:`loop_medians` in a fresh process on the checkout at ``root`` (its src/ and benchmarks/)."""
    env = {**os.environ, "PYTHONPATH": f"{root / 'src'}{os.pathsep}{root / 'benchmarks'}"}
    code = f"import json, sys; sys.path.append({str(HERE)!r}); import bench_mpc_step_versions as v; " \
           f"print(json.dumps(v.loop_medians({repeats})))"
    done = subprocess.run([sys.executable, "-c", code], cwd=root / "benchmarks", env=env, capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, type=Path, help="another checkout of thermo-ddp (its root)")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    if not (args.baseline / "src" / "thermo_ddp").is_dir():
        sys.exit(f"--baseline: {args.baseline} is not a thermo-ddp checkout (no src/thermo_ddp)")
    this = HERE.parent
    runs = {"this": [], "baseline": []}
    for k in range(args.rounds):
        for label, root in (("baseline", args.baseline), ("this", this)):
            runs[label].append(run_checkout(root, args.repeats))
            print(f"round {k + 1}/{args.rounds} {label}: " + ", ".join(
                f"{c} {1e3 * runs[label][-1][c]:.3f} ms" for c in map(lambda cl: case_name(*cl), CASES)), flush=True)
    cases = {}
    for careful, limit in CASES:
        name = case_name(careful, limit)
        this_s, base_s = (statistics.median(r[name] for r in runs[label]) for label in ("this", "baseline"))
        cases[name] = {"this_median_s": this_s, "baseline_median_s": base_s, "ratio_this_over_baseline": this_s / base_s}
        print(f"  {name}: this {1e3 * this_s:.3f} ms, baseline {1e3 * base_s:.3f} ms, ratio {this_s / base_s:.3f}")
    write("mpc_step_versions", {"description": "DDP's warm MPC step (controller's rk4 problem, N = 200), this "
                                               "checkout against a baseline, alternated rounds",
                                "baseline": str(args.baseline), "rounds": args.rounds, "repeats": args.repeats,
                                "steps": STEPS, "runs": runs, "cases": cases})


if __name__ == "__main__":
    main()
