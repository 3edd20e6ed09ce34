"""Never-seen requests: whole plan_lift calls, DDP against IPOPT, in one run.

A user asks for a payload, limit and hold nobody asked for before. After one warm-up request (which fills a
fresh compiled-code cache), three random requests (payload 20-40 kg, limit 90-140 °C, hold 5-40 s; seeded)
are planned by DDP and by IPOPT, each a whole cold `plan_lift` call (problem, solver and any compilation
inside). IPOPT runs in both of CasADi's set-ups: the NLP expanded to SX (the package's default: slower to set
up, faster to evaluate) and kept in MX (`ReferenceSettings(expand=False)`); the ratio is taken against the
faster of the two on each request. Reported per request: wall time of each, the number of C compilations DDP
needed (counted from the codegen log), the achieved holds; and the median IPOPT / DDP wall ratio. The target
of issue 15: nothing compiled and DDP >= 5x IPOPT end to end.

Each request is planned ``--repeats`` times per peer (median wall; the first call is the never-seen one).

    python benchmarks/bench_novel_requests.py [--requests 3] [--seed 0] [--repeats 3]
"""
from __future__ import annotations

import argparse
import logging
import os
import statistics
import tempfile
import time

from _common import write


class CompileCounter(logging.Handler):
    """Counts the codegen's 'compiling ...' records."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.count = 0

    def emit(self, record):
        self.count += record.getMessage().startswith("compiling")


PEERS = {"ddp": ("ddp", None), "ipopt_sx": ("ipopt", True), "ipopt_mx": ("ipopt", False)}


def median_plan(plan_lift, counter: CompileCounter, request: dict, peer: str, repeats: int) -> dict:
    """``repeats`` whole calls (the first is the never-seen one: its compilations count); the median wall."""
    runs = [timed_plan(plan_lift, counter, request, peer) for _ in range(repeats)]
    return {**runs[0], "wall_s": statistics.median(r["wall_s"] for r in runs), "wall_runs_s": [r["wall_s"] for r in runs]}


def timed_plan(plan_lift, counter: CompileCounter, request: dict, peer: str) -> dict:
    from thermo_ddp.solvers import ReferenceSettings
    from thermo_ddp.tasks import lift
    solver, expand = PEERS[peer]
    if expand is not None:
        lift.DEFAULT_OPTIONS["ipopt"] = ReferenceSettings(expand=expand)
    before = counter.count
    t0 = time.perf_counter()
    plan = plan_lift(request["payload_kg"], request["limit_c"], request["hold_s"], solver=solver)
    return {"wall_s": time.perf_counter() - t0, "compilations": counter.count - before, "status": plan.status,
            "achieved_hold_s": plan.achieved_hold_s, "solve_s": plan.solver["total_solve_s"],
            "solves": plan.solver["solves"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3, help="whole calls per request and peer (median)")
    args = ap.parse_args()
    os.environ["THERMO_DDP_CACHE"] = tempfile.mkdtemp(prefix="novel-requests-cache-")  # nothing seen before
    import numpy as np
    from thermo_ddp.tasks.lift import plan_lift

    counter = CompileCounter()
    codegen_log = logging.getLogger("thermo_ddp.codegen")
    codegen_log.setLevel(logging.INFO)
    codegen_log.addHandler(counter)
    warm_up = {"payload_kg": 40.0, "limit_c": 84.0, "hold_s": 30.0}
    warm = {peer: timed_plan(plan_lift, counter, warm_up, peer) for peer in PEERS}
    rng = np.random.default_rng(args.seed)
    rows = []
    for _ in range(args.requests):
        request = {"payload_kg": round(float(rng.uniform(20, 40)), 1), "limit_c": round(float(rng.uniform(90, 140)), 1),
                   "hold_s": round(float(rng.uniform(5, 40)), 1)}
        runs = {peer: median_plan(plan_lift, counter, request, peer, args.repeats) for peer in PEERS}
        ddp, best = runs["ddp"], min(runs["ipopt_sx"]["wall_s"], runs["ipopt_mx"]["wall_s"])
        rows.append({**request, **runs, "ipopt_over_ddp_wall": best / ddp["wall_s"],
                     "same_hold": len({r["achieved_hold_s"] for r in runs.values()}) == 1})
        print(f"{request}: DDP {ddp['wall_s']:.3f} s ({ddp['compilations']} compilations, hold "
              f"{ddp['achieved_hold_s']:.1f} s), IPOPT SX {runs['ipopt_sx']['wall_s']:.3f} s / MX "
              f"{runs['ipopt_mx']['wall_s']:.3f} s (holds {runs['ipopt_sx']['achieved_hold_s']:.1f}, "
              f"{runs['ipopt_mx']['achieved_hold_s']:.1f} s): {rows[-1]['ipopt_over_ddp_wall']:.2f}x", flush=True)
    median = statistics.median(r["ipopt_over_ddp_wall"] for r in rows)
    write("novel_requests", {"warm_up": {**warm_up, **warm}, "requests": rows,
                             "median_ipopt_over_ddp_wall": median,
                             "ddp_compilations": sum(r["ddp"]["compilations"] for r in rows)})
    print(f"median (faster IPOPT) / DDP wall {median:.2f}x; DDP compiled {sum(r['ddp']['compilations'] for r in rows)} "
          f"times for {len(rows)} new requests")


if __name__ == "__main__":
    main()
