"""Robustness sweep of the closed-loop lift on Dask: randomised runs (plant thermal values +-25 %, friction
+-30 %, casing noise and quantisation, voltage and current noise, initial temperature 30-60 °C), each
paired with a nominal run, on a LocalCluster of 2 worker processes. Figures: runs over the winding limit
(target 0), cut-off trips at 84 °C (measured casing), the minimum margin under the limit, the median hold
as a fraction of the nominal hold, runs needing the fallback controller. The controller's hold is robust to
the sweep's thermal spread (thermo_ddp.mpc.robust); the same seeds are run again with the nominal plan
(``nominal_plan``: its summary and each run's fallbacks, holds and margins). Wall time against serial: the
first ``--serial-runs`` seeds are run again in this process one after the other (the same runs, checked
equal; ``--serial-runs 0``: none), and the serial time of the whole sweep is extrapolated from them. See
thermo_ddp.studies.sweep.

Usage: python benchmarks/bench_robustness_sweep.py [--runs 200] [--workers 2] [--seed 0] [--serial-runs 20]
"""
from __future__ import annotations

import argparse
import logging

from _common import RESULTS, write

from thermo_ddp.studies.engine import EngineSettings
from thermo_ddp.studies.sweep import robustness_sweep

COMPARED = ("max_winding_c", "achieved_hold_s", "margin_c", "fallbacks")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--serial-runs", type=int, default=20)
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    sweep = robustness_sweep(args.runs, args.seed, engine=EngineSettings(workers=args.workers))
    out = sweep.to_dict()
    write("robustness_sweep", out)  # the robust sweep first: the comparison and the serial runs are added after
    sweep.plot(RESULTS / "robustness_sweep.png")
    print(sweep.report(), flush=True)
    nominal = robustness_sweep(args.runs, args.seed, engine=EngineSettings(workers=args.workers), nominal_plan=True)
    out["nominal_plan"] = {"summary": nominal.summary(),
                           "runs": [{k: r.get(k) for k in ("seed", "fallbacks", "achieved_hold_s", "margin_c", "violations")}
                                    for r in nominal.runs]}
    write("robustness_sweep", out)
    print(nominal.report(), flush=True)
    if args.serial_runs:
        serial = robustness_sweep(args.serial_runs, args.seed, engine=None)
        same = all(a[k] == b[k] for a, b in zip(sweep.runs, serial.runs) for k in COMPARED)
        serial_estimate_s = serial.wall_s * args.runs / args.serial_runs
        out["serial"] = {"runs": args.serial_runs, "wall_s": serial.wall_s, "equal_to_dask_runs": same,
                         "extrapolated_wall_s": serial_estimate_s, "speed_up": serial_estimate_s / sweep.wall_s}
        write("robustness_sweep", out)
        print(f"serial: {args.serial_runs} runs in {serial.wall_s:.0f} s (equal to the Dask runs: {same}); "
              f"{args.runs} runs extrapolated {serial_estimate_s:.0f} s, Dask {sweep.wall_s:.0f} s "
              f"({out['serial']['speed_up']:.2f}x)")


if __name__ == "__main__":
    main()
