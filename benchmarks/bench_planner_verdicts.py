"""Planner verdicts against IPOPT on random lift requests (issue 23).

Each request (payload 0-60 kg, winding limit 70-140 °C, hold 1-40 s, goal angle, lift time, energy weight
including 0, careful motion on or off) is planned by ``plan_lift`` with DDP; IPOPT, on the same
transcription, gives its verdicts where DDP's plan draws the line (:func:`ipopt_at_boundary`: the hold DDP
achieved and one knot more), or with ``--full-ipopt`` plans the request itself (its own longest-hold search;
about 4x the time). Counted, in benchmarks/results/planner_verdicts.json:

- ``agree``: both reached a verdict, the same status, the same longest hold within one knot and, at the same
  hold, the same cost within 1e-3 (relative); ``agree_ipopt_one_knot_longer`` of them: IPOPT feasible one knot
  past DDP's longest hold (and not two: within the criterion, but DDP's certificate there was only local);
- ``disagree``: both reached a verdict and differ (listed in full);
- ``failed_as_verdict``: a plan that states a verdict while its decisive solve did not reach one (must be 0);
- ``ddp_failed`` / ``ipopt_failed``: plans ``failed`` (no verdict: said so, exit 1), ``tracebacks`` (must be 0),
  ``refused``: requests refused as bad input before any work (e.g. a limit below the winding at rest);
- ``ddp_ladder``: how the DDP plans reached their verdicts (which rung of the retry ladder).

    .venv/bin/python benchmarks/bench_planner_verdicts.py --workers 2   # 200 requests
    .venv/bin/python benchmarks/bench_planner_verdicts.py --quick    # 8 requests
    .venv/bin/python benchmarks/bench_planner_verdicts.py --recheck  # older results: IPOPT two knots past
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures
import json
import logging
import time
import traceback

import numpy as np

from _common import RESULTS, write

ENERGY_WEIGHTS = (0.0, 1e-3, 1e-2, 1e-1)
COST_RTOL = 1e-3


def random_request(rng: np.random.Generator) -> dict:
    return {"payload_kg": round(float(rng.uniform(0, 60)), 1), "limit_c": round(float(rng.uniform(70, 140)), 1),
            "hold_s": round(float(rng.uniform(1, 40)), 1), "goal_rad": round(float(rng.uniform(-2.2, -0.6)), 3),
            "lift_s": round(float(rng.uniform(1.0, 3.0)), 2), "energy_weight": float(rng.choice(ENERGY_WEIGHTS)),
            "careful_motion": bool(rng.integers(2))}


def run_plan(request: dict, solver: str) -> dict:
    """One plan's outcome as plain data (never raises: a traceback is recorded as such)."""
    from thermo_ddp import InputError, plan_lift
    start = time.perf_counter()
    try:
        plan = plan_lift(**request, solver=solver)
    except InputError as err:
        return {"outcome": "refused", "message": str(err)}
    except Exception:  # noqa: BLE001 - the count the benchmark exists for
        return {"outcome": "traceback", "message": traceback.format_exc(limit=3)}
    sv = plan.solver
    return {"outcome": "plan", "status": plan.status, "cause": plan.cause, "achieved_hold_s": plan.achieved_hold_s,
            "cost": sv["cost"], "solver_status": sv["status"], "attempts": sv["attempts"], "solves": sv["solves"],
            "probes": sv["probes"], "wall_s": time.perf_counter() - start, "message": plan.message}


def compare(ddp: dict, ipopt: dict, dt_s: float = 0.1) -> str:
    """agree | disagree | ddp_failed | ipopt_failed | refused | traceback."""
    for r in (ddp, ipopt):
        if r["outcome"] != "plan":
            return r["outcome"]
    if ddp["status"] == "failed":
        return "ddp_failed"
    if ipopt["status"] == "failed":
        return "ipopt_failed"
    if ipopt["achieved_hold_s"] is None:
        return "disagree"
    same_hold = abs(ddp["achieved_hold_s"] - ipopt["achieved_hold_s"]) <= dt_s + 1e-9
    at_same_hold = ddp["achieved_hold_s"] == ipopt["achieved_hold_s"] or "checks" in ipopt  # boundary: DDP's hold
    same_cost = (not at_same_hold or ddp["status"] == "infeasible"
                 or abs(ddp["cost"] - ipopt["cost"]) <= COST_RTOL * max(1.0, abs(ipopt["cost"])))
    same = ddp["status"] == ipopt["status"] or {ddp["status"], ipopt["status"]} <= {
        "feasible", "infeasible_hold", "one_knot_longer"}
    return "agree" if same and same_hold and same_cost else "disagree"


