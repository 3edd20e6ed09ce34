"""Planner verdicts against IPOPT on random lift requests (issue 23).

Each request (payload 0-60 kg, winding limit 70-140 °C, hold 1-40 s, goal angle, lift time, energy weight
including 0, careful motion on or off) is planned by ``plan_lift`` with DDP; IPOPT, on the same
transcription, gives its verdicts where DDP's plan draws the line (:func:`ipopt_at_boundary`: the hold DDP
achieved and one knot more), or with ``--full-ipopt`` plans the request itself (its own longest-hold search;
about 4x the time). Counted, in benchmarks/results/planner_verdicts.json:

- ``agree``: both reached a verdict, the same status, the same longest hold within one knot and, at the same
  hold, the same cost within 1e-3 (relative); ``agree_ipopt_one_knot_longer`` of them: IPOPT feasible one knot
  past DDP's longest hold (and not two: within the criterion, but DDP's certificate there was only local);
  ``agree_ipopt_one_knot_shorter``: IPOPT infeasible at DDP's longest hold and feasible one knot shorter, where
  DDP too fell short of the hold asked (within the criterion: the same feasibility, the longest holds a knot
  apart; no cost is compared, IPOPT having no plan at DDP's hold);
- ``disagree``: both reached a verdict and differ (listed in full);
- ``failed_as_verdict``: a plan that states a verdict while its decisive solve did not reach one (must be 0);
- ``ddp_failed`` / ``ipopt_failed``: plans ``failed`` (no verdict: said so, exit 1), ``tracebacks`` (must be 0),
  ``refused``: requests refused as bad input before any work (e.g. a limit below the winding at rest);
- ``ddp_ladder``: how the DDP plans reached their verdicts (which rung of the retry ladder);
- ``certified`` (per row; ``disagree_certified`` / ``disagree_not_certified``): a disagreeing DDP verdict that
  holds from both starts (:func:`certified`: IPOPT started from DDP's plan confirms its hold at its cost, and
  one knot more is infeasible for IPOPT from its own start and from DDP's plan stretched by a knot): the oracle
  is a local solver too, and where its own start finds another local optimum the two verdicts differ
  (benchmarks/README.md). An agreeing row is certified as it stands.

``--reuse JSON`` takes IPOPT's own-start verdicts (same request, same hold) from an earlier results file instead
of solving them again (the transcription and IPOPT unchanged: the reused verdicts are what IPOPT would give;
the count is ``ipopt_checks_reused``); IPOPT from DDP's plan is always solved.

    .venv/bin/python benchmarks/bench_planner_verdicts.py --workers 2   # 200 requests
    .venv/bin/python benchmarks/bench_planner_verdicts.py --quick    # 8 requests
    .venv/bin/python benchmarks/bench_planner_verdicts.py --recheck  # older results: IPOPT two knots past
    .venv/bin/python benchmarks/bench_planner_verdicts.py --workers 2 --reuse old.json  # IPOPT's verdicts kept
    .venv/bin/python benchmarks/bench_planner_verdicts.py --request '{"payload_kg": 38.4, "limit_c": 88.0, ...}'

A disagreement also gets ``cross_starts`` (:func:`cross_starts`): at DDP's hold, IPOPT and DDP each from its own
start and from the other's solution, to tell a solver that stopped short from distinct local optima.
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
    return _planned(request, solver)[0]


def _planned(request: dict, solver: str):
    """(:func:`run_plan`'s data, the plan or None)."""
    from thermo_ddp import InputError, plan_lift
    start = time.perf_counter()
    try:
        plan = plan_lift(**request, solver=solver)
    except InputError as err:
        return {"outcome": "refused", "message": str(err)}, None
    except Exception:  # noqa: BLE001 - the count the benchmark exists for
        return {"outcome": "traceback", "message": traceback.format_exc(limit=3)}, None
    sv = plan.solver
    return {"outcome": "plan", "status": plan.status, "cause": plan.cause, "achieved_hold_s": plan.achieved_hold_s,
            "cost": sv["cost"], "solver_status": sv["status"], "attempts": sv["attempts"], "solves": sv["solves"],
            "probes": sv["probes"], "wall_s": time.perf_counter() - start, "message": plan.message}, plan


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
    same_cost = (not at_same_hold or ddp["status"] == "infeasible" or ipopt["status"] == "one_knot_shorter"
                 or abs(ddp["cost"] - ipopt["cost"]) <= COST_RTOL * max(1.0, abs(ipopt["cost"])))
    same = ddp["status"] == ipopt["status"] or {ddp["status"], ipopt["status"]} <= {
        "feasible", "infeasible_hold", "one_knot_longer"} or (ddp["status"], ipopt["status"]) == (
        "infeasible_hold", "one_knot_shorter")  # DDP held a knot more than IPOPT: the same if DDP fell short too
    return "agree" if same and same_hold and same_cost else "disagree"


def failed_as_verdict(r: dict) -> bool:
    return r["outcome"] == "plan" and r["status"] != "failed" and r["solver_status"] not in ("converged", "infeasible")


def _request_key(request: dict) -> str:
    return json.dumps(request, sort_keys=True)


def ipopt_at_boundary(request: dict, ddp: dict, cached: dict | None = None) -> dict:
    """IPOPT's verdicts on the same transcription where DDP's plan draws its line: the hold it achieved (must
    be feasible, at the same cost) and one knot longer (must be infeasible); for a feasible request the hold
    asked, for an infeasible one touching the goal. The same answer as IPOPT's own longest-hold search
    (``--full-ipopt``) whenever feasibility is monotone in the hold, in 1-2 IPOPT solves instead of 4-8.
    ``cached``: IPOPT's verdicts at these holds from an earlier run (knots -> check), taken as they are."""
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess, make_solver
    start = time.perf_counter()
    try:
        lp = build_lift_problem(LiftSettings(**request))
        solver, top = [], lp.hold_knots[1] - lp.hold_knots[0]
        knots = round(ddp["achieved_hold_s"] / lp.settings.dt_s) if ddp["status"] != "infeasible" else -1
        checks, cached = {}, cached or {}

        def check(k):
            if str(k) in cached:
                checks[k] = {**cached[str(k)], "reused": True}
                return
            solver[:] = solver or [make_solver(lp, "ipopt")]  # built only when a verdict is not reused
            probe = lp.with_hold(k * lp.settings.dt_s)
            checks[k] = _check(solver[0].solve(probe.x0, probe.params, initial_guess(probe)))

        for k in sorted({max(knots, 0), knots + 1} & set(range(top + 1))):
            check(k)
        if checks.get(knots + 1, {}).get("verdict") == "feasible" and knots + 2 <= top:
            check(knots + 2)  # IPOPT holds a knot more: is its longest hold within one knot of DDP's?
        if knots >= 1 and checks[knots]["verdict"] == "infeasible":
            check(knots - 1)  # IPOPT cannot hold DDP's hold: is its longest hold within one knot of DDP's?
    except Exception:  # noqa: BLE001 - the count the benchmark exists for
        return {"outcome": "traceback", "message": traceback.format_exc(limit=3)}
    return _boundary_verdict(ddp, knots, checks, time.perf_counter() - start)


def _check(result) -> dict:
    from thermo_ddp.tasks.verdicts import verdict
    return {"verdict": verdict(result), "status": result.status, "reason": result.reason, "cost": result.cost}


def ipopt_from_ddp(request: dict, ddp: dict, plan, cold: dict | None = None) -> dict:
    """IPOPT started from DDP's own plan: at DDP's hold (the plan's trajectories) and one knot longer (the plan
    stretched by a knot, as the search warm-starts a probe), two knots longer where one was feasible: knots ->
    check. ``cold`` (IPOPT's own-start checks, knots -> check) gets IPOPT's own verdict two knots longer when it
    lacks it. With IPOPT's own-start verdicts they make the certified criterion (benchmarks/README.md)."""
    from thermo_ddp.solvers import WarmStart
    from thermo_ddp.tasks.hold_search import stretched_warm_start
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess, make_solver
    lp = build_lift_problem(LiftSettings(**request))
    solver, top, dt = make_solver(lp, "ipopt"), lp.hold_knots[1] - lp.hold_knots[0], lp.settings.dt_s
    knots = round(ddp["achieved_hold_s"] / dt) if ddp["status"] != "infeasible" else 0
    at = lp.with_hold(knots * dt)
    checks = {knots: _check(solver.solve(at.x0, at.params, WarmStart(plan.xs, plan.us)))}
    for extra in (1, 2):
        if ddp["status"] == "infeasible" or knots + extra > top or (
                extra == 2 and checks[knots + 1]["verdict"] != "feasible"):
            break
        longer = lp.with_hold((knots + extra) * dt)
        checks[knots + extra] = _check(solver.solve(longer.x0, longer.params,
                                                    stretched_warm_start((at, plan), knots + extra)))
        if extra == 2 and cold is not None and str(knots + 2) not in cold and knots + 2 not in cold:
            cold[knots + 2] = _check(solver.solve(longer.x0, longer.params, initial_guess(longer)))
    return checks


def _landing(result) -> dict:
    """Where a solve landed: its verdict, status, cost, largest violation and final stationarity (DDP: its own
    projected |Qu|; IPOPT: the KKT residual, with its own dynamics multipliers)."""
    stat = result.kkt["stationarity"] if not result.solver.startswith("ddp") else float(
        np.asarray(result.history["stationarity"])[-1])
    return {**_check(result), "iterations": int(result.iterations), "violation": float(result.max_constraint_violation),
            "stationarity": float(stat)}


def cross_starts(request: dict, ddp: dict, plan) -> dict:
    """At DDP's hold (for "infeasible": touching the goal), each solver from its own start and from the other's
    solution: IPOPT from DDP's plan; DDP from IPOPT's own-start solution, with its trajectories only (as the
    search warm-starts) and with IPOPT's constraint multipliers too. Two solvers that each stay where the other
    landed have found distinct local optima of the same transcription; one that moves to the other's point had
    stopped short (a tolerance or stopping-rule issue)."""
    from thermo_ddp.solvers import WarmStart
    from thermo_ddp.tasks.lift import LiftSettings, build_lift_problem, initial_guess, make_solver
    lp = build_lift_problem(LiftSettings(**request))
    knots = round(ddp["achieved_hold_s"] / lp.settings.dt_s) if ddp["status"] != "infeasible" else 0
    at = lp.with_hold(knots * lp.settings.dt_s)
    ddp_solver, ipopt = make_solver(lp, "ddp"), make_solver(lp, "ipopt")
    own = ipopt.solve(at.x0, at.params, initial_guess(at))
    lam = {k: own.multipliers[k] for k in ("constraints", "terminal_constraints") if k in own.multipliers}
    return {"hold_knots": knots, "ddp_plan_cost": ddp["cost"],
            "ddp_own_start": _landing(ddp_solver.solve(at.x0, at.params, initial_guess(at))),
            "ipopt_own_start": _landing(own),
            "ipopt_from_ddp_plan": _landing(ipopt.solve(at.x0, at.params, WarmStart(plan.xs, plan.us))),
            "ddp_from_ipopt": _landing(ddp_solver.solve(at.x0, at.params, WarmStart(own.xs, own.us))),
            "ddp_from_ipopt_with_multipliers": _landing(ddp_solver.solve(at.x0, at.params,
                                                                         WarmStart(own.xs, own.us, lam)))}


def certified(ddp: dict, ipopt: dict) -> bool:
    """DDP's verdict holds from both starts: its hold is feasible for IPOPT started from DDP's plan at DDP's cost
    (1e-3), and the longest hold is within one knot of it: one knot more, or else two knots more, is infeasible
    for IPOPT from its own start and from DDP's plan stretched (for "infeasible": touching the goal is
    infeasible from both starts); a feasible request's hold needs only the first."""
    warm = {int(k): v for k, v in ipopt.get("from_ddp", {}).items()}
    cold = {int(k): v for k, v in ipopt.get("checks", {}).items()}
    if not warm or ddp.get("outcome") != "plan" or ddp["status"] == "failed":
        return False
    if ddp["status"] == "infeasible":
        return all(c.get(0, {}).get("verdict") == "infeasible" for c in (warm, cold))
    k = min(warm)
    same = warm[k]["verdict"] == "feasible" and abs(warm[k]["cost"] - ddp["cost"]) <= COST_RTOL * max(
        1.0, abs(ddp["cost"]))

    def infeasible(j):
        return all(c.get(j, {}).get("verdict") == "infeasible" for c in (warm, cold))

    return same and (k + 1 not in warm or infeasible(k + 1) or infeasible(k + 2))


def certify(args):
    """The disagreeing rows of results/planner_verdicts.json judged again by :func:`certified` (DDP planned
    again, IPOPT started from its plan; IPOPT's own-start verdicts kept), with their :func:`cross_starts`."""
    data = json.loads((RESULTS / "planner_verdicts.json").read_text())
    for row in data["rows"]:
        if row["comparison"] != "disagree":
            continue
        ddp, plan = _planned(row["request"], "ddp")
        if ddp.get("status") != row["ddp"].get("status") or ddp.get("achieved_hold_s") != row["ddp"].get(
                "achieved_hold_s"):
            print(row["request"], "DDP planned otherwise this time: left as it was", flush=True)
            continue
        row["ipopt"]["from_ddp"] = ipopt_from_ddp(row["request"], ddp, plan, row["ipopt"]["checks"])
        row["ipopt"]["cross_starts"] = cross_starts(row["request"], ddp, plan)
        row["certified"] = certified(row["ddp"], row["ipopt"])
        print(row["request"], row["ipopt"]["from_ddp"], row["certified"], flush=True)
    args.seed = data["summary"]["seed"]
    _write(args, data["summary"]["of"], data["rows"])


def _boundary_verdict(ddp: dict, knots: int, checks: dict, wall_s: float) -> dict:
    checks = {int(k): v for k, v in checks.items()}
    if any(c["verdict"] is None for c in checks.values()):
        status = "failed"
    elif knots >= 0 and checks[knots]["verdict"] != "feasible":  # IPOPT cannot hold what DDP held
        status = "infeasible" if knots == 0 else (
            "one_knot_shorter" if checks.get(knots - 1, {}).get("verdict") == "feasible" else "shorter")
    elif checks.get(knots + 1, {}).get("verdict") == "feasible":
        # IPOPT's longest hold is one knot longer than DDP's (within the criterion), or more
        status = "one_knot_longer" if checks.get(knots + 2, {}).get("verdict") != "feasible" else "longer"
    else:
        status = ddp["status"]
    achieved = {ddp["status"]: ddp["achieved_hold_s"], "one_knot_longer": ddp["achieved_hold_s"] + 0.1,
                "one_knot_shorter": ddp["achieved_hold_s"] - 0.1}.get(status)
    cost = checks[knots]["cost"] if knots >= 0 and knots in checks else float("nan")
    return {"outcome": "plan", "status": status, "achieved_hold_s": achieved, "cost": cost, "checks": checks,
            "solver_status": "converged" if status != "failed" else "failed", "wall_s": wall_s}


def run_pair(request: dict, full_ipopt: bool = False, cached: dict | None = None) -> tuple[dict, dict]:
    logging.getLogger("thermo_ddp").setLevel(logging.ERROR)
    ddp, plan = _planned(request, "ddp")
    if full_ipopt or ddp["outcome"] != "plan" or ddp["status"] == "failed":
        return ddp, run_plan(request, "ipopt")
    ipopt = ipopt_at_boundary(request, ddp, cached)
    if compare(ddp, ipopt) == "disagree":
        try:
            ipopt["from_ddp"] = ipopt_from_ddp(request, ddp, plan, ipopt["checks"])
            ipopt["cross_starts"] = cross_starts(request, ddp, plan)
        except Exception:  # noqa: BLE001 - the count the benchmark exists for
            return ddp, {"outcome": "traceback", "message": traceback.format_exc(limit=3)}
    return ddp, ipopt


def _cached_checks(path: str | None) -> dict:
    """IPOPT's verdicts by request from an earlier results file (``--reuse``): request key -> knots -> check."""
    if not path:
        return {}
    rows = json.loads(open(path).read())["rows"]
    return {_request_key(r["request"]): {k: {f: v[f] for f in ("verdict", "status", "reason", "cost")}
                                         for k, v in r["ipopt"].get("checks", {}).items()} for r in rows}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--seed", type=int, default=23)
    ap.add_argument("--workers", type=int, default=1, help="processes (each request's two plans run in one)")
    ap.add_argument("--quick", action="store_true", help="8 requests (a smoke run)")
    ap.add_argument("--full-ipopt", action="store_true", help="IPOPT plans every request itself (its own search)")
    ap.add_argument("--reuse", metavar="JSON",
                    help="IPOPT's own-start verdicts from an earlier results file where the same request and hold")
    ap.add_argument("--certify", action="store_true",
                    help="judge the disagreeing rows of results/planner_verdicts.json again by the certified criterion")
    ap.add_argument("--rerun-careful-off", action="store_true",
                    help="plan again the requests of results/planner_verdicts.json with careful motion off")
    ap.add_argument("--request", action="append", type=json.loads, metavar="JSON",
                    help="plan this request (a LiftSettings mapping, e.g. '{\"payload_kg\": 38.4, ...}') instead of "
                         "random ones; repeatable; results in results/planner_verdicts_chosen.json")
    ap.add_argument("--recheck", action="store_true",
                    help="re-judge results/planner_verdicts.json: IPOPT two knots past DDP's hold where it held one")
    args = ap.parse_args()
    if args.recheck:
        return recheck(args)
    if args.certify:
        return certify(args)
    if args.rerun_careful_off:
        return rerun_careful_off(args)
    n = 8 if args.quick else args.requests
    rng = np.random.default_rng(args.seed)
    requests = args.request or [random_request(rng) for _ in range(n)]
    n = len(requests)
    rows, cache = [], _cached_checks(args.reuse)
    cached = [cache.get(_request_key(r)) for r in requests]
    with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
        for k, (request, (ddp, ipopt)) in enumerate(zip(requests, pool.map(run_pair, requests, [args.full_ipopt] * n,
                                                                           cached))):
            comparison = compare(ddp, ipopt)
            rows.append({"request": request, "ddp": ddp, "ipopt": ipopt, "comparison": comparison,
                         "certified": comparison == "agree" or certified(ddp, ipopt)})
            print(f"{k + 1:3d}/{n} {request}: DDP {ddp.get('status', ddp['outcome'])} {ddp.get('achieved_hold_s', '')}"
                  f" | IPOPT {ipopt.get('status', ipopt['outcome'])} {ipopt.get('achieved_hold_s', '')}: "
                  f"{rows[-1]['comparison']}", flush=True)
            if (k + 1) % 10 == 0 or k + 1 == n:  # partial results survive an interrupted run
                _write(args, n, rows)


def rerun_careful_off(args):
    """The rows of results/planner_verdicts.json with careful motion off planned again (after a change of the
    solver's options for them), IPOPT's own-start verdicts reused from ``--reuse`` and those rows."""
    data = json.loads((RESULTS / "planner_verdicts.json").read_text())
    cache = {**_cached_checks(args.reuse), **_cached_checks(str(RESULTS / "planner_verdicts.json"))}
    index = [k for k, r in enumerate(data["rows"]) if not r["request"]["careful_motion"]]
    requests = [data["rows"][k]["request"] for k in index]
    with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
        pairs = pool.map(run_pair, requests, [False] * len(requests), [cache.get(_request_key(r)) for r in requests])
        for n, (k, request, (ddp, ipopt)) in enumerate(zip(index, requests, pairs)):
            comparison = compare(ddp, ipopt)
            data["rows"][k] = {"request": request, "ddp": ddp, "ipopt": ipopt, "comparison": comparison,
                               "certified": comparison == "agree" or certified(ddp, ipopt)}
            print(f"{n + 1}/{len(index)} {request}: {comparison}", flush=True)
    args.seed = data["summary"]["seed"]
    _write(args, data["summary"]["of"], data["rows"])


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
        "agree_ipopt_one_knot_shorter": sum(1 for r in rows if r["comparison"] == "agree"
                                            and r["ipopt"].get("status") == "one_knot_shorter"),
        "converged_ddp_verdicts": sum(1 for r in rows if r["comparison"] in ("agree", "disagree")),
        "disagree_certified": sum(1 for r in rows if r["comparison"] == "disagree" and r.get("certified")),
        "disagree_not_certified": sum(1 for r in rows if r["comparison"] == "disagree" and not r.get("certified")),
        "ipopt_checks_reused": sum(1 for r in rows for c in r["ipopt"].get("checks", {}).values() if c.get("reused")),
        "ddp_ladder": dict(collections.Counter(" > ".join(p["attempts"]) for p in plans)),
        "ddp_statuses": dict(collections.Counter(p["status"] for p in plans)),
        "ddp_causes": dict(collections.Counter(str(p["cause"]) for p in plans)),
        "ddp_solves_median": float(np.median([p["solves"] for p in plans])) if plans else None,
        "ddp_solves_max": max((p["solves"] for p in plans), default=None),
        "ddp_wall_s_total": float(sum(p["wall_s"] for p in plans)),
        "ipopt_wall_s_total": float(sum(p["wall_s"] for p in ipopt))}
    name = "planner_verdicts_chosen" if getattr(args, "request", None) else "planner_verdicts"
    write(name, {"summary": summary, "disagreements": [r for r in rows if r["comparison"] == "disagree"],
                 "rows": rows})
    print({k: v for k, v in summary.items() if k not in ("ddp_ladder",)}, flush=True)


if __name__ == "__main__":
    main()
