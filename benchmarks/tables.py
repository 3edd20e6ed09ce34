"""Markdown tables (for README.md) from benchmarks/results/{lift_ocp,mpc_step,arm_crocoddyl}.json.

    python benchmarks/tables.py
"""
from __future__ import annotations

import json

from _common import RESULTS


def _load(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.1f}"


def lift_tables(data: dict) -> list[str]:
    lines = []
    for label, case in data["lift"].items():
        lines += [f"\n**{label}** (median wall ms of `solve`; iterations; final cost; max violation; status)\n",
                  "| N | dt s | solver | cold ms | it | cost | viol | status | warm ms | it | cost | status "
                  "| cold / DDP | warm / DDP |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for n, res in case.items():
            if not n.isdigit():
                continue
            for name in ("ddp", "ipopt", "fatrop"):
                c, w = res[name]["cold"], res[name]["warm"]
                ratios = ("1" if name == "ddp" else f"{c['time_over_ddp']:.1f}",
                          "1" if name == "ddp" else f"{w['time_over_ddp']:.1f}")
                lines.append(f"| {n} | {res['dt_s']:.4g} | {name} | {_ms(c['wall_median_s'])} | {c['iterations']} "
                             f"| {c['cost']:.6g} | {c['max_violation']:.1e} | {c['status']} "
                             f"| {_ms(w['wall_median_s'])} | {w['iterations']} | {w['cost']:.6g} | {w['status']} "
                             f"| {ratios[0]} | {ratios[1]} |")
        lines.append(f"\nDDP time N=800 / N=100: cold {case['ddp_cold_time_ratio_800_over_100']:.1f}x, "
                     f"warm {case['ddp_warm_time_ratio_800_over_100']:.1f}x.")
    lines += ["\n**plan_lift, whole cold calls** (median wall s; solver time and work summed over the solves: "
              "iterations, DDP's backward / forward passes and multiplier updates)\n",
              "| case | solver | wall s | solver s | solves | status | hold s | iterations | backward / forward "
              "/ updates | reversals | v near stop rad/s | IPOPT / DDP wall | IPOPT / DDP solver |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, case in data["plan_lift"].items():
        for name in ("ddp", "ipopt", "ddp_careful_off"):
            r, w, m = case[name], case[name]["work"], case[name]["motion"]
            ratio = ("", "") if name != "ipopt" else (f"{case['ipopt_over_ddp_wall']:.1f}",
                                                      f"{case['ipopt_over_ddp_solve']:.1f}")
            passes = " / ".join(str(w[k]) for k in ("backward_passes", "forward_passes", "multiplier_updates")
                                if k in w)
            lines.append(f"| {label} | {name} | {r['wall_median_s']:.3f} | {r['solve_s']:.3f} | {r['solves']} | "
                         f"{r['status']} | {r['achieved_hold_s']:.1f} | {w['iterations']} | {passes} "
                         f"| {m['reversals']} | {m['max_speed_near_stop_rad_s']:.2f} | {ratio[0]} | {ratio[1]} |")
    return lines


def mpc_table(data: dict) -> list[str]:
    lines = ["| case | solver | warm step median ms | worst step ms | iterations median (max) | all converged "
             "| IPOPT or fatrop / DDP |", "|---|---|---|---|---|---|---|"]
    for label, case in data["cases"].items():
        for name in ("ddp", "ipopt", "fatrop"):
            r = case[name]
            ratio = "1" if name == "ddp" else f"{case[f'{name}_over_ddp_median']:.1f}"
            lines.append(f"| {label} | {name} | {_ms(r['warm_step_median_s'])} | {_ms(r['warm_step_max_s'])} "
                         f"| {r['iterations_median']:g} ({r['iterations_max']}) | {r['all_converged']} | {ratio} |")
    return lines


def arm_table(data: dict) -> list[str]:
    lines = ["| joints | nx | rollout diff | ours it ms | croco it ms | ours / croco (it) | ours solve ms (it) "
             "| croco solve ms (it) | ours / croco (solve) | cost rel diff |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for label, case in data["cases"].items():
        o, c = case["ours"], case["crocoddyl"]
        lines.append(f"| {case['nu']} | {case['nx']} | {case['check']['rollout_max_abs_diff']:.0e} | "
                     f"{1e3 * o['iteration']['median_s']:.3f} | {1e3 * c['iteration']['median_s']:.3f} | "
                     f"{case['iteration_ours_over_crocoddyl']:.2f} | {_ms(o['solve']['wall_median_s'])} "
                     f"({o['solve']['iterations']}) | {_ms(c['solve']['wall_median_s'])} "
                     f"({c['solve']['iterations']}) | "
                     f"{case['solve_ours_over_crocoddyl']:.2f} | {case['cost_rel_diff']:.1e} |")
    return lines


def main():
    for name, fun in (("lift_ocp", lift_tables), ("mpc_step", mpc_table), ("arm_crocoddyl", arm_table)):
        try:
            data = _load(name)
        except FileNotFoundError:
            print(f"\n({name}.json missing)")
            continue
        print(f"\n### {name}\nmachine: {data['machine']['cpu']}, {data['machine']['cores']} cores, "
              f"Python {data['machine']['python']}")
        print("\n".join(fun(data)))


if __name__ == "__main__":
    main()