def failed_as_verdict(r: dict) -> bool:
    return r["outcome"] == "plan" and r["status"] != "failed" and r["solver_status"] not in ("converged", "infeasible")


def ipopt_at_boundary(request: dict, ddp: dict) -> dict:
    """IPOPT's verdicts on the same transcription where DDP's plan draws its line: the hold it achieved (must
    be feasible, at the same cost) and one knot longer (must be infeasible); for a feasible request the hold
    asked, for an infeasible one touching the goal. The same answer as IPOPT's own longest-hold search
    (``--full-ipopt``) whenever feasibility is monotone in the hold, in 1-2 IPOPT solves instead of 4-8."""
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess, make_solver
    from thermo_ddp.tasks.verdicts import verdict
    start = time.perf_counter()
    try:
        lp = build_lift_problem(LiftSettings(**request))
        solver, top = make_solver(lp, "ipopt"), lp.hold_knots[1] - lp.hold_knots[0]
        knots = round(ddp["achieved_hold_s"] / lp.settings.dt_s) if ddp["status"] != "infeasible" else -1
        checks = {}

        def check(k):
            probe = lp.with_hold(k * lp.settings.dt_s)
            r = solver.solve(probe.x0, probe.params, initial_guess(probe))
            checks[k] = {"verdict": verdict(r), "status": r.status, "reason": r.reason, "cost": r.cost}

        for k in sorted({max(knots, 0), knots + 1} & set(range(top + 1))):
            check(k)
        if checks.get(knots + 1, {}).get("verdict") == "feasible" and knots + 2 <= top:
            check(knots + 2)  # IPOPT holds a knot more: is its longest hold within one knot of DDP's?
    except Exception:  # noqa: BLE001 - the count the benchmark exists for
        return {"outcome": "traceback", "message": traceback.format_exc(limit=3)}
    return _boundary_verdict(ddp, knots, checks, time.perf_counter() - start)


def _boundary_verdict(ddp: dict, knots: int, checks: dict, wall_s: float) -> dict:
    checks = {int(k): v for k, v in checks.items()}
    if any(c["verdict"] is None for c in checks.values()):
        status = "failed"
    elif knots >= 0 and checks[knots]["verdict"] != "feasible":
        status = "infeasible" if knots == 0 else "shorter"  # IPOPT cannot hold what DDP held
    elif checks.get(knots + 1, {}).get("verdict") == "feasible":
        # IPOPT's longest hold is one knot longer than DDP's (within the criterion), or more
        status = "one_knot_longer" if checks.get(knots + 2, {}).get("verdict") != "feasible" else "longer"
    else:
        status = ddp["status"]
    achieved = {ddp["status"]: ddp["achieved_hold_s"], "one_knot_longer": ddp["achieved_hold_s"] + 0.1}.get(status)
    cost = checks[knots]["cost"] if knots >= 0 and knots in checks else float("nan")
    return {"outcome": "plan", "status": status, "achieved_hold_s": achieved, "cost": cost, "checks": checks,
            "solver_status": "converged" if status != "failed" else "failed", "wall_s": wall_s}


