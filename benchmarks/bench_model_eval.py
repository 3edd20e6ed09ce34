"""Cost of one evaluation of the step function and of its Jacobians: CasADi SX virtual machine
against the same function as generated, compiled C (the peer, in the same run), for 1 and 7 joints.
"per call" includes Python's call overhead; "batched" evaluates BATCH points in one mapped call
(as the solver does over a horizon) and divides, which measures the numerical kernel itself.

    python benchmarks/bench_model_eval.py [--repeats 9]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from _common import median_time, write
from thermo_ddp.model.actuated import load_model
from thermo_ddp.model.arm import LEFT_ARM
from thermo_ddp.codegen import compiled

CASES = {"1_joint": ("arm_left_4_joint",), "7_joints": LEFT_ARM}
BATCH = 200


def bench_case(joints, repeats: int, integrator: str, dt_s: float = 0.01) -> dict:
    model = load_model(joints, payload_kg=40.0)
    x, u = model.state(q=np.full(model.nu, -0.5)), np.full(model.nu, 2.0)
    out = {"nx": model.nx, "nu": model.nu, "integrator": integrator}
    xb, ub, pb = np.tile(x, (BATCH, 1)).T, np.tile(u, (BATCH, 1)).T, np.full((1, BATCH), 26.0)
    for name, fn in (("step", model.step(dt_s, integrator)), ("step_jacobians", model.step_jacobians(dt_s, integrator))):
        t0 = time.perf_counter()
        c_fn, c_map = compiled(fn), compiled(fn.map(BATCH))
        build_s = time.perf_counter() - t0
        sx_map = fn.map(BATCH)
        res = {"instructions": fn.n_instructions(), "c_build_or_load_s": build_s}
        for label, f_sx, f_c, args, per in (("per_call", fn, c_fn, (x, u, 26.0), 1),
                                              ("batched", sx_map, c_map, (xb, ub, pb), BATCH)):
            sx = median_time(lambda: f_sx(*args), repeats, number=20)
            cc = median_time(lambda: f_c(*args), repeats, number=20)
            res[label] = {"sx_s": sx["median_s"] / per, "c_s": cc["median_s"] / per,
                          "speedup_c_over_sx": sx["median_s"] / cc["median_s"]}
            print(f"{len(joints)} joint(s) {integrator:>14} {name:>15} {label:>8}: SX {res[label]['sx_s'] * 1e6:8.2f} us,"
                  f" C {res[label]['c_s'] * 1e6:8.2f} us ({res[label]['speedup_c_over_sx']:.1f}x)")
        out[name] = res
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args()
    # Implicit Euler unrolls Newton steps with a symbolic dense solve: fine for one joint (nx = 5),
    # but its 7-joint Jacobian (nx = 35) is ~4e6 instructions, too large to compile; RK4 only there.
    integrators = {"1_joint": ("rk4", "implicit_euler"), "7_joints": ("rk4",)}
    results = {f"{case}_{integ}": bench_case(joints, args.repeats, integ)
               for case, joints in CASES.items() for integ in integrators[case]}
    write("model_eval", {"description": "step and step_jacobians: SX VM vs compiled C (median per call)",
                         "results": results})


if __name__ == "__main__":
    main()
