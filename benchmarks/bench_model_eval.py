"""Cost of one evaluation of the step function and of its Jacobians: CasADi SX virtual machine
against the same function as generated, compiled C (the peer, in the same run), for 1 and 7 joints.

    python benchmarks/bench_model_eval.py [--repeats 9]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from _common import median_time, write
from thermo_ddp.actuated_arm import load_model
from thermo_ddp.arm import LEFT_ARM
from thermo_ddp.codegen import compiled

CASES = {"1_joint": ("arm_left_4_joint",), "7_joints": LEFT_ARM}


def bench_case(joints, repeats: int, integrator: str, dt_s: float = 0.01) -> dict:
    model = load_model(joints, payload_kg=40.0)
    x, u = model.state(q=np.full(model.nu, -0.5)), np.full(model.nu, 2.0)
    out = {"nx": model.nx, "nu": model.nu, "integrator": integrator}
    for name, fn in (("step", model.step(dt_s, integrator)), ("step_jacobians", model.step_jacobians(dt_s, integrator))):
        t0 = time.perf_counter()
        c_fn = compiled(fn)
        build_s = time.perf_counter() - t0
        sx = median_time(lambda: fn(x, u, 26.0), repeats, number=50)
        cc = median_time(lambda: c_fn(x, u, 26.0), repeats, number=50)
        out[name] = {"instructions": fn.n_instructions(), "sx": sx, "c": cc, "c_build_or_load_s": build_s,
                     "speedup_c_over_sx": sx["median_s"] / cc["median_s"]}
        print(f"{len(joints)} joint(s) {integrator:>14} {name:>15}: SX {sx['median_s'] * 1e6:8.1f} us, "
              f"C {cc['median_s'] * 1e6:8.1f} us ({out[name]['speedup_c_over_sx']:.1f}x)")
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args()
    results = {f"{case}_{integ}": bench_case(joints, args.repeats, integ)
               for case, joints in CASES.items() for integ in ("rk4", "implicit_euler")}
    write("model_eval", {"description": "step and step_jacobians: SX VM vs compiled C (median per call)",
                         "results": results})


if __name__ == "__main__":
    main()
