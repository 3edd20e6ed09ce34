"""Robustness sweep of the closed-loop lift on Dask: randomised runs (plant thermal values +-25 %, friction
+-30 %, casing noise and quantisation, voltage and current noise, initial temperature 30-60 °C), each
paired with a nominal run, on a LocalCluster of 2 worker processes. Figures: runs over the winding limit
(target 0), cut-off trips at 84 °C (measured casing), the minimum margin under the limit, the median hold
as a fraction of the nominal hold, runs needing the fallback controller.

Each seed runs twice, in the same batch: with the controller's hold robust to the sweep's thermal spread
(thermo_ddp.mpc.robust, the sweep's default) and with the nominal plan (``--nominal-plan``): the JSON's
``robust`` and ``nominal_plan`` hold the same seeds. The JSON is rewritten after every batch of
``--batch`` seeds, so a run stopped early still reports the seeds it finished (``runs`` says how many).
Wall time against serial: the first ``--serial-runs`` seeds are run again in this process one after the
other (the same runs, checked equal; 0: none), and the serial time of the robust sweep is extrapolated.
See thermo_ddp.studies.sweep.

Usage: python benchmarks/bench_robustness_sweep.py [--runs 200] [--workers 2] [--seed 0] [--batch 20] [--serial-runs 10]
"""
from __future__ import annotations

import argparse
import logging
import time

from _common import RESULTS, write

from thermo_ddp.studies.engine import EngineSettings, dask_client, engine_info, map_tasks
from thermo_ddp.studies.sweep import SweepResult, _failed, run_seeds, sweep_run

COMPARED = ("max_winding_c", "achieved_hold_s", "margin_c", "fallbacks")
MODES = {"robust": False, "nominal_plan": True}  # the mode's nominal_plan flag


def batches(seeds, size):
    return [seeds[i:i + size] for i in range(0, len(seeds), size)]


def sweep_pairs(args) -> tuple[dict, dict]:
    """Both modes over the same seeds, batch after batch on one LocalCluster; the JSON written after each."""
    seeds = run_seeds(args.seed, args.runs)
    runs, wall = {m: [] for m in MODES}, {m: 0.0 for m in MODES}
    with dask_client(EngineSettings(workers=args.workers)) as client:
        info = engine_info(client).to_dict()
        for k, batch in enumerate(batches(seeds, args.batch)):
            for mode, nominal_plan in MODES.items():
                start = time.perf_counter()
                outcomes = map_tasks(client, sweep_run, batch, progress=None, desc=f"{mode} {k}", short=False,
                                     nominal_plan=nominal_plan)
                wall[mode] += time.perf_counter() - start
                runs[mode] += [o.value if o.success else _failed(o.item, o.message) for o in outcomes]
            results = {m: SweepResult(info, tuple(runs[m]), args.seed, False, wall[m], nominal_plan=n)
                       for m, n in MODES.items()}
            out = results["robust"].to_dict()
            out["nominal_plan"] = results["nominal_plan"].to_dict()
            write("robustness_sweep", out)
            print(f"{len(runs['robust'])} seeds: fallback runs robust {results['robust'].summary()['runs_with_fallback']}"
                  f", nominal plan {results['nominal_plan'].summary()['runs_with_fallback']}", flush=True)
    return results, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, default=20)
    ap.add_argument("--serial-runs", type=int, default=10)
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    results, out = sweep_pairs(args)
    sweep = results["robust"]
    sweep.plot(RESULTS / "robustness_sweep.png")
    print(sweep.report())
    print(results["nominal_plan"].report())
    if args.serial_runs:
        from thermo_ddp.studies.sweep import robustness_sweep
        serial = robustness_sweep(args.serial_runs, args.seed, engine=None)
        same = all(a[k] == b[k] for a, b in zip(sweep.runs, serial.runs) for k in COMPARED)
        estimate = serial.wall_s * args.runs / args.serial_runs
        out["serial"] = {"runs": args.serial_runs, "wall_s": serial.wall_s, "equal_to_dask_runs": same,
                         "extrapolated_wall_s": estimate, "speed_up": estimate / sweep.wall_s}
        write("robustness_sweep", out)
        print(f"serial: {args.serial_runs} runs in {serial.wall_s:.0f} s (equal to the Dask runs: {same}); "
              f"{args.runs} runs extrapolated {estimate:.0f} s, Dask {sweep.wall_s:.0f} s ({estimate / sweep.wall_s:.2f}x)")


if __name__ == "__main__":
    main()
