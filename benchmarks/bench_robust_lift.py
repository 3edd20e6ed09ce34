"""The robust lift (issue 26): what it costs against the nominal longest-hold search, DDP against IPOPT on the
same scenario problems, and whether its promise holds for random motors of the set.

For the default 40 kg lift under 84 °C and 140 °C with every thermal value within +-20 %:
1. speed: whole ``plan_lift`` calls, nominal and robust (``uncertainty=0.2``: nominal search, worst-motor
   searches, scenario searches), DDP (median of ``--repeats`` after one untimed call that fills the compiled-code
   cache) and IPOPT (one call each: minutes). Reported: wall times, the robust / nominal ratio per solver
   (issue 26: <= 10x with DDP, aim 5x), IPOPT / DDP on the robust search, and the breakdown (solver time,
   worst-motor searches);
2. agreement: holds, scenario counts and the final costs of DDP and IPOPT (same scenarios: the worst motors
   found are the same vertices);
3. the promise: 200 random motors of the box replayed through an independent thermal model
   (``thermo_ddp.testing.thermal_replay``: scipy solve_ivp on hand-written networks) under the nominal and the
   robust plan, each with its casing at the plan's reading and its other nodes at its own equilibrium given
   it (the default start, ``"sensor"``): how many exceed the limit by more than 0.5 K, and the largest excess;
4. the other start conventions: the robust hold when every node of every motor starts at the plan's initial
   state (``start="measured"``) and when every motor starts at its own rest (``start="rest"``), each replayed
   from that start.

    python benchmarks/bench_robust_lift.py [--repeats 3] [--quick]

(--quick: DDP only, one repeat, written to robust_lift_ddp.json)
"""
from __future__ import annotations

import argparse
import logging
import statistics
import time

import numpy as np

from _common import write
from thermo_ddp.tasks.lift import plan_lift
from thermo_ddp.tasks.robust import Uncertainty
from thermo_ddp.tasks.uncertainty import UncertaintySet
from thermo_ddp.testing.thermal_replay import replay_winding_c

LIMITS_C = (84.0, 140.0)
FRACTION, DRAWS, SEED = 0.2, 200, 1


def timed(fn, repeats: int):
    """(last result, median wall time, all times)."""
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return out, statistics.median(times), times


def exceedances(plan, motors, start_c) -> dict:
    w = replay_winding_c(motors, plan.time_s, plan.us, plan.series("v_rad_s"), start_c)
    excess = w.max(axis=1) - plan.settings.limit_c
    return {"over_0_5k": int(np.count_nonzero(excess > 0.5)), "over_0k": int(np.count_nonzero(excess > 0)),
            "max_excess_k": float(excess.max()), "draws": len(motors)}


def summary(plan, wall_s: float, times) -> dict:
    out = {"wall_s": wall_s, "times_s": times, "status": plan.status, "hold_s": plan.achieved_hold_s,
           "cost": plan.solver["cost"], "solve_s": plan.solver["total_solve_s"], "solves": plan.solver["solves"],
           "work": plan.solver["work"]}
    if hasattr(plan, "robust"):
        r = plan.robust
        out.update(scenarios=int(r.thetas.shape[0]), worst_winding_c=r.worst_winding_c,
                   worst_certified=r.worst_certified, worst_case_s=r.worst_case_s, nominal_solve_s=r.nominal_solve_s,
                   worst_motor=dict(zip(r.uset.keys, r.worst_theta.tolist())))
    return out


def bench_limit(limit_c: float, repeats: int, solvers) -> dict:
    out = {}
    for solver in solvers:
        n = repeats if solver == "ddp" else 1
        if solver == "ddp":  # untimed: fills the compiled-code cache of both problems
            plan_lift(40.0, limit_c, uncertainty=FRACTION, solver=solver)
        nominal, t_nom, times_nom = timed(lambda: plan_lift(40.0, limit_c, solver=solver), n)
        robust, t_rob, times_rob = timed(lambda: plan_lift(40.0, limit_c, uncertainty=FRACTION, solver=solver), n)
        out[solver] = {"nominal": summary(nominal, t_nom, times_nom), "robust": summary(robust, t_rob, times_rob),
                       "robust_over_nominal": t_rob / t_nom}
        print(f"{limit_c:g} °C {solver}: nominal {nominal.achieved_hold_s:.1f} s in {t_nom:.2f} s, robust "
              f"{robust.achieved_hold_s:.1f} s in {t_rob:.2f} s ({t_rob / t_nom:.1f}x), "
              f"{robust.robust.thetas.shape[0]} scenarios, worst {robust.robust.worst_winding_c:.2f} °C")
        if solver == "ddp":
            params = nominal.model.params[nominal.model.joints[0]]
            uset = UncertaintySet.from_fraction(params, FRACTION)
            motors = [uset.parameters(params, th) for th in uset.sample(np.random.default_rng(SEED), DRAWS)]
            casing = {"casing": float(nominal.series("casing_c")[0, 0])}
            out["replay"] = {"nominal": exceedances(nominal, motors, casing),
                             "robust": exceedances(robust, motors, casing)}
            measured = plan_lift(40.0, limit_c, uncertainty=Uncertainty(FRACTION, "measured"))
            out["start_measured"] = {"hold_s": measured.achieved_hold_s,
                                     "scenarios": int(measured.robust.thetas.shape[0]),
                                     "replay": exceedances(measured, motors, nominal.xs[0, 2:])}
            rest = plan_lift(40.0, limit_c, uncertainty=Uncertainty(FRACTION, "rest"))
            out["start_rest"] = {"hold_s": rest.achieved_hold_s, "scenarios": int(rest.robust.thetas.shape[0]),
                                 "worst_winding_c": rest.robust.worst_winding_c,
                                 "replay_from_rest": exceedances(rest, motors, None),
                                 "nominal_replay_from_rest": exceedances(nominal, motors, None)}
            print(f"  replay of {DRAWS} motors: {out['replay']}; every node measured: hold "
                  f"{measured.achieved_hold_s:.1f} s; from rest: hold {rest.achieved_hold_s:.1f} s")
    if "ipopt" in out:
        d, i = out["ddp"]["robust"], out["ipopt"]["robust"]
        out["ddp_vs_ipopt"] = {"same_hold": d["hold_s"] == i["hold_s"], "same_scenarios": d["scenarios"] == i["scenarios"],
                               "cost_rel_diff": abs(d["cost"] - i["cost"]) / abs(i["cost"]),
                               "ipopt_over_ddp_robust_wall": i["wall_s"] / d["wall_s"]}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    solvers = ("ddp",) if args.quick else ("ddp", "ipopt")
    repeats = 1 if args.quick else args.repeats
    results = {f"{limit:g}c": bench_limit(limit, repeats, solvers) for limit in LIMITS_C}
    write("robust_lift_ddp" if args.quick else "robust_lift",
          {"fraction": FRACTION, "payload_kg": 40.0, "repeats": repeats, "results": results})


if __name__ == "__main__":
    main()
