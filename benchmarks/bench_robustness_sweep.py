"""Robustness sweep of the closed-loop lift: randomised runs (plant thermal values +-25 %, friction
+-30 %, casing noise and quantisation, voltage and current noise, initial temperature 30-60 °C), each
paired with a nominal run; 2 worker processes. Figures: limit violations (target 0), cut-off trips at
84 °C (measured casing), the minimum margin under the limit and the median hold as a fraction of the
nominal hold. See thermo_ddp.studies.sweep.

Usage: python benchmarks/bench_robustness_sweep.py [--runs 200] [--workers 2] [--seed 0]
"""
from __future__ import annotations

import argparse
import logging

from _common import write

from thermo_ddp.studies.sweep import robustness_sweep


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    out = robustness_sweep(args.runs, args.workers, args.seed)
    write("robustness_sweep", out)
    print(f"{out['runs']} runs in {out['wall_s']:.0f} s on {out['workers']} workers: {out['violations']} violations, "
          f"{out['cutoff_trips']} cut-off trips, min margin {out['min_margin_c']:.2f} K, "
          f"median hold fraction {out['median_hold_fraction']:.2f} (min {out['min_hold_fraction']:.2f})")


if __name__ == "__main__":
    main()