def run_pair(request: dict, full_ipopt: bool = False) -> tuple[dict, dict]:
    logging.getLogger("thermo_ddp").setLevel(logging.ERROR)
    ddp = run_plan(request, "ddp")
    if full_ipopt or ddp["outcome"] != "plan" or ddp["status"] == "failed":
        return ddp, run_plan(request, "ipopt")
    return ddp, ipopt_at_boundary(request, ddp)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--seed", type=int, default=23)
    ap.add_argument("--workers", type=int, default=1, help="processes (each request's two plans run in one)")
    ap.add_argument("--quick", action="store_true", help="8 requests (a smoke run)")
    ap.add_argument("--full-ipopt", action="store_true", help="IPOPT plans every request itself (its own search)")
    ap.add_argument("--recheck", action="store_true",
                    help="re-judge results/planner_verdicts.json: IPOPT two knots past DDP's hold where it held one")
    args = ap.parse_args()
    if args.recheck:
        return recheck(args)
    n = 8 if args.quick else args.requests
    rng = np.random.default_rng(args.seed)
    requests = [random_request(rng) for _ in range(n)]
    rows = []
    with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
        for k, (request, (ddp, ipopt)) in enumerate(zip(requests, pool.map(run_pair, requests, [args.full_ipopt] * n))):
            rows.append({"request": request, "ddp": ddp, "ipopt": ipopt, "comparison": compare(ddp, ipopt)})
            print(f"{k + 1:3d}/{n} {request}: DDP {ddp.get('status', ddp['outcome'])} {ddp.get('achieved_hold_s', '')}"
                  f" | IPOPT {ipopt.get('status', ipopt['outcome'])} {ipopt.get('achieved_hold_s', '')}: "
                  f"{rows[-1]['comparison']}", flush=True)
            if (k + 1) % 10 == 0 or k + 1 == n:  # partial results survive an interrupted run
                _write(args, n, rows)


def recheck(args):
    """Rows where IPOPT held DDP's hold plus one knot, judged again with IPOPT two knots past (older runs)."""
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess, make_solver
    from thermo_ddp.tasks.verdicts import verdict
    data = json.loads((RESULTS / "planner_verdicts.json").read_text())
    rows = data["rows"]
    for row in rows:
        ipopt, ddp = row["ipopt"], row["ddp"]
        if ipopt.get("status") != "longer" or "checks" not in ipopt:
            continue
        lp = build_lift_problem(LiftSettings(**row["request"]))
        knots = round(ddp["achieved_hold_s"] / lp.settings.dt_s)
        if str(knots + 2) not in ipopt["checks"] and knots + 2 <= lp.hold_knots[1] - lp.hold_knots[0]:
            probe = lp.with_hold((knots + 2) * lp.settings.dt_s)
            r = make_solver(lp, "ipopt").solve(probe.x0, probe.params, initial_guess(probe))
            ipopt["checks"][str(knots + 2)] = {"verdict": verdict(r), "status": r.status, "reason": r.reason,
                                               "cost": r.cost}
        row["ipopt"] = _boundary_verdict(ddp, knots, ipopt["checks"], ipopt["wall_s"])
        row["comparison"] = compare(ddp, row["ipopt"])
        print(row["request"], row["ipopt"]["status"], row["comparison"], flush=True)
    args.seed = data["summary"]["seed"]
    _write(args, data["summary"]["of"], rows)


def _write(args, n, rows):
    counts = collections.Counter(r["comparison"] for r in rows)
    counts["failed_as_verdict"] = sum(failed_as_verdict(r[k]) for r in rows for k in ("ddp", "ipopt"))
    plans = [r["ddp"] for r in rows if r["ddp"]["outcome"] == "plan"]
    ipopt = [r["ipopt"] for r in rows if r["ipopt"]["outcome"] == "plan"]
    summary = {"requests": len(rows), "of": n, "seed": args.seed, **{k: counts[k] for k in (
        "agree", "disagree", "ddp_failed", "ipopt_failed", "refused", "traceback", "failed_as_verdict")},
        "agree_ipopt_one_knot_longer": sum(1 for r in rows if r["comparison"] == "agree"
                                           and r["ipopt"].get("status") == "one_knot_longer"),
        "converged_ddp_verdicts": sum(1 for r in rows if r["comparison"] in ("agree", "disagree")),
        "ddp_ladder": dict(collections.Counter(" > ".join(p["attempts"]) for p in plans)),
        "ddp_statuses": dict(collections.Counter(p["status"] for p in plans)),
        "ddp_causes": dict(collections.Counter(str(p["cause"]) for p in plans)),
        "ddp_solves_median": float(np.median([p["solves"] for p in plans])) if plans else None,
        "ddp_solves_max": max((p["solves"] for p in plans), default=None),
        "ddp_wall_s_total": float(sum(p["wall_s"] for p in plans)),
        "ipopt_wall_s_total": float(sum(p["wall_s"] for p in ipopt))}
    write("planner_verdicts", {"summary": summary, "disagreements": [r for r in rows if r["comparison"] == "disagree"],
                               "rows": rows})
    print({k: v for k, v in summary.items() if k not in ("ddp_ladder",)}, flush=True)


if __name__ == "__main__":
    main()
